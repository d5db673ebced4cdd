"""What the docs' checks of an export run outside the study share (``threejs_check.py``,
``wgsl_check.py``): a calibration's folder read back as the GL check reads it, the start of
their record, and the figures each comparison keeps.
"""

from __future__ import annotations

import json
import platform
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from shaders_port import Constants  # noqa: E402
from study import read_exr  # noqa: E402
from study._io import repo_relative  # noqa: E402
from study.calibration.frames import prepare  # noqa: E402
from study.export.gl_check import GL_MEAN, GL_P999, passes  # noqa: E402
from study.export.shaders import load_constants_json  # noqa: E402
from study.export.textures import with_exported_textures  # noqa: E402
from study.scene.baseline_inputs import inputs_for_shader  # noqa: E402
from study.scene.shader_inputs import load_or_build_shader_inputs  # noqa: E402

KEYS = ("mean_abs", "p999", "max_abs", "unexplained", "n_water")


def calibration(out: Path, experiment: str) -> tuple:
    """(its shader inputs with the exported textures, its ``constants.json`` as a dict,
    ``{"fitted": ..., "default": ...}`` Constants) of the calibration in ``out``, calibrated on
    ``experiment``."""
    exp, variant, _ = prepare(experiment, out, [])
    inputs = load_or_build_shader_inputs(exp, variant, log=lambda *a: None)
    inputs = inputs_for_shader(exp, inputs, exp.fit.shader, variant, log=lambda *a: None)
    inputs = with_exported_textures(inputs, out / "shaders")
    summary = json.loads((out / "constants.json").read_text())
    constants = {
        "fitted": load_constants_json(out / "constants.json"),
        "default": Constants.from_dict(read_exr(out / "default.exr")[1]["constants"]),
    }
    return inputs, summary, constants


def record_head(script: str, out: Path, experiment: str, summary: dict, inputs) -> dict:
    """The record's first entries: the command that writes it, the calibration, the machine
    and the GL check's thresholds."""
    return {
        "command": f"python scripts/{script} {out} {experiment}",
        "calibration": repo_relative(out),
        "shader": summary["shader"],
        "resolution": [int(inputs.width), int(inputs.height)],
        "machine": f"{platform.machine()}, {platform.system()}",
        "thresholds": {"mean_abs": GL_MEAN, "p999": GL_P999},
    }


def verdict(res: dict) -> dict:
    """``compare_port_gl``'s figures kept in a record (:data:`KEYS`), and whether they pass the
    GL check's thresholds."""
    out = {k: float(res[k]) if k in ("mean_abs", "p999", "max_abs") else int(res[k]) for k in KEYS}
    out["passes"] = passes(res)
    return out
