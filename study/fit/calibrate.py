"""The main job: fit the shader's constants to an experiment's reference, export, report.

1. Reference (cached) and shader inputs; the port set up at ``fit.resolution`` against the
   box-downsampled reference (``ShaderModel``).
2. Identifiability at the start: the forward-mode Jacobian of the residual with respect to
   every requested continuous constant, column-scaled by each parameter's typical change
   (half its start value), goes through ``_identify.identify``; what the scene does not
   identify is frozen at its start value, with the reason.
3. Fit of the identified constants with the chosen solver (``fit.solver``).
4. Identifiability again at the solution. A constant that lost its identifiability there
   (e.g. an attenuation distance pushed to where the attenuation clamp saturates, or to
   where it no longer attenuates at all) has status ``bound``: the data fix only one side
   of it, the exported value is the solver's, and the report says so instead of claiming
   a fitted value. Relative standard errors at the solution come from the Gauss-Newton
   covariance.
5. Step counts (``steps_grazing``, ``steps_steep``) are piecewise constant in their effect
   (the crossing step jumps), so no gradient solver sees them: when requested they are
   chosen by a 2-D sweep of the loss over a grid at the fitted continuous constants.
6. Errors (RMSE, FLIP) with the start and the fitted constants at the full resolution, the
   export into GLSL and its check on llvmpipe, figures and the report.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import numpy as np

from shaders_port import Constants

from .solvers import FitProblem, Param, fit
from .identify import identify, sweep_1d, sweep_2d
from .model import ShaderModel, bounds, expand_parameters, get_value, with_values

DISCRETE = ("steps_grazing", "steps_steep")
# solver stopping tolerances (on u = transformed parameters, where one unit is about a 50 %
# change, and on the loss): 1e-6 is far below the parameters' standard errors
FIT_RTOL, FIT_ATOL = 1e-6, 1e-9
STEP_GRID = {"steps_grazing": [4.0, 6.0, 8.0, 10.0, 14.0, 20.0], "steps_steep": [1.0, 2.0, 3.0, 4.0, 6.0]}


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def make_problem(model: ShaderModel, start: Constants, names: list[str], progress: bool = True) -> FitProblem:
    """The fit problem over scalar constant ``names`` (e.g. 'water_color[1]') of ``model``."""
    params = []
    for n in names:
        lo, hi = bounds(n)
        v = get_value(start, n)
        params.append(Param(n, v, lo, hi, scale=0.5 * abs(v) if v else None,
                            derivative_free=n in DISCRETE))
    count = {"n": 0}

    def note(r):
        count["n"] += 1
        if progress:
            print(f"\rfit: evaluation {count['n']}, loss {0.5 * float(r @ r):.6g}   ", end="",
                  file=sys.stderr, flush=True)
        return r

    def residual(values: dict):
        return note(model.residual(with_values(start, values)))

    def residual_and_jacobian(values: dict, free: list[str]):
        r, J = model.residual_and_jacobian(with_values(start, values), free)
        return note(r), J

    def loss_drjit(values: dict):
        return model.loss_ad(with_values(start, values))

    return FitProblem(params, residual, residual_and_jacobian, loss_drjit=loss_drjit, name="calibration")


def std_errors(J: np.ndarray, r: np.ndarray, values: np.ndarray) -> list[float | None]:
    """Relative standard errors sqrt(diag(s^2 (J^T J)^-1)) / |value|, s^2 = ||r||^2 / (m - k)."""
    m, k = J.shape
    if m <= k:
        return [None] * k
    s2 = float(r @ r) / (m - k)
    try:
        cov = s2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return [None] * k
    d = np.sqrt(np.maximum(np.diag(cov), 0.0))
    return [float(x / abs(v)) if v else None for x, v in zip(d, values)]


def _ident_dict(rep, names, J=None, r=None, values=None) -> dict:
    out = {"names": list(names), "singular_values": rep.singular_values.tolist(),
           "condition": rep.condition if np.isfinite(rep.condition) else None,
           "sensitivity": [rep.sensitivity[n] for n in names],
           "decision": ["frozen: " + rep.reasons[n] if rep.freeze[n] else rep.reasons[n] for n in names]}
    if J is not None:
        out["rel_std_error"] = std_errors(J, r, values)
    return out


@dataclass
class Calibration:
    start: Constants
    fitted: Constants
    parameters: dict
    identifiability: dict
    fit_summary: dict
    losses: list
    sweep: dict | None


def scene_frozen(exp) -> dict:
    """Constants the scene's physics cannot identify whatever the Jacobian says: clear water
    (``water.sigma_t = 0``) has no attenuation, so the shader's attenuation there could only be
    a blend towards a mean colour that happens to lower the error, not a distance."""
    from ..scene.mitsuba_scene import has_medium
    if has_medium(exp):
        return {}
    why = ("the scene's water does not absorb (water.sigma_t = 0), so it cannot identify an "
           "attenuation distance; kept at the start value")
    return {n: why for n in ("attenuation_distance", "absorption_r", "absorption_g", "absorption_b")}


def calibrate_model(model: ShaderModel, start: Constants, requested: list[str], solver: str,
                    max_steps: int, frozen_by_scene: dict | None = None) -> Calibration:
    """Steps 2-5 of the module docstring on a prepared model. ``frozen_by_scene``: name ->
    reason for constants frozen before looking at the Jacobian (:func:`scene_frozen`).
    ``requested`` names the seed's constants; a variant fits its own in their place
    (``Variant.fit_names``, e.g. the Beer-Lambert absorptions for ``attenuation_distance``)."""
    names = expand_parameters(model.variant.fit_names(requested))
    pre = {n: why for n, why in (frozen_by_scene or {}).items() if n in names}
    continuous = [n for n in names if n not in DISCRETE and n not in pre]
    discrete = [n for n in names if n in DISCRETE]
    if not continuous and not discrete:
        raise ValueError(f"nothing left to fit: {sorted(pre)} frozen by the scene ({list(pre.values())})")
    problem = make_problem(model, start, continuous + discrete)
    frozen = dict(pre)
    id0 = None
    if continuous:
        _, J0 = model.residual_and_jacobian(start, continuous)
        id0 = identify(J0, continuous, scales=[problem.params[n].typical for n in continuous])
        frozen.update({n: id0.reasons[n] for n in continuous if id0.freeze[n]})
    free = [n for n in continuous if n not in frozen]
    for n, why in frozen.items():
        _log(f"calibrate: freezing {n} at {get_value(start, n):.4g}: {why}")
    losses, result, bound = [], None, {}
    fitted = start
    if free:
        result = fit(problem, solver=solver, free=free, max_steps=max_steps, rtol=FIT_RTOL, atol=FIT_ATOL)
        print(file=sys.stderr)
        losses += list(result.losses)
        fitted = with_values(start, {n: result.constants[n] for n in free})
        _log(f"calibrate: {solver}: loss {result.loss_start:.6g} -> {result.loss:.6g} "
             f"in {result.iterations} iterations ({result.message})")
        r1, J1 = model.residual_and_jacobian(fitted, free)
        id1 = identify(J1, free, scales=[problem.params[n].typical for n in free])
        for n in free:
            if id1.freeze[n]:
                bound[n] = (f"one-sided: at the solution ({get_value(fitted, n):.4g}) the image no longer "
                            f"depends on it ({id1.reasons[n]}); any value beyond it in the same direction "
                            "gives the same image, so only a bound is identified")
                _log(f"calibrate: {n} is only bounded by the data: {bound[n]}")
    ident = {"start": _ident_dict(id0, continuous)} if id0 is not None else {}
    if free:
        vals = np.array([get_value(fitted, n) for n in free])
        ident["solution"] = _ident_dict(id1, free, J1, r1, vals)
    sweep = None
    if discrete:
        sweep = step_sweep(problem, fitted, discrete)
        fitted = with_values(fitted, sweep["best"])
    params = {}
    for n in names:
        status = "frozen" if n in frozen else "bound" if n in bound else "swept" if n in discrete else "fitted"
        params[n] = {"default": get_value(start, n), "fitted": None if n in frozen else get_value(fitted, n),
                     "frozen": n in frozen, "status": status,
                     "reason": frozen.get(n) or bound.get(n) or ("chosen by the step sweep" if n in discrete
                                                                  else "identified and fitted")}
        if n in continuous:
            params[n]["sensitivity_start"] = id0.sensitivity[n] if id0 is not None else None
            if "solution" in ident and n in ident["solution"]["names"]:
                j = ident["solution"]["names"].index(n)
                params[n]["sensitivity"] = ident["solution"]["sensitivity"][j]
                params[n]["rel_std_error"] = ident["solution"].get("rel_std_error", [None] * len(free))[j]
            else:
                params[n]["sensitivity"] = id0.sensitivity[n] if id0 is not None else None
    summary = result.summary() if result is not None else {"solver": solver, "iterations": 0,
                                                           "converged": True, "message": "nothing to fit"}
    return Calibration(start, fitted, params, ident, summary, losses, sweep)


def step_sweep(problem: FitProblem, at: Constants, names: list[str]) -> dict:
    """Loss over the step-count grid (both counts, or one) at the other constants ``at``."""
    base = {n: get_value(at, n) for n in problem.names}
    if len(names) == 2:
        a, b = "steps_grazing", "steps_steep"
        grid = sweep_2d(problem, a, STEP_GRID[a], b, STEP_GRID[b], x=base)
        if not np.isfinite(grid).any():
            return {"names": [a, b], "grid": {a: STEP_GRID[a], b: STEP_GRID[b]}, "loss": grid.tolist(),
                    "best": {a: base[a], b: base[b]}, "note": "every grid point was non-finite; kept the start"}
        i, j = np.unravel_index(np.nanargmin(grid), grid.shape)
        best = {a: STEP_GRID[a][i], b: STEP_GRID[b][j]}
        return {"names": [a, b], "grid": {a: STEP_GRID[a], b: STEP_GRID[b]}, "loss": grid.tolist(), "best": best}
    n = names[0]
    losses = sweep_1d(problem, n, STEP_GRID[n], x=base)
    if not np.isfinite(losses).any():
        return {"names": [n], "grid": {n: STEP_GRID[n]}, "loss": losses.tolist(), "best": {n: base[n]},
                "note": "every grid point was non-finite; kept the start"}
    return {"names": [n], "grid": {n: STEP_GRID[n]}, "loss": losses.tolist(),
            "best": {n: STEP_GRID[n][int(np.nanargmin(losses))]}}


def timed(timings: dict, key: str):
    class _T:
        def __enter__(self):
            self.t = time.perf_counter()

        def __exit__(self, *exc):
            timings[key] = time.perf_counter() - self.t
    return _T()
