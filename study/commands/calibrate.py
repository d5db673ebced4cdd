"""``study calibrate``: one command for every calibration. One experiment is a still scene or,
with ``animation.frames`` > 1, every frame of moving water (``study.commands.animated``);
several experiments are fitted jointly (``study.commands.joint``); ``fit.shader`` names a
shader of the study's space or a user's GLSL file, fitted alike (``study.fit.build``)."""

from __future__ import annotations

import time

from .._backend import drjit_backend
from .._progress import log as _log
from ..fit.build import build_model
from ..fit.calibrate import calibrate_model, scene_frozen, timed
from ..fit.decorrelated import half_models, texture_half_models
from ..fit.solvers import SOLVERS
from ..scene.animation import is_animated
from ..scene.views import has_views
from .animated import run_calibrate_animated
from .joint import run_calibrate_joint
from .steps import (
    calibration_figures,
    calibration_result,
    evaluate_calibration,
    export_calibration,
    load_scene_data,
    prepare,
    write_result,
)
from .viewer import write_viewer


def run_calibrate(experiment, out, overrides=None, variant=None, solver=None, cache=None) -> dict:
    """``study calibrate``: reference (cached), fit, export, GL check, figures, report.md and
    constants.json (a ``CalibrationResult``) in ``out``, for a shader of the study's space or a
    user's GLSL file alike (``study.fit.build.build_model``). ``experiment``: one experiment file,
    or a list of them: several are fitted jointly (``study.commands.joint``); an animated one
    (``animation.frames`` > 1) on all its frames (``study.commands.animated``). Returns the JSON
    object written."""
    if isinstance(experiment, (list, tuple)):
        if len(experiment) > 1:
            return run_calibrate_joint(experiment, out, overrides, variant, solver, cache)
        (experiment,) = experiment

    if solver is not None and solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; choose one of {', '.join(SOLVERS)}")
    t_start = time.perf_counter()
    exp, variant, out = prepare(experiment, out, overrides, variant, frames=True)
    setup_s = time.perf_counter() - t_start
    solver = solver or exp.fit.solver

    if has_views(exp):  # one constants block over the views: the joint fit's path
        return run_calibrate_joint([experiment], out, overrides, variant, solver, cache)
    if is_animated(exp):
        return run_calibrate_animated(exp, variant, out, solver, cache, setup_s)
    ref, inputs, timings = load_scene_data(exp, variant, cache)
    timings = {"setup_s": setup_s, **timings}
    model, cal = fit_still(exp, variant, ref, inputs, solver, timings)
    backend = model.backend
    with timed(timings, "evaluate_s"):
        ev = evaluate_calibration(exp, inputs, ref, model, cal, backend)
    (gl,), engine_targets, extra = export_calibration(exp, model, [inputs], cal, out, timings)
    with timed(timings, "figures_s"):
        figs = calibration_figures(out, exp, model, ref, ev, cal, solver)
    timings["total_s"] = time.perf_counter() - t_start  # up to the report (written last)
    result = calibration_result(exp, variant, model, ref, cal, ev, solver, timings, gl)
    result.engine_targets = engine_targets
    result.textures = extra.pop("textures")
    result.extra.update(extra)
    summary = write_result(out, result, figs, ev)
    write_viewer(out, exp, inputs)
    return summary


def fit_still(exp, variant: str, ref, inputs, solver: str, timings: dict):
    """The fit of a still scene, as ``study calibrate`` runs it: the model of ``fit.shader`` at
    ``fit.resolution`` on the backend of ``variant`` (timed as ``model_s``), its decorrelated
    halves or basin check, then :func:`calibrate_model` (``fit_s``). ``ref``: the scene's
    ``Reference``; ``inputs``: its ``ShaderInputs`` at ``resolution``. Returns (model, the
    ``Calibration``)."""
    backend = drjit_backend(variant)
    with timed(timings, "model_s"):
        model = build_model(exp, inputs, ref.image, backend=backend, stderr_full=ref.stderr)
        start = model.start_constants(exp)
        halves = half_models(exp, inputs, ref.image, backend=backend)
        check = halves or texture_half_models(exp, inputs, ref.image, backend=backend)
    names = model.parameter_names(exp.fit.parameters)
    _log(
        f"calibrate: fitting {', '.join(names)} of {model.label} with {solver} on "
        f"{int(model.mask.sum())} water pixels at "
        f"{exp.fit.resolution[0]}x{exp.fit.resolution[1]}"
    )
    with timed(timings, "fit_s"):
        cal = calibrate_model(
            model,
            start,
            exp.fit.parameters,
            solver,
            exp.fit.max_steps,
            frozen_by_scene=scene_frozen(exp),
            halves=halves,
            scan_basins=True,
            basin_check=check,
        )
    return model, cal
