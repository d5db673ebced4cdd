"""One calibration of loaded frames, every form (one frame, views, several experiments, an
animation's frames) and every caller (``study calibrate``, ``study generalise``, the
tradeoff's recommendation): the fit over the frames, the start and fitted constants scored at
full resolution, the export with its GL check, the figures, ``constants.json`` (a
``CalibrationResult``), ``report.md`` and the viewer, all in one folder."""

from __future__ import annotations

import time
from pathlib import Path

from .._io import write_exr, write_json
from .._progress import log as _log
from ..export.threejs import ThreeUnsupported, write_threejs
from ..export.viewer import ViewerUnsupported, calibration_viewer
from ..fit.calibrate import timed
from ..fit.model import constants_json
from ..report.animation import animation_figures, write_animation_report
from ..report.calibration import comparison_figure, diagnostics_figure, loss_figure, write_report
from ..report.generalise import write_joint_report
from .animation import animation_record, animation_step, write_offsets
from .export import fit_status, write_export
from .fitting import FitOptions, fit_frames, frame_models
from .frames import output_folder
from .result import build_result
from .scoring import Scorer
from .shader import Shader


def calibrate(frames, out, options=None, shader=None, start=None, t_start=None) -> tuple:
    """The calibration of loaded ``frames`` (``study.calibration.frames.Frames``) into the
    folder ``out`` (module docstring). ``options``: the ``FitOptions`` (default: the first
    frame's experiment's); ``shader``: the ``Shader`` fitted (default: its ``fit.shader``);
    ``start``: the start constants (default: the shader's start constants for the experiment).
    Returns (the JSON object written, the ``Fit``)."""
    t_start = time.perf_counter() if t_start is None else t_start
    exp = frames.first.exp
    options = options or FitOptions.of(exp)
    out = output_folder(out)
    shader = shader or Shader.of(exp)
    timings = dict(frames.timings)
    with timed(timings, "model_s"):
        models = frame_models(frames, shader, frames.variant, options)
        start = models[0].start_constants(exp) if start is None else start
    with timed(timings, "fit_s"):
        fit = fit_frames(frames, shader, frames.variant, options, start, models)
    cal = fit.calibration
    scorer = Scorer(shader, frames, frames.variant)
    step = None
    with timed(timings, "evaluate_s"):
        if frames.kind == "animated":
            step = animation_step(frames, shader, fit, options, scorer, start)
            scores = {"default": step["scores"]["start"], "fitted": step["scores"]["all_frames"]}
        else:
            scores = {"default": scorer.all(start), "fitted": scorer.all(cal.fitted)}
    checked = [f.inputs for f in frames] if frames.kind == "animated" else [frames[0].inputs]
    export = write_export(shader, exp, checked, cal.fitted, fit_status(cal.parameters), out,
                          frames.variant, timings)  # fmt: skip
    with timed(timings, "figures_s"):
        figs = _figures(out, frames, shader, scores, cal, options.solver, step)
    timings["total_s"] = time.perf_counter() - t_start  # up to the report (written last)
    result = build_result(frames, shader, fit, scores, timings, export, options)
    if step is not None:
        offsets = write_offsets(out / "shaders" / "animation.json", exp, frames)
        result.extra["animation"] = animation_record(exp, frames, step, offsets, figs)
    summary = result.to_json()
    write_json(out / "constants.json", summary)
    _report(out, frames.kind, summary, figs)
    write_viewer(out, exp, frames[0].inputs)
    _log_done(frames, summary, step, timings, out)
    return summary, fit


def _figures(out, frames, shader, scores: dict, cal, solver: str, step) -> dict:
    """The figures of each form: one frame's comparison, diagnostics and loss plots and its
    EXRs; an animation's clip and temporal error; none for several frames (their report is a
    table). Returns figure name -> file name."""
    if frames.kind == "animated":
        record = step["record"]
        ev = {
            "images": {"all_frames": [s.image for s in step["scores"]["all_frames"]]},
            "mask": step["mask"],
            "scores": record,
        }
        figs = animation_figures(
            out, [f.ref for f in frames], ev, frames.experiment.animation.time_step
        )
        write_exr(out / "fitted_frame0.exr", ev["images"]["all_frames"][0])
        return figs
    if frames.kind != "still":
        return {}
    ref, s0, s1 = frames[0].ref, scores["default"][0], scores["fitted"][0]
    figs = {"comparison": "comparison.png", "diagnostics": "diagnostics.png", "loss": "loss.png"}
    comparison_figure(
        out / figs["comparison"],
        {"reference": ref.image, "default": s0.image, "fitted": s1.image},
        {"default": s0.errors, "fitted": s1.errors},
        s1.mask,
        title=f"{frames.experiment.name}: {shader.label}",
    )
    diagnostics_figure(
        out / figs["diagnostics"],
        s1.diagnostics.maps,
        s1.mask,
        title="diagnostics, fitted constants",
    )
    loss_figure(
        out / figs["loss"],
        {solver: cal.losses},
        title=f"loss at each of the solver's {len(cal.losses)} calls, in order\n"
        "(x: the call; value and Jacobian calls, rejected trial points included)",
    )
    write_exr(out / "fitted.exr", s1.image, {"constants": constants_json(cal.fitted)})
    write_exr(out / "default.exr", s0.image, {"constants": constants_json(cal.start)})
    write_exr(out / "reference.exr", ref.image, ref.provenance)
    return figs


def _report(out, kind: str, summary: dict, figs: dict) -> None:
    if kind == "still":
        write_report(out, summary, figs)
    elif kind == "animated":
        write_animation_report(out, summary)
    else:
        write_joint_report(out, summary)


def _log_done(frames, summary: dict, step, timings: dict, out) -> None:
    if step is not None:
        s = summary["animation"]["scores"]
        _log(
            f"calibrate: {len(frames)} frames, mean FLIP {s['start']['flip_mean']:.4f} -> "
            f"{s['all_frames']['flip_mean']:.4f} (frame 0's fit: "
            f"{s['single_frame']['flip_mean']:.4f}), temporal RMSE "
            f"{s['all_frames']['temporal']['trmse']:.4f}; {timings['total_s']:.0f} s; wrote {out}"
        )
    elif frames.kind == "still":
        e = summary["error"]
        _log(
            f"calibrate: RMSE {e['rmse']['default']:.4f} -> {e['rmse']['fitted']:.4f}, FLIP "
            f"{e['flip']['default']:.4f} -> {e['flip']['fitted']:.4f}; wrote {out}"
        )
    else:
        _log(f"calibrate (joint, {len(frames)} scenes): wrote {out}")


def write_viewer(out: Path, exp, inputs) -> Path | None:
    """``out/viewer/`` of the calibration just written in ``out`` (see
    ``study.export.viewer.calibration_viewer``) and ``out/threejs/``, the three.js module
    (``study.export.threejs``), which shows the pool from the viewer's data; a calibration
    without a GLSL ES export (the SPIRV-Cross tools missing) gets neither, and a shader whose
    inputs the module does not build no module, each with a note. Returns ``index.html`` or
    None."""
    try:
        page = calibration_viewer(out, exp, inputs)
    except (FileNotFoundError, ViewerUnsupported) as exc:
        _log(f"calibrate: no viewer: {exc}")
        return None
    _log(f"calibrate: wrote the WebGL 2 viewer {page} (open it in a browser)")
    try:
        example = write_threejs(out, exp, inputs)
    except (FileNotFoundError, ThreeUnsupported) as exc:
        _log(f"calibrate: no three.js module: {exc}")
    else:
        _log(f"calibrate: wrote the three.js module and its example {example}")
    return page
