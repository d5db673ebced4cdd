"""``study generalise``: the joint calibration of several experiments (or one experiment's
views) plus leave-one-scene-out validation: which constants are universal, which
scene-specific."""

from __future__ import annotations

from pathlib import Path

from .._io import write_json
from .._progress import log as _log
from ..calibration.fitting import FitOptions, fit_frames
from ..calibration.frames import load_frames
from ..calibration.scoring import Scorer
from ..calibration.shader import Shader
from ..fit.joint import leave_one_out, universality
from ..fit.result import jsonable
from ..report.generalise import write_generalise_report
from ..calibration.run import calibrate


def run_generalise(experiments, out, overrides=None, variant=None, solver=None, cache=None) -> dict:
    """``study generalise A.toml B.toml ...``: the joint fit (exported as by ``calibrate``) plus
    leave-one-scene-out validation (each scene scored under the seed's constants, the constants
    fitted on the other scenes and its own fit, each fitted with the same options) and the
    universal/scene-specific verdict per constant; generalise.json and generalise.md."""
    frames = load_frames(experiments, overrides, variant, cache)
    if len(frames) < 2:
        raise ValueError(
            "study generalise needs at least two experiments or views (camera.views) to leave "
            "one out"
        )
    out = Path(out)
    first = frames.first.exp
    shader, options = Shader.of(first), FitOptions.of(first, solver)
    joint, fit = calibrate(frames, out, options, shader)
    models, cal = fit.models, fit.calibration
    start = cal.start
    scorer = Scorer(shader, frames, frames.variant)

    def fit_on(idx):
        picked = [frames[j] for j in idx]
        return fit_frames(picked, shader, frames.variant, options, start,
                          [models[j] for j in idx]).calibration  # fmt: skip

    def evaluate(i, constants):
        return scorer(i, constants).errors

    names = [f.name for f in frames]
    rows = leave_one_out(names, fit_on, evaluate, start, log=_log)
    uni = universality({r["scene"]: r["own_calibration"] for r in rows}, cal)
    # the first scene's own constants on every scene: what a block fitted on one view (or
    # scene) loses on the others
    first_own = rows[0]["own_calibration"].fitted
    table = [
        {
            "scene": r["scene"],
            "seed": r["seed"],
            "others": r["others"],
            "own": r["own"],
            "first": evaluate(i, first_own),
            "own_constants": {n: p["fitted"] for n, p in r["own_calibration"].parameters.items()},
            "own_status": {n: p["status"] for n, p in r["own_calibration"].parameters.items()},
        }
        for i, r in enumerate(rows)
    ]
    summary = jsonable({
        "experiments": joint["experiments"],
        "scenes": joint["scenes"],
        "joint": joint,
        "leave_one_out": table,
        "universality": uni,
    })  # fmt: skip
    summary = shader.named(summary)
    write_json(out / "generalise.json", summary)
    write_generalise_report(out, summary)
    _log(f"generalise: wrote {out / 'generalise.md'}")
    return summary
