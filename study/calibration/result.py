"""The one builder of a calibration's ``CalibrationResult`` (what ``constants.json`` holds), for
every form: one frame, several (views or experiments: the error per frame), an animation (the
error averaged over its frames), and the tradeoff's recommended point."""

from __future__ import annotations

import numpy as np

from .._io import repo_relative
from .._metrics import flip_map, information_criteria, rmse
from ..fit.model import constants_json
from ..export.result import CalibrationResult
from ..fit.joint import JointModel
from ..scene.user_scene import sun_summary


def _mean(scores: list, key: str) -> float:
    return float(np.mean([getattr(s, key) for s in scores]))


def result_error(kind: str, frames, scores: dict) -> dict:
    """The result's ``error``: ``scores`` is {"default": [Score per frame], "fitted": [...]}.
    One frame or an animation: {"rmse": {"default", "fitted"}, "flip": {...}} (an animation's
    averaged over its frames); views or experiments: frame name -> {"default": {"rmse",
    "flip"}, "fitted": {...}}."""
    if kind in ("still", "animated"):
        return {
            k: {which: _mean(scores[which], k) for which in ("default", "fitted")}
            for k in ("rmse", "flip")
        }
    return {
        f.name: {which: scores[which][i].errors for which in ("default", "fitted")}
        for i, f in enumerate(frames)
    }


def fit_resolution_error(model, constants) -> dict:
    """{"flip", "rmse"} on the water pixels of ``model``'s image at ``constants`` (at the fit's
    resolution, its samples a pixel folded) against its reference (box-downsampled)."""
    img, _ = model.render(constants)
    m = model.mask
    return {
        "flip": float(flip_map(model.reference, img)[m].mean()),
        "rmse": rmse(model.reference, img, m),
    }


def reference_record(ref) -> dict:
    """What a result records of a frame's reference (``Reference``)."""
    p = ref.provenance
    return {
        "spp": ref.spp,
        **{k: p.get(k) for k in ("spp_asked", "spp_per_pass", "n_seeds")},
        "sampler": p.get("sampler"),
        "noise": ref.noise,
        "path": repo_relative(ref.path),
        "key": p["key"],
    }


def build_result(frames, shader, fit, scores: dict, timings: dict, export, options):
    """The ``CalibrationResult`` of a calibration of ``shader`` over ``frames`` (``Frames``):
    ``fit`` (``study.calibration.fitting.Fit``), ``scores`` ({"default", "fitted"}: a
    ``Score`` per frame, ``study.calibration.scoring``), ``export``
    (``study.calibration.export.Export``), ``timings`` (stage -> seconds), ``options`` the
    fit's ``FitOptions`` (its solver and loss are recorded)."""
    cal, first = fit.calibration, frames[0]
    kind = frames.kind
    result = CalibrationResult(
        shader=shader.label,
        backend=frames.variant,
        parameters=cal.parameters,
        constants=constants_json(cal.fitted),
        error=result_error(kind, frames, scores),
        solver=options.solver,
        loss=options.loss,
        fit=cal.fit_summary,
        identifiability=cal.identifiability,
        timings=timings,
        gl_check=export.gl_check,
        engine_targets=export.engine_targets,
        textures=export.textures,
        export=export.words,
        extra=dict(export.extra),
    )
    if kind in ("still", "animated"):
        result.experiment = frames.experiment.name
        result.fit_resolution = list(first.exp.fit.resolution)
        result.resolution = list(first.exp.resolution)
        result.supersample = options.supersample(first.exp)
        if options.target_resolution is not None:
            result.target_resolution = list(options.target_resolution)
    if kind == "still":
        fitted = scores["fitted"][0]
        k = [n for n, p in cal.parameters.items() if p["status"] in ("fitted", "bound")]
        result.step_sweep = cal.sweep
        result.reference = reference_record(first.ref)
        result.diagnostics = fitted.diagnostics.summary(fitted.mask)
        result.sun = sun_summary(first.exp)
        result.fit_error = fit_resolution_error(fit.models[0], cal.fitted)
        result.parsimony = {
            **information_criteria(fit.models[0].residual(cal.fitted), len(k)),
            "fitted": k,
            "defines": list(fit.models[0].defines),
        }
    if kind in ("views", "joint"):
        weights = JointModel(fit.models).weights
        result.experiments = [repo_relative(f.path) for f in frames]
        result.scenes = [f.name for f in frames]
        result.weights = {f.name: float(w) for f, w in zip(frames, weights)}
    return result
