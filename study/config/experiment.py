"""Experiment files (TOML): validation, ``--set`` overrides, loading.

An experiment describes one scene (pool floor, water, waves, sky and sun, camera,
resolution), how its reference is rendered, and what is fitted. Its keys are those of
``schema.SCHEMA``, the single source of truth: validation, defaults and the key table of
``docs/experiment-keys.md`` (``schema.schema_markdown``) all come from it.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from shaders_port.space import parse_fix
from shaders_port.variants import get_variant

from .._backend import active_variant, drjit_backend
from .._progress import log
from . import files as user_files
from .errors import ExperimentError, clip_text
from .floor import floor_height, heightmap_floor
from .resolution import AUTO, PRESETS, auto_fit_resolution
from .user_shader import check_user_shader, is_user_shader, shader_waves_digest
from .schema import (
    FIT_PARAMETERS,
    FLOOR_SHAPES,
    REFERENCE_ONLY_KEYS,
    SCHEMA,
    SHADER_INPUT_KEYS,
    SHADERS,
    SOLVERS,
    Field,
    schema_markdown,
)
from .sections import SECTIONS, TOP_LEVEL, section_of

__all__ = [
    "Experiment",
    "ExperimentError",
    "Field",
    "SCHEMA",
    "load_experiment",
    "load_experiments",
    "schema_markdown",
    "validate",
    "FIT_PARAMETERS",
    "FLOOR_SHAPES",
    "REFERENCE_ONLY_KEYS",
    "SHADER_INPUT_KEYS",
    "SHADERS",
    "SOLVERS",
]


_VEC_LEN = {"vec2": 2, "vec3": 3, "vec4": 4}


def _clip(v, limit: int = 80) -> str:
    """``repr(v)`` cut to a readable length (an echoed bad value must not flood the message)."""
    return clip_text(repr(v), limit)


# keys added after references were cached: hashed only when set, so that the cached
# references and inputs of experiments that do not use them stay valid
_LATER_KEYS = (
    "floor.ledge",
    "floor.heightmap",
    "floor.height_scale",
    "floor.albedo_image",
    "floor.extent",
    "sky.envmap",
    "sky.rotation",
    "sky.scale",
    "sun.source",
    "mesh.file",
    "mesh.position",
    "mesh.scale",
    "mesh.rotation",
    "mesh.albedo",
    "mesh.texture",
    "waves.source",
    "waves.height_scale",
    "waves.shader_grid",
    "waves.time",
    "camera.views",
)


_NOTED: set = set()


def _check_fit_shader(values: dict, base: dict):
    """``fit.shader``: a user's file, loaded and checked with its declaration (returned, a
    ``UserShader``); or a shader of the space (None returned), which takes none of the keys of
    a user's file, and whose ``fit.parameters`` become those it fits (:func:`fit_parameters`).
    Then ``tradeoff.variants`` and ``tradeoff.fix`` (:func:`_check_shaders`)."""
    if is_user_shader(values["fit.shader"]):
        user = check_user_shader(values, base)
        _check_shaders(values, [])
        return user
    if values["fit.vertex"]:
        raise ExperimentError(
            "fit.vertex is the vertex shader of your own fit.shader (a .frag, .glsl, .fs, .fsh "
            "or .fx file); "
            "remove it, or set fit.shader to your fragment shader"
        )
    for key in ("fit.declare", "fit.defines", "fit.vertex_defines", "fit.include_paths"):
        if values[key] is not None:
            raise ExperimentError(
                f"{key} is for your own fit.shader (a .frag file); "
                "remove it, or set fit.shader to the file"
            )
    if values["waves.source"] == "shader":
        raise ExperimentError(
            f"waves.source = 'shader' takes the waves of your own fit.shader (a .frag file); "
            f"{values['fit.shader']!r} is a shader of the study's space, whose waves are the "
            "study's: remove waves.source"
        )
    _check_shaders(values, [("fit.shader", values["fit.shader"])])
    values["fit.parameters"] = fit_parameters(values["fit.shader"], values["fit.parameters"])
    return None


def _check_shaders(values: dict, names: list) -> None:
    """``names`` ((key, shader name) pairs) and ``tradeoff.variants`` name shaders of the
    space, ``tradeoff.fix`` pins its axes (``shaders_port.space``)."""
    names = names + [("tradeoff.variants", v) for v in values["tradeoff.variants"] or []]
    for key, name in names:
        try:
            get_variant(name)
        except ValueError as exc:
            raise ExperimentError(f"{key}: {exc}") from None
    try:
        parse_fix(values["tradeoff.fix"])
    except ValueError as exc:
        raise ExperimentError(str(exc)) from None


def fit_parameters(shader_name: str, listed: list | None) -> list[str]:
    """The constants a fit of ``shader_name`` takes for ``fit.parameters = listed``: unset
    (None), every ``FIT_PARAMETERS`` entry the shader reads outside its step schedule; else
    the listed ones it reads, or that it replaces by constants of its own (e.g. the
    Beer-Lambert absorptions for ``attenuation_distance``; the fit takes the replacements).
    A listed constant it does not read is dropped with one note on stderr; none left is an
    ExperimentError."""
    shader = get_variant(shader_name)
    reads = shader.reads()
    readable = [p for p in FIT_PARAMETERS if p in reads and p not in shader.schedule]
    if listed is None:
        return readable
    kept = [p for p in listed if p in reads or p in shader.replaces]
    dropped = [p for p in listed if p not in kept]
    if not kept:
        raise ExperimentError(
            f"fit.parameters {listed}: fit.shader = {shader_name!r} reads none of them (its "
            f"GLSL declares no such constant); it reads: {', '.join(readable)} (or leave "
            "fit.parameters unset to fit them all)"
        )
    if dropped and (shader_name, tuple(dropped)) not in _NOTED:
        _NOTED.add((shader_name, tuple(dropped)))
        log(f"experiment: {shader_name} does not read {', '.join(dropped)}; not fitted")
    return kept


def _unset_later_key(key: str, value) -> bool:
    return key in _LATER_KEYS and value == SCHEMA[key].default


def _check_ledge(values: dict) -> None:
    """The ledge must lie inside the pool, below the wave troughs and clear of the floor."""
    x_min, x_max, top, thick = values["floor.ledge"]
    if thick == 0.0:
        return

    hx, hz = values["pool.half_extent"]
    key = "floor.ledge = [x_min, x_max, top, thickness]"
    if thick < 0.0:
        raise ExperimentError(f"{key}: thickness {thick} is negative (0 = no ledge)")
    if not -hx < x_min < x_max < hx:
        raise ExperimentError(
            f"{key}: need -{hx} < x_min < x_max < {hx} (inside the pool), got "
            f"x_min={x_min}, x_max={x_max}"
        )
    trough = -values["waves.amplitude"] - 0.05
    if top > trough:
        raise ExperimentError(
            f"{key}: top {top} must be at least 0.05 below the wave troughs (y <= {trough:.3f})"
        )
    x, z = np.meshgrid(np.linspace(x_min, x_max, 65), np.linspace(-hz, hz, 65))
    f = {k[len("floor.") :]: values[k] for k in values if k.startswith("floor.")}
    if f["shape"] == "heightmap":
        floor_top = float(heightmap_floor(values, x, z).max())
    else:
        floor_top = float(
            floor_height(
                f["shape"], f["depth"], f["relief"], f["steps"], f["seed"], (hx, hz), x, z
            ).max()
        )
    if top - thick <= floor_top + 0.05:
        raise ExperimentError(
            f"{key}: the underside (y = {top - thick:.3f}) must be at least 0.05 "
            f"above the floor under it (highest at y = {floor_top:.3f}); "
            "make the ledge thinner or higher, or the floor deeper"
        )


def _check(key: str, f: Field, v):
    def bad(msg):
        allowed = f" Allowed: {', '.join(map(str, f.choices))}." if f.choices else ""
        rng = f" Range: [{f.lo}, {f.hi}]." if f.lo is not None else ""
        raise ExperimentError(f"{key}: {msg}.{allowed}{rng} ({f.doc})")

    def num(x, integer=False):
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            bad(f"expected a number, got {_clip(x)}")
        try:
            finite = math.isfinite(x)
        except OverflowError:  # an integer beyond any float
            finite = False
        if not finite:
            bad(f"{_clip(x)} is not finite")
        if integer and float(x) != int(x):
            bad(f"expected an integer, got {_clip(x)}")
        if f.lo is not None and not (f.lo <= x <= f.hi):
            bad(f"{_clip(x)} is out of range")
        return int(x) if integer else float(x)

    k = f.kind
    if k == "str":
        if not isinstance(v, str):
            bad(f"expected a string, got {_clip(v)}")
        if f.choices and v not in f.choices:
            bad(f"unknown value {_clip(v)}")
        return v
    if k == "bool":
        if not isinstance(v, bool):
            bad(f"expected true or false, got {_clip(v)}")
        return v
    if k in ("float", "int"):
        return num(v, integer=(k == "int"))
    if k == "path":
        if not isinstance(v, str):
            bad(f"expected a file name (a string), got {_clip(v)}")
        if "\x00" in v or len(v) > 4096:
            bad(f"not a usable file name: {_clip(v)}")
        return v
    if k == "extent":
        if v == "pool":
            return v
        if not isinstance(v, list) or len(v) != 4:
            bad(f'expected "pool" or [x0, z0, x1, z1], got {_clip(v)}')
        return [num(x) for x in v]
    if k == "int_or_auto":
        return v if v == "auto" else num(v, integer=True)
    if k in _VEC_LEN and isinstance(v, str) and f.choices:  # a resolution's preset, or auto
        if v not in f.choices:
            bad(f"expected a list of {_VEC_LEN[k]} numbers or a preset, got {_clip(v)}")
        return v if v == AUTO else list(PRESETS[v])
    if k in _VEC_LEN:
        if not isinstance(v, list) or len(v) != _VEC_LEN[k]:
            bad(f"expected a list of {_VEC_LEN[k]} numbers, got {_clip(v)}")
        return [num(x, integer=(key.endswith("resolution"))) for x in v]
    if k == "vec2x4":
        if (
            not isinstance(v, list)
            or len(v) != 4
            or not all(isinstance(r, list) and len(r) == 2 for r in v)
        ):
            bad(f"expected 4 pairs of numbers, got {_clip(v)}")
        return [[num(x) for x in r] for r in v]
    if k == "views":
        shape_ok = isinstance(v, list) and all(
            isinstance(w, list) and len(w) == 2 and all(isinstance(p, list) and len(p) == 3
                                                        for p in w) for w in v
        )  # fmt: skip
        if not shape_ok:
            bad(f"expected a list of [[x, y, z], [x, y, z]] (position, target), got {_clip(v)}")
        return [[[num(x) for x in p] for p in w] for w in v]
    if k == "list_str":
        if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
            bad(f"expected a list of strings, got {_clip(v)}")
        for x in v:
            if f.choices and x not in f.choices:
                bad(f"unknown entry {_clip(x)}")
        if len(set(v)) != len(v):
            bad("entries must be unique")
        return list(v)
    if k == "list_float":
        if not isinstance(v, list) or not v:
            bad(f"expected a non-empty list of numbers, got {_clip(v)}")
        out = [num(x) for x in v]
        if len(set(out)) != len(out):
            bad("entries must be unique")
        return out
    raise AssertionError(k)


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out


def _parse_value(text: str):
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text  # a bare word such as `steps` is a string


@dataclass
class Experiment:
    """A validated experiment: ``values`` maps every dotted key of SCHEMA to its value; read
    them typed, a section at a time (``exp.water.sigma_t``, ``exp.fit.shader``, ``exp.name``:
    ``study.config.sections``)."""

    values: dict
    path: Path | None = None
    digests: dict = field(default_factory=dict)  # file key -> SHA-256 of the file's contents
    # key -> "auto" (fit.resolution) or "sun" (SUN_DISC_STARTS): values the tool chose
    auto: dict = field(default_factory=dict)

    def on_backend(self, variant: str) -> "Experiment":
        """This experiment for a run on the Mitsuba ``variant`` (``study._backend.init_backend``'s
        choice): a ``fit.resolution = "auto"`` chosen for that device
        (``study.config.resolution.auto_fit_resolution``); itself when nothing changes."""
        if "fit.resolution" not in self.auto:
            return self
        fit = auto_fit_resolution(self.values["resolution"], drjit_backend(variant))
        if fit == self.values["fit.resolution"]:
            return self
        values = {**self.values, "fit.resolution": fit}
        return Experiment(values, self.path, dict(self.digests), dict(self.auto))

    def __getattr__(self, name: str):
        values = self.__dict__.get("values")
        if values is not None and not name.startswith("_"):
            if name in SECTIONS:
                return section_of(values, name)
            if name in TOP_LEVEL:
                return values[name]
        raise AttributeError(f"{type(self).__name__} has no section or key {name!r}")

    def __getitem__(self, key: str):
        return self.values[key]

    def section(self, name: str) -> dict:
        p = name + "."
        return {k[len(p) :]: v for k, v in self.values.items() if k.startswith(p)}

    def scene_hash(self) -> str:
        """SHA-256 over every value that affects the reference image (not the keys that only
        shape the shader's inputs, ``SHADER_INPUT_KEYS``, nor the fit)."""
        prefixes = (
            "resolution",
            "camera.",
            "pool.",
            "floor.",
            "water.",
            "waves.",
            "sky.",
            "sun.",
            "mesh.",
            "reference.",
        )
        data = {
            k: v
            for k, v in sorted(self.values.items())
            if k.startswith(prefixes) and k not in SHADER_INPUT_KEYS and not _unset_later_key(k, v)
        }
        data.update(self._file_contents())
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()

    def inputs_hash(self) -> str:
        """SHA-256 over every value that affects the shader inputs (the scene and
        ``SHADER_INPUT_KEYS``; not the reference's own sample count, ``REFERENCE_ONLY_KEYS``, nor
        the fit, the start constants or the names)."""
        prefixes = (
            "resolution",
            "camera.",
            "pool.",
            "floor.",
            "water.",
            "waves.",
            "sky.",
            "sun.",
            "mesh.",
            "reference.",
            "variant",
        )
        data = {
            k: v
            for k, v in sorted(self.values.items())
            if k.startswith(prefixes)
            and k not in REFERENCE_ONLY_KEYS
            and not _unset_later_key(k, v)
        }
        data.update(self._file_contents())
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()

    def dry_scene_hash(self) -> str:
        """SHA-256 over every value that affects the scene without the water seen from a fixed
        point (the pool, floor, sky, sun and mesh, their files' contents, the path length and
        the seed of ``reference``): not the camera, the resolution, the water nor its waves."""
        prefixes = ("pool.", "floor.", "sky.", "sun.", "mesh.")
        keys = ("reference.max_depth", "reference.seed", "variant")
        data = {
            k: v
            for k, v in sorted(self.values.items())
            if (k.startswith(prefixes) or k in keys) and not _unset_later_key(k, v)
        }
        data.update({k: v for k, v in self._file_contents().items() if k.startswith(prefixes)})
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()

    def _file_contents(self) -> dict:
        """The file keys' paths replaced by their contents' digests (a moved file is the same
        scene; a changed file is a new one)."""
        out = {}
        for k, sha in self.digests.items():
            out[k] = ""  # the path itself does not matter
            out[f"{k}#sha256"] = sha
        return out

    def to_toml_dict(self) -> dict:
        return copy.deepcopy(self.values)


# start constants of the sun's disc (specular = disc) that default to the scene's sun
# (study.fit.model.constants_from_experiment reads them off the sun)
SUN_DISC_STARTS = ("constants.sun_disc_radius", "constants.sun_disc_radiance")


def _choose_auto(values: dict) -> dict:
    """Replace ``fit.resolution = "auto"`` in ``values`` by the tool's choice for the device of
    the run (``study._backend.init_backend``'s variant when it ran, else the experiment's
    ``variant``); return the keys so chosen (key -> "auto")."""
    if values["fit.resolution"] != AUTO:
        return {}
    device = drjit_backend(active_variant() or values["variant"])
    values["fit.resolution"] = auto_fit_resolution(values["resolution"], device)
    return {"fit.resolution": AUTO}


def validate(raw: dict, overrides: list[str] | None = None, path: Path | None = None) -> Experiment:
    """Validate a parsed TOML dictionary (plus ``key=value`` overrides) against SCHEMA."""
    if not isinstance(raw, dict):
        raise ExperimentError(f"expected a table of keys, got {_clip(raw)}")
    flat = _flatten(raw)
    base = {k: (path.parent if path is not None else None) for k in flat}
    for item in overrides or []:
        if "=" not in item:
            raise ExperimentError(
                f"--set {_clip(item)}: expected KEY=VALUE, e.g. --set water.ior=1.33"
            )
        key, text = item.split("=", 1)
        flat[key.strip()] = _parse_value(text.strip())
        # relative to the working directory; a declaration's files (fit.declare's normal_map)
        # to the experiment file, wherever the line comes from
        keep = key.strip() == "fit.declare" and path is not None
        base[key.strip()] = path.parent if keep else None
    unknown = sorted(set(flat) - set(SCHEMA))
    if unknown:
        import difflib

        hints = []
        for u in unknown[:5]:
            close = difflib.get_close_matches(u, SCHEMA, n=1) if len(u) <= 100 else []
            hints.append(_clip(u) + (f" (did you mean {close[0]!r}?)" if close else ""))
        more = f" and {len(unknown) - 5} more" if len(unknown) > 5 else ""
        raise ExperimentError(
            f"unknown key(s): {', '.join(hints)}{more}. Every key is listed in "
            "docs/experiment-keys.md"
        )
    values = {}
    for key, f in SCHEMA.items():
        values[key] = _check(key, f, flat[key]) if key in flat else copy.deepcopy(f.default)
    auto = _choose_auto(values)
    for key in SUN_DISC_STARTS:  # the sun's disc starts at the scene's sun unless given
        if key not in flat:
            auto[key] = "sun"
    fmt = values["fit.resolution"]
    res = values["resolution"]
    if fmt[0] > res[0] or fmt[1] > res[1] or res[0] % fmt[0] or res[1] % fmt[1]:
        raise ExperimentError(
            f"fit.resolution {fmt} must divide resolution {res} "
            "(the reference is box-downsampled to it)"
        )
    if (
        values["fit.input_noise"] == "decorrelate"
        and values["reference.texture_method"] != "lighting"
    ):
        raise ExperimentError(
            'fit.input_noise = "decorrelate" needs the refraction texture\'s two '
            'independent halves, which only reference.texture_method = "lighting" '
            'renders; use that method or fit.input_noise = "ignore"'
        )
    user = _check_fit_shader(values, base)  # the user's shader, loaded and checked, or None
    if values["camera.position"] == values["camera.target"]:
        raise ExperimentError("camera.position equals camera.target; move one of them")
    if values["camera.position"][1] <= 0.0:
        raise ExperimentError("camera.position: the camera must be above the water plane (y > 0)")
    for i, (position, target) in enumerate(values["camera.views"]):
        if position[1] <= 0.0 or position == target:
            raise ExperimentError(
                f"camera.views[{i}] = {[position, target]}: a view's position must be above the "
                "water plane (y > 0) and differ from its target"
            )

    for key in user_files.FILE_KEYS:
        values[key] = user_files.resolve(key, values[key], base.get(key))
    digests = user_files.check_files(values)
    if values["waves.source"] == "shader":
        digests["waves.surface"] = shader_waves_digest(user)  # what draws the waves
    _check_ledge(values)
    n = values["reference.sky_directions"]
    if round(n**0.5) ** 2 != n:
        raise ExperimentError(
            f"reference.sky_directions = {n}: the directions are stratified on a square grid; "
            "use a square number (16, 25, 36, 49, ...)"
        )
    return Experiment(values, path, digests, auto)


def load_experiment(path, overrides: list[str] | None = None) -> Experiment:
    """Read and validate an experiment TOML file; raise ExperimentError with the key at fault."""
    path = Path(path)
    if not path.is_file():
        raise ExperimentError(f"experiment file {path} does not exist")
    try:
        raw = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ExperimentError(f"{path}: not valid TOML ({exc})") from exc
    return validate(raw, overrides, path)


def load_experiments(paths, overrides: list[str] | None = None) -> list[Experiment]:
    """Several experiment files with the same overrides, for a study over scenes: at least one,
    and distinct names (they name the study's outputs)."""
    if not paths:
        raise ExperimentError("give at least one experiment file")
    exps = [load_experiment(p, overrides) for p in paths]
    names = [e["name"] for e in exps]
    if len(set(names)) != len(names):
        raise ExperimentError(f"experiment names must be distinct (they name the outputs): {names}")
    return exps
