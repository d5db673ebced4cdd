"""The step after the fit that is special to an animation (``animation.frames`` > 1): frame 0
fitted alone with the same options (the still frame's constants), every constants block (the
start, frame 0's and all frames') scored on every frame, the temporal error
(``study._metrics.temporal_errors``) on the pixels that are water in every frame, each block's
own loss, and ``shaders/animation.json`` (the wave offsets the application sets per frame)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._io import write_json
from .._metrics import temporal_errors
from .._progress import log as _log
from ..fit.joint import JointModel
from ..fit.model import constants_json
from .fitting import fit_frames


def animation_step(frames, shader, fit, options, scorer, start) -> dict:
    """Frame 0's own fit and every block scored over the frames (module docstring). Returns
    ``single`` (frame 0's ``Calibration``), ``scores`` (block -> a ``Score`` per frame),
    ``record`` (block -> per-frame and mean FLIP and RMSE, their spread over frames, the temporal
    error and its ``maps``), ``mask`` (the pixels water in every frame) and ``losses``."""
    _log("calibrate: fitting frame 0 alone (the still frame's constants)")
    single = fit_frames([frames[0]], shader, frames.variant, options, start, fit.models[:1])
    blocks = {
        "start": start,
        "single_frame": single.calibration.fitted,
        "all_frames": fit.calibration.fitted,
    }
    scores = {name: scorer.all(c) for name, c in blocks.items()}
    mask = np.logical_and.reduce([s.mask for s in scores["start"]])
    refs = [f.ref for f in frames]
    record = {}
    for name, per in scores.items():
        flips = np.array([s.flip for s in per])
        rmses = np.array([s.rmse for s in per])
        t = temporal_errors([r.image for r in refs], [s.image for s in per], mask,
                            [r.stderr for r in refs], [r.passes for r in refs])  # fmt: skip
        record[name] = {
            "flip": flips.tolist(),
            "rmse": rmses.tolist(),
            "flip_mean": float(flips.mean()),
            "flip_spread": float(flips.std(ddof=1)),
            "rmse_mean": float(rmses.mean()),
            "rmse_spread": float(rmses.std(ddof=1)),
            "temporal": {k: v for k, v in t.items() if k != "maps"},
            "maps": t["maps"],
        }
    return {
        "single": single.calibration,
        "scores": scores,
        "record": record,
        "mask": mask,
        "losses": _losses(fit.models, blocks),
    }


def _losses(models, blocks: dict) -> dict:
    """The fit's own loss (0.5 |r|^2 at the fit resolution) of each constants block: on each
    frame and over all frames (the joint fit's weighted sum, ``JointModel``)."""
    joint = JointModel(models)
    out = {}
    for name, c in blocks.items():
        r = joint.residual(c)
        out[name] = {
            "all_frames": 0.5 * float(r @ r),
            "per_frame": [0.5 * float(np.sum(m.residual(c) ** 2)) for m in models],
        }
    return out


def write_offsets(path: Path, exp, frames) -> dict:
    """``shaders/animation.json``: what the application sets as ``wave1..wave4`` per frame."""
    data = {
        "uniforms": ["wave1", "wave2", "wave3", "wave4"],
        "rule": "wave_i(t) = offsets[i] + t * velocities[i], t in seconds, texture units",
        "offsets": exp.waves.offsets,
        "velocities": exp.animation.velocities,
        "time_step": exp.animation.time_step,
        "frames": [f.exp.waves.offsets for f in frames],
    }
    write_json(path, data)
    return data


def animation_record(exp, frames, step: dict, offsets: dict, figures: dict) -> dict:
    """The result's ``animation`` entry: frame count and clock, frame 0's own fit, every
    block's scores (without maps), the mask's size, the offsets, what the frames share, the
    figures, each frame's reference and the blocks' losses."""
    single = step["single"]
    return {
        "frames": int(exp.animation.frames),
        "time_step": exp.animation.time_step,
        "velocities": exp.animation.velocities,
        "single_frame": {
            "constants": constants_json(single.fitted),
            "parameters": single.parameters,
            "fit": single.fit_summary,
        },
        "scores": {
            n: {k: v for k, v in s.items() if k != "maps"} for n, s in step["record"].items()
        },
        "mask_pixels": int(step["mask"].sum()),
        "offsets": offsets,
        "shared": frames.animation["shared"],
        "figures": figures,
        "references": [
            {
                "spp": f.ref.spp,
                "noise": f.ref.noise,
                "key": f.ref.provenance["key"],
                "path": str(f.ref.path),
            }
            for f in frames
        ],  # fmt: skip
        "losses": step["losses"],
    }
