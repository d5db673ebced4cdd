"""``study viewer``: the WebGL 2 viewer (``study.export.viewer``) and the three.js module
(``study.export.threejs``) of a calibration's output folder, written again (or for the first
time, for a result from before they existed)."""

from __future__ import annotations

import json
from pathlib import Path

from .._progress import log as _log
from ..config.experiment import ExperimentError
from ..export.threejs import ThreeUnsupported, write_threejs
from ..export.viewer import calibration_viewer
from ..scene.baseline_inputs import inputs_for_shader
from ..scene.animation import frame_experiment
from ..scene.reference import reference_key
from ..scene.shader_inputs import load_or_build_shader_inputs
from ..calibration.frames import prepare


def run_viewer(out, experiment, overrides=None, variant=None, cache=None) -> Path:
    """``study viewer OUT EXPERIMENT``: ``OUT/viewer/`` of the calibration in ``OUT``, whose shader
    inputs are built again (or read from the cache) from ``experiment`` with ``overrides`` (the
    calibration's own ``--set`` options: the experiment must give the calibration's reference,
    ExperimentError otherwise). Returns the path of ``index.html``."""
    out = Path(out)
    result = out / "constants.json"
    if not result.is_file():
        raise FileNotFoundError(f"no calibration in {out}: {result} is missing")
    summary = json.loads(result.read_text("utf-8"))
    exp, variant, _ = prepare(experiment, out, overrides, variant or summary.get("backend"))
    exp = frame_experiment(exp, 0)
    key = summary.get("reference", {}).get("key")
    if key is not None and reference_key(exp, variant) != key:
        raise ExperimentError(
            f"{experiment} (with the --set options given) is not the experiment {out} was "
            f"calibrated on (its reference key differs from {key}): pass the calibration's "
            "experiment file and the same --set options"
        )
    inputs = load_or_build_shader_inputs(exp, variant, cache=cache, log=_log)
    inputs = inputs_for_shader(exp, inputs, exp.fit.shader, variant, cache=cache, log=_log)
    page = calibration_viewer(out, exp, inputs)
    _log(f"viewer: wrote {page}")
    try:
        _log(f"viewer: wrote the three.js module and its example {write_threejs(out, exp, inputs)}")
    except (FileNotFoundError, ThreeUnsupported) as exc:
        _log(f"viewer: no three.js module: {exc}")
    return page
