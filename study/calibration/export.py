"""The export of fitted constants with its GL check, written once for ``study calibrate`` (every
form) and the tradeoff's recommendation.

:func:`write_export` writes the shader with the constants into ``shaders/`` (the study's GLSL,
or a copy of a user's file; every engine target the installed tools make; the textures the
constants assume, ``study.export.textures``), then runs the written files on OpenGL (llvmpipe),
the textures read back from their files, against the shader on each frame, and the engine
targets' checks.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from shaders_port import glsl_scalar

from .._backend import drjit_backend
from .._progress import log as _log
from ..export.textures import with_exported_textures, write_textures
from ..fit.calibrate import timed
from ..scene.shader_waves import shader_waves


@dataclass
class Export:
    """What an export wrote and how its check went: ``gl`` (one GL check per frame: the
    figures of ``study.export.gl_check`` and ``passed``), ``engine_targets`` (target -> its
    files and checks), ``textures`` (the record of what the constants assume), ``words`` (what
    it wrote, in the report's words: ``Shader.export_words``) and ``extra``
    (what a result records of a user's file, and of waves taken from the shader)."""

    gl: list
    engine_targets: dict
    textures: dict
    words: dict
    extra: dict = field(default_factory=dict)

    @property
    def gl_check(self) -> dict:
        """The check of a one-frame calibration; of several: the first frame's figures,
        ``passed`` over all and each frame's figures under ``frames``."""
        if len(self.gl) == 1:
            return self.gl[0]
        out = dict(self.gl[0])
        out["passed"] = all(g.get("passed") is not False for g in self.gl)
        out["frames"] = [{k: g.get(k) for k in ("mean_abs", "p999", "passed")} for g in self.gl]
        return out


def fit_status(parameters: dict) -> dict:
    """GLSL scalar name -> the fit's status (fitted, bound, frozen, swept) of ``parameters``
    (a ``Calibration``'s), which the binding sheets mark."""
    return {glsl_scalar(n): p["status"] for n, p in parameters.items()}


def write_export(
    shader, exp, frames_inputs: list, constants, status: dict, out: Path, variant: str,
    timings: dict | None = None, check_frames: bool = True,
) -> Export:  # fmt: skip
    """``shader`` (``study.calibration.shader.Shader``) with ``constants`` exported into
    ``out/shaders`` and checked (module docstring). ``frames_inputs``: the shader inputs of each
    frame (at the experiment's resolution); the first gives the textures. ``status``: as
    :func:`fit_status`. ``timings`` gets ``export_s`` and ``gl_check_s``."""
    timings = {} if timings is None else timings
    backend = drjit_backend(variant)
    folder = Path(out) / "shaders"
    record = shader.texture_record(exp, frames_inputs[0])
    with timed(timings, "export_s"):
        _log(f"calibrate: exporting and compiling {shader.label} (and its vertex shader)")
        first, normal_map = frames_inputs[0], shader.normal_map
        textures = (record, lambda d: write_textures(record, first, d, normal_map))
        left_out = shader.export(constants, folder, textures, status)
    # the GL check runs the textures that ship: read back from the exported files
    checked = [with_exported_textures(i, folder) for i in frames_inputs]
    if not check_frames:
        checked = checked[:1]
    with timed(timings, "gl_check_s"):
        _log(
            f"calibrate: running the exported shader on OpenGL (llvmpipe), {len(checked)} frame(s)"
        )
        gl = [shader.gl_check(i, constants, folder, backend) for i in checked]
        targets = shader.target_checks(checked[0], constants, folder, left_out, backend)
    text = shader.write_back(exp, constants, all(g.get("passed") is not False for g in gl))
    extra = shader.file_record(exp, text)  # {} for a shader of the space
    if exp.waves.source == "shader":  # the reference's surface: how well it fits the normals
        extra["waves"] = shader_waves(exp).stats
    return Export(gl, targets, record, shader.export_words(exp), extra)
