"""``study calibrate`` on an animated experiment (``animation.frames`` > 1): one constants block
fitted on all frames, reported per frame and over time, exported with the wave offsets as the
vertex shader's uniforms.

Per frame ``k`` (``study.scene.animation.frame_experiment``): the reference and the shader inputs,
each cached under the frame's own key; the parts that do not depend on the wave offsets are
built once (``FrameShared``). The fit is the joint fit of ``study.fit.joint`` with one scene per
frame (each frame weighted equally); beside it frame 0 is fitted alone the same way, and both
constants blocks (and the start constants) are scored on every frame: FLIP and RMSE per frame,
their mean and spread, and the temporal error (``study._metrics.temporal_errors``)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .._backend import drjit_backend
from .._io import write_exr, write_json
from .._metrics import errors, temporal_errors
from .._progress import log as _log
from ..config.errors import ExperimentError
from ..fit.build import build_model
from ..fit.calibrate import calibrate_model, scene_frozen, timed
from ..fit.joint import JointModel, joint_calibrate
from ..fit.model import constants_json
from ..fit.result import CalibrationResult
from ..report.animation import animation_figures, write_animation_report
from ..scene.animation_data import load_frames
from .steps import export_calibration, with_stages
from .viewer import write_viewer


def _score(frames, refs, inputs, backend, constants: dict) -> dict:
    """Each constants block (name -> Constants) on every frame at full resolution: per frame
    RMSE and FLIP, their mean and spread (standard deviation over frames), the images, and the
    temporal error on the pixels that are water in every frame."""
    full = [
        build_model(e, i, r.image, backend=backend, resolution=tuple(e.resolution))
        for e, i, r in zip(frames, inputs, refs)
    ]
    mask = np.logical_and.reduce([m.mask for m in full])
    out = {"mask": mask, "images": {}, "scores": {}}
    for name, c in constants.items():
        imgs = [m.render(c)[0] for m in full]
        per = [errors(r.image, img, m.mask) for r, img, m in zip(refs, imgs, full)]
        flips = np.array([p["flip"] for p in per])
        rmses = np.array([p["rmse"] for p in per])
        t = temporal_errors(
            [r.image for r in refs], imgs, mask, [r.stderr for r in refs], [r.passes for r in refs]
        )
        out["images"][name] = imgs
        out["scores"][name] = {
            "flip": flips.tolist(),
            "rmse": rmses.tolist(),
            "flip_mean": float(flips.mean()),
            "flip_spread": float(flips.std(ddof=1)),
            "rmse_mean": float(rmses.mean()),
            "rmse_spread": float(rmses.std(ddof=1)),
            "temporal": {k: v for k, v in t.items() if k != "maps"},
            "maps": t["maps"],
        }
    return out


def run_calibrate_animated(exp, variant: str, out: Path, solver: str, cache=None, setup_s=0.0):
    """The animated calibration of ``exp`` (backend initialised, ``out`` created): per-frame data,
    the joint fit over all frames and the fit of frame 0 alone, scored on every frame; the
    exported shaders (GL-checked on every frame with its own wave uniforms), ``animation.webp``
    and ``.gif`` (reference | fitted | FLIP error), ``temporal.png``, ``constants.json`` and
    ``report.md``. Returns the JSON object written."""
    if exp.fit.input_noise != "ignore":
        raise ExperimentError(
            f'fit.input_noise = "{exp.fit.input_noise}" is not built for an animated '
            "experiment (its frames are fitted jointly by least squares); use fit.input_noise = "
            '"ignore", or --set animation.frames=1 to fit its frame 0 that way'
        )
    t_start = time.perf_counter() - setup_s
    data = load_frames(exp, variant, cache)
    frames, refs, inputs = data["frames"], data["refs"], data["inputs"]
    timings = {"setup_s": setup_s, **data["timings"]}
    backend = drjit_backend(variant)
    names = [f"frame{k}" for k in range(len(frames))]
    with timed(timings, "model_s"):
        models = [
            build_model(e, i, r.image, backend=backend, stderr_full=r.stderr)
            for e, i, r in zip(frames, inputs, refs)
        ]
    start = models[0].start_constants(exp)
    frozen = [scene_frozen(e) for e in frames]
    params, steps = exp.fit.parameters, exp.fit.max_steps
    _log(f"calibrate: fitting {params} of {models[0].label} with {solver} on {len(frames)} frames")
    with timed(timings, "fit_s"):
        joint = joint_calibrate(models, start, params, solver, steps, frozen, names)
    _log("calibrate: fitting frame 0 alone (the still frame's constants)")
    with timed(timings, "fit_single_s"):
        single = calibrate_model(models[0], start, params, solver, steps, frozen_by_scene=frozen[0])
    with timed(timings, "evaluate_s"):
        blocks = {"start": start, "single_frame": single.fitted, "all_frames": joint.fitted}
        losses = _losses(models, blocks)
        ev = _score(
            frames,
            refs,
            inputs,
            backend,
            {"start": start, "single_frame": single.fitted, "all_frames": joint.fitted},
        )
    shader = models[0].label
    joint.parameters = with_stages(joint.parameters, getattr(models[0], "user_shader", None))
    gl_frames, engine_targets, extra = export_calibration(
        exp, models[0], inputs, joint, out, timings
    )
    offsets = _write_offsets(out / "shaders" / "animation.json", exp, frames)
    with timed(timings, "figures_s"):
        figs = animation_figures(out, refs, ev, exp.animation.time_step)
        write_exr(out / "fitted_frame0.exr", ev["images"]["all_frames"][0])
    timings["total_s"] = time.perf_counter() - t_start
    more = {
        "offsets": offsets,
        "shared": data["shared"],
        "figures": figs,
        "references": _refs(refs),
        "losses": losses,
    }
    summary = _result(exp, variant, shader, (joint, single), ev, solver, timings, gl_frames,
                      {"engine_targets": engine_targets, **extra}, more)  # fmt: skip
    write_json(out / "constants.json", summary)
    write_animation_report(out, summary)
    write_viewer(out, exp, inputs[0])
    s = summary["animation"]["scores"]
    _log(
        f"calibrate: {len(frames)} frames, mean FLIP {s['start']['flip_mean']:.4f} -> "
        f"{s['all_frames']['flip_mean']:.4f} (frame 0's fit: {s['single_frame']['flip_mean']:.4f})"
        f", temporal RMSE {s['all_frames']['temporal']['trmse']:.4f}; {timings['total_s']:.0f} s;"
        f" wrote {out}"
    )
    return summary


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


def _write_offsets(path: Path, exp, frames) -> dict:
    """``shaders/animation.json``: what the application sets as ``wave1..wave4`` per frame."""
    data = {
        "uniforms": ["wave1", "wave2", "wave3", "wave4"],
        "rule": "wave_i(t) = offsets[i] + t * velocities[i], t in seconds, texture units",
        "offsets": exp.waves.offsets,
        "velocities": exp.animation.velocities,
        "time_step": exp.animation.time_step,
        "frames": [e.waves.offsets for e in frames],
    }
    write_json(path, data)
    return data


def _refs(refs) -> list:
    return [
        {"spp": r.spp, "noise": r.noise, "key": r.provenance["key"], "path": str(r.path)}
        for r in refs
    ]


def _result(exp, variant, shader, fits, ev, solver, timings, gl_frames, extra, more) -> dict:
    """The JSON object of ``constants.json``: a ``CalibrationResult`` of the all-frames fit (what
    ``study export`` reads; ``fits``: it and frame 0's alone) with ``extra`` (the engine
    targets, the textures, a user's file) and the per-frame and temporal record under
    ``animation`` (``more`` added to it)."""
    joint, single = fits
    sc = ev["scores"]
    gl = dict(gl_frames[0])
    gl["passed"] = all(g.get("passed") for g in gl_frames)
    gl["frames"] = [{k: g.get(k) for k in ("mean_abs", "p999", "passed")} for g in gl_frames]
    result = CalibrationResult(
        shader=shader,
        backend=variant,
        parameters=joint.parameters,
        constants=constants_json(joint.fitted),
        error={
            "rmse": {"default": sc["start"]["rmse_mean"], "fitted": sc["all_frames"]["rmse_mean"]},
            "flip": {"default": sc["start"]["flip_mean"], "fitted": sc["all_frames"]["flip_mean"]},
        },
        solver=solver,
        fit=joint.fit_summary,
        identifiability=joint.identifiability,
        timings=timings,
        gl_check=gl,
        experiment=exp.name,
        fit_resolution=exp.fit.resolution,
        resolution=exp.resolution,
        engine_targets=extra.pop("engine_targets"),
        textures=extra.pop("textures", None),
        extra=extra,
    )
    result.extra["animation"] = {
        "frames": int(exp.animation.frames),
        "time_step": exp.animation.time_step,
        "velocities": exp.animation.velocities,
        "single_frame": {
            "constants": constants_json(single.fitted),
            "parameters": single.parameters,
            "fit": single.fit_summary,
        },
        "scores": {n: {k: v for k, v in s.items() if k != "maps"} for n, s in sc.items()},
        "mask_pixels": int(ev["mask"].sum()),
        **more,
    }
    return result.to_json()
