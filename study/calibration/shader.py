"""One handle for the shader a calibration fits, whichever kind it is.

``fit.shader`` names a shader of the study's space (a hand port of ``shaders_port.variants``,
exported as the study's GLSL) or a user's GLSL file (a ``UserShader``: executed through SPIR-V,
exported as a copy of the file with the fitted constants in place). :class:`Shader` answers
everything a calibration asks of either: its model at a resolution, the inputs it reads, its
textures, its export into every engine target, the GL check of that export and what the result
records of it. This module is the one place that asks which kind a shader is.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from shaders_port import Constants
from shaders_port.variants import get_variant

from .._io import repo_relative, write_text_atomic
from .._progress import log as _log
from ..config.experiment import fit_parameters
from ..config.user_shader import is_user_shader, load_user_shader
from ..export.gl_check import (
    gl_check,
    gl_check_user,
    gles_check_user,
    hlsl_check_user,
    manifest_checks,
    target_checks,
)
from ..export.shaders import export_shaders, export_user_shader
from ..export.targets import resolve_targets
from ..export.textures import texture_record
from ..fit.model import ShaderModel, constants_from_experiment
from ..fit.spirv_model import SpirvModel
from ..export.result import glsl_renamed
from ..scene.baseline_inputs import inputs_for_shader

USER = "user:"  # the prefix of a user's shader's name in a sweep's table (``user:<file>``)


class Shader:
    """The shader of ``fit.shader`` (``name``: a shader of the space, or a GLSL file's path),
    ``user`` its ``UserShader`` when it is a file (read with the experiment's ``fit.declare``),
    else None."""

    def __init__(self, name: str, user=None):
        self.name = name
        self.user = user

    @classmethod
    def of(cls, exp, name: str | None = None) -> "Shader":
        """The shader ``name`` (default: ``exp.fit.shader``) as ``exp`` declares it."""
        name = name or exp.fit.shader
        if is_user_shader(name):
            return cls(name, load_user_shader({**exp.values, "fit.shader": name}))
        get_variant(name)  # ValueError naming the space's shaders for an unknown one
        return cls(name)

    @classmethod
    def of_saved(cls, saved) -> "Shader":
        """The shader a saved calibration (``study.export.shaders.SavedCalibration``) was
        fitted for: its ``shader``, and its user's file when it has one."""
        return cls(saved.data.get("shader"), saved.user)

    @classmethod
    def of_table(cls, exp, name: str) -> "Shader":
        """The shader a sweep's table names ``name`` (:attr:`table_name`) in experiment ``exp``:
        ``user:<file>`` is the experiment's own ``fit.shader``."""
        return cls.of(exp) if str(name).startswith(USER) else cls.of(exp, name)

    @property
    def is_user(self) -> bool:
        return self.user is not None

    @property
    def label(self) -> str:
        """How reports call it: the variant's name, or the file's name."""
        return self.user.label if self.is_user else self.name

    @property
    def table_name(self) -> str:
        """Its name in a sweep's table: the variant, or ``user:<file name>``."""
        return USER + self.user.label if self.is_user else self.name

    def named(self, summary: dict) -> dict:
        """A JSON object of results with every constant as this shader's source names it: the
        study's GLSL names for a shader of the space (``study.export.result.glsl_renamed``); a
        user's file names its own already."""
        return summary if self.is_user else glsl_renamed(summary)

    # ---- the fit --------------------------------------------------------------------------
    def with_inputs(self, exp, inputs, variant: str, cache=None):
        """``inputs`` with the optional fields this shader reads (screen buffers, a local cube
        map: ``study.scene.baseline_inputs.inputs_for_shader``)."""
        return inputs_for_shader(exp, inputs, self.name, variant, cache=cache, log=_log)

    def model(self, exp, inputs, reference, backend=None, resolution=None, stderr=None,
              supersample: int = 1):  # fmt: skip
        """The fit's model (``study.fit.protocol.ImageModel``) at ``resolution`` (default
        ``fit.resolution``) against ``reference`` ((H, W, 3) float32 linear RGB at the
        experiment's resolution, box-downsampled); ``stderr``: its per-pixel standard error;
        ``supersample``: samples per side of a pixel (``study.fit.model.ReferenceModel``)."""
        if self.is_user:
            return SpirvModel.from_experiment(
                exp, inputs, reference, backend, resolution, stderr, self.user, supersample
            )
        return ShaderModel.from_experiment(
            exp, inputs, reference, self.name, backend, resolution, stderr,
            supersample=supersample,
        )  # fmt: skip

    def point_parameters(self, exp) -> tuple | None:
        """The constants a sweep point refits: a user's file, ``fit.parameters`` (None: every
        declared one); a shader of the space, those of ``fit.parameters`` it reads (unset: all
        it reads) without its schedule constants (the sweep sets those), plus the variant's own
        ``fit_parameters`` (e.g. the baseline's distortions)."""
        if self.is_user:
            p = exp.fit.parameters
            return None if p is None else tuple(p)
        v = get_variant(self.name)
        listed = exp.fit.parameters
        if listed is None:  # an experiment of a user's own shader: the space's fit their own
            listed = fit_parameters(self.name, None)
        names = [n for n in v.fit_names(listed) if n not in v.schedule]
        reads = set(v.reads())
        return tuple(names + [n for n in v.fit_parameters if n in reads and n not in names])

    def start_boxes(self, exp, study_boxes) -> dict:
        """A multistart's boxes, scalar name -> (lo, hi, log-uniform): a user's file, each
        declared constant's range, sampled log-uniformly when it starts above 0 and spans two
        decades or more; a shader of the space, ``study_boxes(exp)``."""
        if not self.is_user:
            return study_boxes(exp)
        u = self.user
        return {
            n: (lo, hi, bool(lo > 0 and hi / lo >= 100))
            for n in u.scalar_names()
            for lo, hi in [u.bounds(n)]
        }

    def start(self, exp, values: dict | None = None):
        """Constants to render with: ``values`` (a ``Constants.to_dict()``, or a user's GLSL
        name -> value) over the shader's own defaults; without them, the experiment's start
        constants for a shader of the space."""
        if self.is_user:
            return {**self.user.defaults(), **(values or {})}
        return Constants.from_dict(values) if values else constants_from_experiment(exp)

    def constants(self, values: dict, schedule: dict | None = None):
        """The constants block of ``values`` (a table's ``fitted.*`` or ``start.*``: a
        ``Constants.to_dict()``, or a user's scalar name -> value) with ``schedule`` set."""
        if self.is_user:
            return self.user.with_scalars(self.user.defaults(), values)
        return Constants.from_dict(values).replace(**(schedule or {}))

    def with_stages(self, parameters: dict) -> dict:
        """``parameters`` (scalar name -> the fit's record) with each one's ``stage``
        ('fragment', 'vertex' or 'both') for a user's shader run after its own vertex shader;
        else unchanged."""
        if not self.is_user or self.user.vertex is None:
            return parameters
        return {
            n: {**p, "stage": self.user.stage_of(n.split("[")[0])} for n, p in parameters.items()
        }

    def render(self, inputs, constants, backend=None) -> dict:
        """The shader on ``inputs`` with ``constants`` (``ShaderOutput.numpy()``: ``color``
        (H, W, 3) float32 linear RGB, ``mask``, the diagnostics maps)."""
        if self.is_user:
            return self.user.render(inputs, constants, backend=backend).numpy()
        return get_variant(self.name).render(inputs, constants, backend=backend).numpy()

    # ---- the export -----------------------------------------------------------------------
    def texture_record(self, exp, inputs) -> dict:
        """What the constants assume of the textures (``study.export.textures``): a shader of
        the space with ``LEAN_NORMALS`` ships its slope moments too, with ``PARALLAX_OFFSET``
        its height map."""
        defines = () if self.is_user else get_variant(self.name).defines
        lean, heights = "LEAN_NORMALS" in defines, "PARALLAX_OFFSET" in defines
        return texture_record(exp, inputs, self.user, lean, heights)

    @property
    def normal_map(self):
        """The normal-map image a user's declaration names (None: the study's)."""
        return self.user.engine["normal_map"] if self.is_user else None

    def export(self, constants, folder: Path, textures, status: dict, targets=None, names=None):
        """The shader with ``constants`` written into ``folder`` with every engine target the
        installed tools make (``targets``: those named); ``textures``: (record, writer) of what
        the constants assume (``study.export.textures``), or None; ``status``: GLSL scalar name
        -> the fit's status, which the binding sheets mark; ``names``: for a shader of the
        space, the shaders to write with the constants (default: itself; with no name, every
        shipped one). Returns {target left out: why} (a user's file whose translation to a
        target fails leaves that target out)."""
        if not self.is_user:
            names = names or ([self.name] if self.name else None)
            export_shaders(constants, folder, names, targets, textures, status)
            return {}
        return _export_user(self.user, constants, folder, textures, status, targets)

    def gl_check(self, inputs, constants, folder: Path, backend=None) -> dict:
        """The export in ``folder`` run on OpenGL (llvmpipe) against this shader on
        ``inputs`` (``study.export.gl_check``)."""
        if not self.is_user:
            return gl_check(self.name, inputs, constants, folder)
        return gl_check_user(self.user, inputs, constants, self.render(inputs, constants, backend))

    def target_checks(self, inputs, constants, folder: Path, left_out: dict, backend=None):
        """What checked each engine target of the export in ``folder`` (``targets.json``), with
        the HLSL (and a user's GLSL ES) round trip run on llvmpipe against this shader."""
        if not self.is_user:
            return target_checks(self.name, inputs, constants, folder)
        ours = self.render(inputs, constants, backend)
        out = manifest_checks(folder)
        out.update({t: {"left_out": why} for t, why in left_out.items()})
        for target, check in (("gles300", gles_check_user), ("hlsl", hlsl_check_user)):
            if target in out and "left_out" not in out[target]:
                out[target]["llvmpipe"] = check(self.user, inputs, constants, ours, folder)
        return out

    def write_back(self, exp, constants, passed: bool) -> str | None:
        """A user's file (and its own vertex file) with ``constants`` written over its own when
        ``fit.write_back = "file"`` and the GL check ``passed``. Returns the fragment file's
        text as the calibration leaves it; None for a shader of the space."""
        if not self.is_user:
            return None
        user = self.user
        if exp.fit.write_back != "file":
            return user.source
        if not passed:
            _log(f"calibrate: {user.label} not written back: the GL check failed")
            return user.source
        # the initializers replaced; a uniform without one stays so (its start, in the
        # declaration, stays the start value: the file must read back as it was declared)
        text = user.written(constants, bare_initializers=False)
        write_text_atomic(Path(exp.fit.shader), text)
        _log(f"calibrate: wrote the fitted constants into {exp.fit.shader}")
        vtext = user.vertex_written(constants, bare_initializers=False)
        if (
            vtext is not None
            and not user.vertex.shader.shared
            and vtext != user.vertex.shader.original
        ):
            write_text_atomic(Path(exp.fit.vertex), vtext)
            _log(f"calibrate: wrote the fitted constants into {exp.fit.vertex}")
        return text

    def export_words(self, exp) -> dict:
        """What the export wrote, in the report's words: ``files`` (the shader files) and
        ``constants`` (how the engine targets carry the fitted constants)."""
        if not self.is_user:
            return {
                "files": "`shaders/compat/` (GLSL 1.20, drop-in) and `shaders/core/` (GLSL 330 "
                "core); every file compiled with glslangValidator",
                "constants": "the fitted constants as named specialization constants",
            }
        vertex = (
            f"`shaders/core/{Path(exp.fit.vertex).name}` (your vertex shader, the fitted values "
            "of the constants it declares in place alike)"
            if self.user.vertex is not None
            else "`shaders/core/water.vert` (the study's vertex shader it runs after)"
        )
        return {
            "files": f"`shaders/core/{Path(exp.fit.shader).name}` (your "
            f"`{repo_relative(exp.fit.shader)}` with "
            "the fitted constants in place of their initializers, every other byte as in your "
            f"file) and {vertex}; compiled with glslangValidator",
            "constants": "the fitted constants as written in the file, those that are uniforms "
            'declared without initializer (the sheet\'s "Uniforms the material sets" gives '
            "their values)",
        }

    def file_record(self, exp, text: str | None) -> dict:
        """What a result records of a user's file (its path, SHA-256 of ``text``, declaration,
        defines, include paths, vertex file and grid); {} for a shader of the space."""
        if not self.is_user:
            return {}
        user = self.user
        extra = {
            "shader_file": repo_relative(exp.fit.shader),
            "shader_sha256": hashlib.sha256(text.encode("utf-8")).hexdigest(),
            "declaration": {
                "constants": {n: user.declared_range(n) for n in user.constants},
                "bindings": dict(user.bindings),
                "values": {n: list(v) for n, v in user.engine_values().items()},
                **_engine_record(user.engine, exp.fit.shader),
            },
            "defines": list(user.defines),
            # after the file's own folder
            "include_paths": [repo_relative(p) for p in user.include_paths[1:]],
        }
        if user.vertex is not None:  # the pair: its vertex shader and the grid it ran on
            extra["vertex_file"] = repo_relative(exp.fit.vertex)
            extra["vertex_grid"] = list(user.vertex.cells)
            extra["vertex_defines"] = list(user.vertex.shader.defines)
        return extra


def _engine_record(engine: dict, shader_file) -> dict:
    """A user's engine options as a result records them: a declared normal map's path relative
    to the shader's file, as the declaration writes it and ``UserShader`` reads it back (no path
    of the machine that made the result)."""
    out = {k: v for k, v in engine.items() if v is not None}
    if out.get("normal_map"):
        out["normal_map"] = Path(
            os.path.relpath(out["normal_map"], Path(shader_file).resolve().parent)
        ).as_posix()
    return out


def _export_user(user, values: dict, folder: Path, textures, status: dict, targets=None) -> dict:
    """``export_user_shader`` into every engine target the user's files translate to: a target
    whose translation or compile check fails (a vertex shader writing ``gl_ClipDistance`` is
    no GLSL ES 3.00) is left out with a warning naming its error; ValueError when the core
    files themselves fail or no target is left. Returns {target left out: why}."""
    targets, left_out = list(resolve_targets(targets)), {}
    while True:
        try:
            export_user_shader(user, values, folder, targets, textures, status)
            return left_out
        except RuntimeError as exc:
            head = str(exc).splitlines()[0] if str(exc) else repr(exc)
            bad = [t for t in targets if f" on {t}/" in head]
            if not bad:
                raise ValueError(f"export of {user.label}: {exc}") from None
            targets.remove(bad[0])
            why = "; ".join(ln for ln in str(exc).splitlines()[1:] if "ERROR" in ln) or head
            _log(f"calibrate: WARNING: engine target {bad[0]} left out: {why}")
            left_out[bad[0]] = why
