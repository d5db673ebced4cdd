"""Export fitted constants into the shipped GLSL (both dialects), compile-checked.

Only the tunable-constants block of each fragment shader changes
(``shaders_port.write_constants``); the vertex shader is copied as shipped. Every written
shader is compiled with ``glslangValidator`` before anything reaches the output folder, and
the new folder is written beside the old one and swapped in by two renames, so a failed
export leaves no half-written shaders and the previous export in place.

Every variant named otherwise than its shader file (e.g. ``water_refraction_beer``, compiled
with ``#define BEER_ATTENUATION``) also gets a file of its own name, ``<variant>.frag``: the
shader file with the constants and the variant's ``#define`` lines right after ``#version``, so
that file alone reproduces the variant (``study.export.gl_check`` runs exactly it; a variant
with ``textures = 'game'`` needs the application to upload its textures at that precision).

``targets`` adds the engine targets of ``study.export.targets`` (GLSL ES 3.00, HLSL, Metal,
SPIR-V, each with its binding sheet), translated from the core files and checked in the same
temporary folder, so they too are written all or not at all.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
import os
import shutil
import sys
import tempfile
from pathlib import Path

from shaders_port import CONSTANT_SPECS, GLSL_NAMES, Constants, glsl_scalar
from shaders_port.glsl_text import compile_check, read_source, write_constants
from shaders_port.spirv.user_shader import UserShader
from shaders_port.spirv.user_vertex import DEFAULT_CELLS, UserVertex
from shaders_port.variants import SHIPPED, VARIANTS, get_variant

from .._io import disk_full, repo_path
from .result import CalibrationResult
from .targets import resolve_targets, translate_targets
from .textures import expects_lines

# every fragment shader file a registered variant uses, in registration order
FRAGMENT_SHADERS = tuple(dict.fromkeys(VARIANTS[n].shader for n in SHIPPED))


@dataclass
class SavedCalibration:
    """A ``constants.json`` read back, in every layout the tool has written: ``data`` (the JSON
    object), ``user`` (the ``UserShader`` a user's shader was fitted on, its ``shader_file``;
    None for the study's shaders), ``constants`` (``Constants``, or a user's ``{GLSL name: float
    | tuple}``) and ``result`` (its ``CalibrationResult``; None for a file of constants alone,
    such as a flat ``{name: value}`` object)."""

    data: dict
    user: object
    constants: object
    result: object

    @property
    def status(self) -> dict:
        """GLSL scalar name -> the fit's status (fitted, bound, frozen, swept); {} without a
        fit."""
        params = self.data.get("parameters")
        if not isinstance(params, dict):
            return {}
        return {glsl_scalar(n): p.get("status") for n, p in params.items() if isinstance(p, dict)}


def read_calibration(path, user=None) -> SavedCalibration:
    """``constants.json`` of ``study calibrate`` (every form), of the tradeoff's recommendation,
    or a flat JSON object ``{name: value}`` with names of ``CONSTANT_SPECS``, read back
    (:class:`SavedCalibration`). For a user's shader (its ``shader_file``) the constants are
    its declared ones, checked against ``user`` (default: the file and declaration the JSON
    names, :func:`_user_shader`). ValueError names what is wrong with the file."""
    data = _read_json(path)
    table = data.get("constants", data)
    if not isinstance(table, dict):
        raise ValueError(f"{path}: 'constants' must be an object of name -> value")
    rest = (data.get("constants_not_read") or {}).get("values", {}) if "constants" in data else {}
    table = {**rest, **table}
    if "shader_file" in data:  # a user's result names its constants under "constants" alone
        user = user or _user_shader(path, data)
        constants = _user_constants(path, {**rest, **data.get("constants", {})}, user)
    else:
        constants = _study_constants(path, table)
    try:
        result = CalibrationResult.from_json(data)
    except (TypeError, ValueError):  # constants alone: no fit recorded
        result = None
    return SavedCalibration(data, user, constants, result)


def load_constants_json(path, shader=None) -> Constants | dict:
    """The constants of :func:`read_calibration` (``shader``: a user's shader already read)."""
    return read_calibration(path, shader).constants


def user_shader_of(path):
    """The ``UserShader`` a user shader's ``constants.json`` was fitted on, or None for a
    calibration of the study's shaders (:func:`read_calibration`)."""
    return read_calibration(path).user


def _user_constants(path, table: dict, shader) -> dict:
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in table.items()}
    unknown = sorted(set(values) - set(shader.constants))
    if unknown:
        raise ValueError(
            f"{path}: {', '.join(unknown)} is no constant that {shader.label} declares "
            f"({', '.join(shader.constants)})"
        )
    return values


def _study_constants(path, table: dict) -> Constants:
    unknown = sorted(set(table) - set(CONSTANT_SPECS) - set(GLSL_NAMES.values()))
    if unknown:
        names = ", ".join(repr(u) if len(u) <= 80 else repr(u[:80]) + "..." for u in unknown[:5])
        more = f" and {len(unknown) - 5} more" if len(unknown) > 5 else ""
        raise ValueError(
            f"{path}: unknown constant(s) {names}{more}; known: the GLSL names "
            f"{sorted(GLSL_NAMES.values())} of the study's shaders (or their descriptive names "
            "in files older versions wrote); a calibration of your own shader names its file as "
            "shader_file"
        )
    try:
        return Constants.from_dict(table)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: {exc}") from exc


def _user_shader(path, data: dict):
    """The ``UserShader`` of a user shader's calibration ``data`` (its ``shader_file`` and
    ``declaration``; a relative path is the repository's, ``study._io.repo_path``). A file
    changed since the calibration (its SHA-256 differs from ``shader_sha256``) is read as it is
    now, with a note on stderr: the fitted values replace its constants' initializers."""
    file = repo_path(data["shader_file"])
    if not file.is_file():
        raise ValueError(
            f"{path}: the calibrated shader {file} is gone; put it back at that path or edit "
            "shader_file"
        )
    vertex = None
    if data.get("vertex_file"):  # a pair: the user's own vertex shader
        vfile = repo_path(data["vertex_file"])
        if not vfile.is_file():
            raise ValueError(
                f"{path}: the calibrated vertex shader {vfile} is gone; put it back at that "
                "path or edit vertex_file"
            )
        vertex = UserVertex.from_file(
            vfile,
            data.get("vertex_grid") or DEFAULT_CELLS,
            data.get("vertex_defines", data.get("defines", ())),
            tuple(str(repo_path(p)) for p in data.get("include_paths", ())),
            vfile.resolve() == file.resolve(),  # one file for both stages
        )
    shader = UserShader.from_file(
        file,
        data.get("declaration"),
        data.get("defines", ()),
        tuple(str(repo_path(p)) for p in data.get("include_paths", ())),
        vertex=vertex,
    )
    sha = hashlib.sha256(shader.source.encode("utf-8")).hexdigest()
    if data.get("shader_sha256") not in (None, sha):
        print(f"export: {file} has changed since it was calibrated", file=sys.stderr)
    return shader


def _read_json(path) -> dict:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"constants file {path} does not exist")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path} is not valid JSON ({exc})") from exc
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a JSON object of constants, got {type(data).__name__}")
    return data


def export_shaders(
    constants: Constants, out_dir, shaders=None, targets=(), textures=None, status=None
) -> list[Path]:
    """Write ``out_dir/{compat,core}/water.vert`` and the fragment shaders of the shaders named
    in ``shaders`` (any of the shader space; default: every shipped one --
    ``water_refraction.frag``, ``water_reflection.frag``, ...) with ``constants``; return the
    written paths. Constants
    are fitted for one shader, so a calibration exports that shader alone. ``targets``: engine
    targets to add (``study.export.targets.TARGETS``; None: every one the installed tools can
    make). ``textures``: (record, writer) of what the constants assume ships with them
    (``study.export.textures``): ``writer(folder)`` writes them into ``out_dir/textures/`` and
    every binding sheet opens with what the record says the shader expects. ``status``: {GLSL
    scalar name: status of the fit} (``constants.json``'s ``parameters``), which the binding
    sheets mark. Raises ValueError on bad constants or an unknown name and RuntimeError if a
    shader does not compile or translate (nothing is written then)."""
    constants.validate()
    names = list(SHIPPED) if shaders is None else list(shaders)
    if not names:
        raise ValueError("export: no shader named; name one of the space's shaders")
    for n in names:
        get_variant(n)  # a shader of the space is registered on first use; else a ValueError
    texts = {}
    for dialect in ("compat", "core"):
        texts[(dialect, "water.vert")] = read_source("water", "vert", dialect)
        bases = {}
        for name in names:
            v = VARIANTS[name]
            if v.shader not in bases:
                bases[v.shader] = write_constants(read_source(v.shader, "frag", dialect), constants)
            text = (
                bases[v.shader] if v.name == v.shader else v.source(dialect, text=bases[v.shader])
            )
            texts[(dialect, f"{v.name}.frag")] = text
    reads = {GLSL_NAMES[c] for n in names for c in VARIANTS[n].reads()}
    fit = {"status": status or {}, "reads": reads}
    return _write_checked(texts, out_dir, targets, constants, textures, fit)


def export_user_shader(
    shader, values: dict, out_dir, targets=(), textures=None, status=None
) -> list[Path]:
    """Write a user's shader (``shaders_port.spirv.user_shader.UserShader``) with ``values`` (GLSL
    name -> float | tuple) in place of its constants' initializers, ``out_dir/core/<file>``,
    beside the vertex shader it runs after (``out_dir/core/water.vert``, the study's, or the
    user's own, ``shader.vertex``, under its file name, with the values of the constants it
    declares in place alike); ``targets``
    ``textures`` and ``status`` as :func:`export_shaders` (translated from those two files,
    each uniform constant without initializer: its binding sheet gives the value to set).
    Compile-checked and written all or not at all, as there; returns the written paths."""
    frag = staged_name(shader.label, "frag")
    texts = {
        ("core", "water.vert"): read_source("water", "vert", "core"),
        ("core", frag): shader.written(values),
    }
    # the sheet's meanings of the user's names: the engine values set, the inputs bound (by a
    # declaration or by an engine's own name) in either stage
    inputs = dict(shader.run_bindings())
    if shader.vertex is not None:
        inputs.update({**shader.vertex.shader.inputs, **shader.vertex.shader.bindings})
    fit = {"status": status or {}, "reads": None, "engine_values": shader.engine_values(),
           "inputs": inputs}  # fmt: skip
    # the engine targets come from the core GLSL the study compiles (a file in an older dialect,
    # or with includes and defines, translated) with every uniform of a constant declared
    # without initializer (GLSL ES refuses one, HLSL and Metal ignore it: the material sets
    # the value its binding sheet gives); the file itself is written as the user wrote it
    core = {}
    if shader.dialect.runs_on_desktop_gl:
        core[frag] = shader.gl_source(values, uniform_initializers=False)
    if shader.vertex is not None:  # the user's own vertex shader in place of the study's:
        # its file with the fitted values of the constants it declares, its engine targets
        # from the GLSL 330 it is compiled as
        vert = staged_name(shader.vertex.label, "vert")
        texts = {("core", vert): shader.vertex_written(values),
                 ("core", frag): texts[("core", frag)]}  # fmt: skip
        core[vert] = shader.vertex_gl_source(values, uniform_initializers=False)
    return _write_checked(texts, out_dir, targets, values, textures, fit, core)


def staged_name(label: str, stage: str) -> str:
    """The exported name of a user's file of ``stage`` ('frag' or 'vert'): ``label`` itself
    when it ends in ``.frag`` / ``.vert``, else its stem with that ending (Urho3D's one
    ``Water.glsl`` for both stages is written as ``Water.frag`` and ``Water.vert``)."""
    stem, dot, ext = label.rpartition(".")
    return label if dot and ext == stage else f"{stem or ext}.{stage}"


def _write_checked(
    texts: dict, out_dir, targets, constants, textures=None, fit=None, core_sources=None
) -> list[Path]:
    """Compile every text of ``texts`` ((dialect, file name) -> GLSL), translate the core ones
    (or, per file name, the text ``core_sources`` gives) to ``targets``, write them and the
    ``textures`` into a temporary folder beside ``out_dir`` and swap it in."""
    core_sources = core_sources or {}
    for (dialect, fname), text in texts.items():  # what glslang compiles (includes resolved)
        compile_check(core_sources.get(fname, text), fname.rsplit(".", 1)[1])
    extra = {}
    targets = resolve_targets(targets)
    expects = expects_lines(textures[0]) if textures else []
    if targets:
        core = {f: t for (d, f), t in texts.items() if d == "core"} | core_sources
        with disk_full(out_dir):  # the tools' scratch files (nothing reaches out_dir yet)
            extra, _ = translate_targets(core, targets, constants, expects, fit)
    out_dir = Path(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out_dir.parent, prefix=f".{out_dir.name}."))
    try:
        with disk_full(out_dir):
            for (dialect, fname), text in texts.items():
                (tmp / dialect).mkdir(exist_ok=True)
                (tmp / dialect / fname).write_text(text, encoding="utf-8")
            for rel, data in extra.items():
                (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
                (tmp / rel).write_bytes(data)
            if textures:
                textures[1](tmp)
        old = None
        if out_dir.exists():
            old = Path(tempfile.mkdtemp(dir=out_dir.parent, prefix=f".{out_dir.name}.old."))
            os.replace(out_dir, old / out_dir.name)
        os.replace(tmp, out_dir)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return sorted(out_dir.rglob("*.*"))
