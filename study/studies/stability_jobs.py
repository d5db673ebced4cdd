"""Worker side of the stability study: one fit from one start, one fit against one noise level,
one fit with one loss, as jobs of the sweep engine (``study.studies.stability`` plans them and
analyses the table).

* :func:`multistart_job`: one solver from one start on one scene. The start is a point of a
  Latin hypercube over each parameter's :data:`BOX` (log-uniform where the box is marked
  ``log``); the fit is ``study.fit.solvers.fit`` with the calibration's stopping rule (loss
  stall ``FTOL`` over ``FTOL_WINDOW`` steps, the step cap ``max_steps``). Returns the final
  loss, iterations, seconds, whether it converged and why, the fitted constants, and the trace
  (lowest loss so far and seconds after each step) from which the analysis reads the time to
  the target loss.
* :func:`noise_job`: the calibration (``calibrate_model``: identifiability, bounds, standard
  errors) against a reference rendered at one spp / texture spp / seed; returns each constant,
  its status and relative standard error.
* :func:`loss_job`: the calibration with one residual (``linear`` RGB or ``log``), scored by
  FLIP and RMSE at the experiment's full resolution.

Failure classes (:func:`failure_class`): ``nonfinite`` (the model returned NaN/inf at a trial
point or the solver returned non-finite parameters), ``step_cap`` (stopped at ``max_steps``),
``error`` (anything else not converged), else ``converged``; ``another_basin`` is decided by
the analysis (converged, but the loss is not within 0.1 % of the best of all runs).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ..calibration.fitting import FitOptions, fit_frames, frame_models
from ..calibration.frames import Frame
from ..calibration.scoring import Scorer
from ..calibration.shader import Shader
from ..config.user_shader import is_user_shader
from ..fit.calibrate import DISCRETE, make_problem, scene_frozen
from ..fit.model import expand_parameters, get_value
from ..fit.solvers import FTOL, FTOL_SE, FTOL_WINDOW, fit
from ..sweep import load_scene

# Start box per constant (physical units) and whether to sample it log-uniformly. Wide enough
# to hold every value fitted on the shipped scenes, narrow enough to stay physically plausible.
BOX = {
    "attenuation_distance": (0.5, 30.0, True),
    "bumptex_mult": (0.25, 4.0, True),
    "water_color[0]": (0.0, 0.6, False),
    "water_color[1]": (0.0, 0.6, False),
    "water_color[2]": (0.0, 0.6, False),
    "specular_strength": (0.0, 8.0, False),
    "specular_exponent": (16.0, 2048.0, True),
    "reflect_color[0]": (0.0, 2.0, False),
    "reflect_color[1]": (0.0, 2.0, False),
    "reflect_color[2]": (0.0, 2.0, False),
}


def start_boxes(exp) -> dict:
    """The multistart's boxes of ``exp``'s fit, scalar name -> (lo, hi, log-uniform): the study's
    :data:`BOX` for its own constants (``fit.parameters``, without the step counts and what the
    scene freezes); for a user's shader, each declared constant's range, sampled log-uniformly
    when it starts above 0 and spans two decades or more (``Shader.start_boxes``)."""
    return Shader.of(exp).start_boxes(exp, _study_boxes)


def _study_boxes(exp) -> dict:
    """:data:`BOX` for the constants ``exp`` fits of a shader of the study's space."""
    frozen = scene_frozen(exp)
    names = [
        n for n in expand_parameters(exp.fit.parameters) if n not in DISCRETE and n not in frozen
    ]
    unknown = [k for k in names if k not in BOX]
    if unknown:
        raise ValueError(f"no start box for {unknown}; known: {sorted(BOX)}")
    return {n: BOX[n] for n in names}


def latin_hypercube(names: list[str], n: int, seed: int = 0, boxes: dict | None = None) -> list:
    """``n`` starts (dicts name -> value): one point per stratum of each parameter's box
    (``boxes``, name -> (lo, hi, log); default :data:`BOX`), strata paired at random (scipy's
    ``qmc.LatinHypercube``), log-uniform where the box says so."""
    from scipy.stats import qmc

    boxes = BOX if boxes is None else boxes
    unknown = [k for k in names if k not in boxes]
    if unknown:
        raise ValueError(f"no start box for {unknown}; known: {sorted(boxes)}")
    u = qmc.LatinHypercube(d=len(names), seed=seed).random(n)
    out = []
    for row in u:
        d = {}
        for k, q in zip(names, row):
            lo, hi, log = boxes[k]
            d[k] = (
                float(math.exp(math.log(lo) + q * (math.log(hi) - math.log(lo))))
                if log
                else float(lo + q * (hi - lo))
            )
        out.append(d)
    return out


def failure_class(converged: bool, message: str, iterations: int, max_steps: int) -> str:
    m = message.lower()
    if "non-finite" in m or "nonfinite" in m or "aborted" in m:
        return "nonfinite"
    if converged:
        return "converged"
    if iterations >= max_steps or "maximum number of steps" in m or "cap" in m:
        return "step_cap"
    return "error"


def solver_left_out(exp, solver: str) -> str | None:
    """Why ``solver`` cannot fit the experiment ``exp`` (None when it can): Adam needs the
    reverse-mode loss, which a user's shader executed through SPIR-V does not have (forward-
    mode derivatives only)."""
    if solver == "adam" and is_user_shader(exp.fit.shader):
        return (
            f"{Path(exp.fit.shader).name} is executed through SPIR-V, which has forward-mode "
            "derivatives only; Adam needs the reverse-mode loss"
        )
    return None


def _model(job, loss: str = "linear"):
    """(the job's scene as a ``Frame`` with the inputs ``fit.shader`` reads, its ``Shader``,
    its model at ``fit.resolution`` seen through the residual ``loss``)."""
    mv = job.get("mitsuba_variant", "llvm_ad_rgb")
    exp, ref, inputs = load_scene(job["scene"], mv)
    shader = Shader.of(exp)
    frame = Frame.of(exp, ref, shader.with_inputs(exp, inputs, mv))
    (model,) = frame_models([frame], shader, mv, FitOptions.of(exp, loss=loss))
    return frame, shader, model


def _fit(job: dict, loss: str = "linear"):
    """(frame, shader, model, ``Calibration``, seconds) of the job's scene fitted as ``study
    calibrate`` fits it (``study.calibration.fitting``), through the residual ``loss``."""
    frame, shader, model = _model(job, loss)
    mv = job.get("mitsuba_variant", "llvm_ad_rgb")
    t0 = time.perf_counter()
    fit = fit_frames([frame], shader, mv, FitOptions.of(frame.exp, loss=loss), models=[model])
    return frame, shader, model, fit.calibration, time.perf_counter() - t0


def multistart_job(job: dict) -> dict:
    """One fit: ``job = {"scene", "solver", "start": {name: value}, "names", "max_steps",
    "lr" (Adam), "start_index"}``."""
    frame, _, model = _model(job)
    start = model.start_constants(frame.exp)
    problem = make_problem(model, start, job["names"], progress=False)
    kw = {"lr": job["lr"]} if job["solver"] == "adam" else {}
    t0 = time.perf_counter()
    res = fit(
        problem,
        job["start"],
        solver=job["solver"],
        free=job["names"],
        max_steps=job["max_steps"],
        rtol=1e-6,
        atol=1e-9,
        ftol=FTOL,
        ftol_window=FTOL_WINDOW,
        ftol_se=FTOL_SE,
        **kw,
    )
    seconds = time.perf_counter() - t0
    loss = res.loss if math.isfinite(res.loss) else None
    return {
        "loss": loss,
        "loss_start": res.loss_start if math.isfinite(res.loss_start) else None,
        "iterations": res.iterations,
        "fit_seconds": seconds,
        "converged": res.converged,
        "message": res.message[:300],
        "failure": failure_class(res.converged, res.message, res.iterations, job["max_steps"]),
        "fitted": {n: float(res.constants[n]) for n in job["names"]},
        "trace_loss": [float(v) for v in res.step_losses],
        "trace_seconds": [float(v) for v in res.step_seconds],
    }


def noise_job(job: dict) -> dict:
    """The calibration against the job's scene (its spp, texture spp and seed are in the scene's
    overrides): constants, statuses and relative standard errors."""
    frame, _, model, cal, fit_s = _fit(job)
    names = model.parameter_names(frame.exp.fit.parameters)
    return {
        "fit_seconds": fit_s,
        "reference_noise": float(frame.ref.noise or float("nan")),
        "value": {n: get_value(cal.fitted, n) for n in names},
        "status": {n: cal.parameters[n]["status"] for n in names},
        "rel_se": {n: cal.parameters[n].get("rel_std_error") for n in names},
    }


def loss_job(job: dict) -> dict:
    """The calibration with residual ``job["loss"]``, scored at full resolution."""
    frame, shader, model, cal, fit_s = _fit(job, job["loss"])
    score = Scorer(shader, [frame], job.get("mitsuba_variant", "llvm_ad_rgb"))(0, cal.fitted)
    names = model.parameter_names(frame.exp.fit.parameters)
    return {
        "flip": score.flip,
        "rmse": score.rmse,
        "fit_seconds": fit_s,
        "iterations": cal.fit_summary.get("iterations", 0),
        "value": {n: get_value(cal.fitted, n) for n in names},
    }


def quantile(values, q: float):
    v = [x for x in values if x is not None and math.isfinite(x)]
    return float(np.quantile(v, q)) if v else None
