"""The main job: fit the shader's constants to an experiment's reference, export, report.

1. Reference (cached) and shader inputs; the port set up at ``fit.resolution`` against the
   box-downsampled reference (``ShaderModel``).
2. Identifiability at the start: the forward-mode Jacobian of the residual with respect to
   every requested continuous constant, column-scaled by each parameter's typical change
   (half its start value), goes through ``_identify.identify``; what the scene does not
   identify is frozen at its start value, with the reason.
3. Fit of the identified constants with the chosen solver (``fit.solver``).
   Constants whose range starts at 0 (colour channels, the specular strength) use the
   ``clip`` parametrisation (``study.fit.solvers``): linear inside the box, so a channel whose
   best value is 0 lands *on* 0 in one step instead of crawling towards it in a log scale;
   the solver stops when the loss stops improving (relative decrease over ``FTOL_WINDOW = 3``
   steps below ``max(1e-6, 1 / (m - k))``, an improvement worth less than one standard
   error of one parameter; ``study.fit.solvers.FTOL_SE``), not at the step cap.
4. Judged at the solution:

   * a constant left on a bound with the loss still falling outwards (the KKT sign, checked by
     the solver) has status ``bound``, its value the bound;
   * a constant that lost its sensitivity there (e.g. an attenuation distance pushed to where
     the attenuation clamp saturates, or to where it no longer attenuates at all) has status
     ``bound`` too: the data fix only one side of it, the exported value is the solver's;
   * a constant whose relative standard error at the solution exceeds ``REL_SE_MAX = 0.5``
     (its one-sigma interval spans more than half its value) is *not identified*: it is
     **frozen** at its start value and the rest refitted from the solution (the worst one
     per round, up to ``SE_ROUNDS`` rounds). Frozen rather than flagged because the exported
     shader needs one value, a value the data cannot pin is set by noise and model error, and
     a free unidentified constant drags the identified ones along its valley (on a stepped
     floor under a high sun no glint is in view and the specular pair absorbed model error
     with relative standard errors of 6 and 12). Standard errors come from the Gauss-Newton
     covariance ``s^2 (J^T J)^-1`` with ``s^2 = ||r||^2 / (m - k)``, which treats residuals
     as independent: model error is correlated across pixels, so these are lower bounds.
     When the model carries the reference's per-pixel standard error, each constant also gets
     ``rel_noise_error`` (:func:`noise_errors`): how much the reference's Monte Carlo noise
     alone moves it, the spread between renders of the same scene with other seeds. The sun's
     glitter makes that spread the larger of the two for the specular pair at a few hundred spp.
5. Step counts (``steps_grazing``, ``steps_steep``) are piecewise constant in their effect
   (the crossing step jumps), so no gradient solver sees them: when requested they are
   chosen by a 2-D sweep of the loss over a grid at the fitted continuous constants.
6. Errors (RMSE, FLIP) with the start and the fitted constants at the full resolution, the
   export into GLSL and its check on llvmpipe, figures and the report.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from shaders_port import Constants
from shaders_port.pipeline.texture import backend_types

from .._progress import log as _log
from .._progress import progress_line
from ..scene.mitsuba_scene import has_medium
from .identify import identify, sweep_1d, sweep_2d
from .model import get_value, with_values
from .normal_equations import forms_normal_equations
from .protocol import CalibrationModel
from .rounds import (
    REL_SE_MAX,
    basin_scans,
    fit_rounds,
    noise_errors,
    refine_decorrelated,
    std_errors,
)
from .solvers import FTOL, FTOL_SE, FTOL_WINDOW, FitProblem, Param

DISCRETE = ("steps_grazing", "steps_steep")
STEP_GRID = {
    "steps_grazing": [4.0, 6.0, 8.0, 10.0, 14.0, 20.0],
    "steps_steep": [1.0, 2.0, 3.0, 4.0, 6.0],
}


def make_problem(
    model: CalibrationModel,
    start,
    names: list[str],
    progress: bool = True,
    on_device: bool = False,
) -> FitProblem:
    """The fit problem over scalar constant ``names`` (e.g. 'water_color[1]') of ``model``, each
    kept in the model's range for it: a logistic transform, or ``clip`` (linear inside the box)
    for a range from 0 (a best value of 0 must be reachable) or a start on a bound.
    ``on_device``: the solvers see the normal equations the model forms where it shades
    (``model.normal_equations``, ``study.fit.normal_equations``)."""
    params = []
    for n in names:
        lo, hi = model.bounds(n)
        v = get_value(start, n)
        clip = (lo == 0.0 or not lo < v < hi) and n not in DISCRETE
        params.append(
            Param(
                n,
                v,
                lo,
                hi,
                scale=(0.5 * abs(v) if v else (0.1 if clip else None)),
                transform="clip" if clip else "auto",
                derivative_free=n in DISCRETE,
            )
        )
    count = {"n": 0}

    def note(r):
        count["n"] += 1
        if progress:
            progress_line(f"fit: evaluation {count['n']}, loss {0.5 * float(r @ r):.6g}")
        return r

    def residual(values: dict):
        return note(model.residual(with_values(start, values)))

    def residual_and_jacobian(values: dict, free: list[str]):
        r, J = model.residual_and_jacobian(with_values(start, values), free)
        return note(r), J

    def loss_drjit(values: dict):
        return model.loss_ad(with_values(start, values))

    def normal_equations(values: dict, free: list[str]):
        ne = model.normal_equations(with_values(start, values), free)
        count["n"] += 1
        if progress:
            progress_line(f"fit: evaluation {count['n']}, loss {ne.loss:.6g}")
        return ne

    if on_device and not forms_normal_equations(model):
        raise ValueError(
            f'fit.normal_equations = "device" needs fit.loss = "linear": the '
            f"{getattr(model, 'loss_name', 'model')!r} loss transforms each residual on the host"
        )
    backend = getattr(model, "backend", None)  # Adam's variables on the model's backend
    return FitProblem(
        params, residual, residual_and_jacobian, loss_drjit=loss_drjit, name="calibration",
        drjit_float=backend_types(backend).Float,
        normal_equations=normal_equations if on_device else None,
    )  # fmt: skip


def _ident_dict(rep, names, J=None, r=None, values=None) -> dict:
    out = {
        "names": list(names),
        "singular_values": rep.singular_values.tolist(),
        "condition": rep.condition if np.isfinite(rep.condition) else None,
        "sensitivity": [rep.sensitivity[n] for n in names],
        "decision": [
            "frozen: " + rep.reasons[n] if rep.freeze[n] else rep.reasons[n] for n in names
        ],
    }
    if J is not None:
        out["rel_std_error"] = std_errors(J, r, values)
    return out


@dataclass
class Calibration:
    """The result of :func:`calibrate_model` for every model: ``start`` and ``fitted`` constants
    (the model's kind: ``Constants`` or a dict of GLSL names), ``parameters`` (scalar name ->
    default, fitted, status fitted | bound | frozen | swept, reason, sensitivities, standard
    errors, basins), ``identifiability`` (at the start and at the solution), ``fit_summary``
    (the solver's), ``losses`` (per evaluation) and the step ``sweep`` (or None)."""

    start: Constants | dict
    fitted: Constants | dict
    parameters: dict
    identifiability: dict
    fit_summary: dict
    losses: list
    sweep: dict | None


def scene_frozen(exp) -> dict:
    """Constants the scene's physics cannot identify whatever the Jacobian says: clear water
    (``water.sigma_t = 0``) has no attenuation, so the shader's attenuation there could only be
    a blend towards a mean colour that happens to lower the error, not a distance."""
    if has_medium(exp):
        return {}
    why = (
        "the scene's water does not absorb (water.sigma_t = 0), so it cannot identify an "
        "attenuation distance; kept at the start value"
    )
    return {
        n: why for n in ("attenuation_distance", "absorption_r", "absorption_g", "absorption_b")
    }


def steps_to_within(step_losses: list, frac: float = 1e-3) -> int | None:
    """First step (1-based) whose lowest loss so far is within ``frac`` of the final one."""
    if not step_losses:
        return None
    final = step_losses[-1]
    for i, v in enumerate(step_losses):
        if v <= final * (1 + frac):
            return i + 1
    return len(step_losses)


def _parameter_table(
    names, start, fitted, frozen, bound, discrete, continuous, id0, ident, noise_se, scans
) -> dict:
    """``Calibration.parameters``: per constant its default, exported value, status and why."""
    params = {}
    for n in names:
        status = (
            "frozen"
            if n in frozen
            else "bound"
            if n in bound
            else "swept"
            if n in discrete
            else "fitted"
        )
        params[n] = {
            "default": get_value(start, n),
            "fitted": None if n in frozen else get_value(fitted, n),
            "frozen": n in frozen,
            "status": status,
            "reason": frozen.get(n)
            or bound.get(n)
            or ("chosen by the step sweep" if n in discrete else "identified and fitted"),
        }
        if n in continuous:
            params[n]["sensitivity_start"] = id0.sensitivity[n] if id0 is not None else None
            if "solution" in ident and n in ident["solution"]["names"]:
                j = ident["solution"]["names"].index(n)
                params[n]["sensitivity"] = ident["solution"]["sensitivity"][j]
                params[n]["rel_std_error"] = ident["solution"]["rel_std_error"][j]
                if n in noise_se:
                    params[n]["rel_noise_error"] = noise_se[n]
                if n in scans:
                    params[n]["basins"] = scans[n]
            else:
                params[n]["sensitivity"] = id0.sensitivity[n] if id0 is not None else None
    return params


def _fit_summary(sol, fits, refined, solver) -> dict:
    """``Calibration.fit_summary``: the last fit's summary over every round's steps."""
    if sol is None:
        return {"solver": solver, "iterations": 0, "converged": True, "message": "nothing to fit"}
    summary = sol.result.summary()
    steps = [f.iterations for f in fits]
    summary.update(
        {
            "iterations": int(sum(steps)),
            "rounds": len(fits),
            "iterations_per_round": steps,
            "step_losses": [v for f in fits for v in f.step_losses],
            "steps_to_0.1pct_per_round": [steps_to_within(f.step_losses) for f in fits],
            "ftol": FTOL,
            "ftol_se": FTOL_SE,
            "ftol_window": FTOL_WINDOW,
            "rel_se_max": REL_SE_MAX,
            "converged": all(f.converged for f in fits),
        }
    )
    if refined is not None:
        summary["input_noise"] = refined.summary()
    return summary


def calibrate_model(
    model: CalibrationModel,
    start: Constants | dict,
    requested: list[str] | None,
    solver: str,
    max_steps: int,
    frozen_by_scene: dict | None = None,
    halves: tuple | None = None,
    scan_basins: bool = False,
    basin_check: tuple | None = None,
    on_device: bool = False,
) -> Calibration:
    """Steps 2-5 of the module docstring on a prepared model. ``frozen_by_scene``: name ->
    reason for constants frozen before looking at the Jacobian (:func:`scene_frozen`).
    ``halves``: two models on the refraction texture's independent halves
    (``study.fit.decorrelated.half_models``); when given, the fitted constants are refined on
    the decorrelated loss (``study.fit.decorrelated.refine``) before the standard errors (the
    identifiability record stays that of the least-squares solution). ``scan_basins``: scan the
    loss along the constants of ``study.fit.basins.BASIN_PARAMETERS`` that were fitted; when a
    basin is lower than the fit's by more than the reference's noise explains (the solver
    stopped at a jump of the piecewise loss), refit once from the lowest such basin and keep
    whichever solution has the lower loss; then scan again at the solution and record the basins
    the noise cannot tell apart, and the restart, in ``parameters[name]["basins"]``.
    ``basin_check``: two models on the texture's independent halves
    (``study.fit.decorrelated.texture_half_models``); when given, a lower basin is refitted only
    if their decorrelated loss puts it lower too (``study.fit.basins.texture_delta``); one it
    does not is recorded as ``unconfirmed`` and reported.
    ``on_device``: the solver reads the normal equations formed where the model shades
    (:func:`make_problem`).
    ``requested`` names the constants to fit (``model.parameter_names`` turns them into scalar
    names: a variant fits its own in place of the seed's, e.g. the Beer-Lambert absorptions for
    ``attenuation_distance``; a user's shader, every declared constant when None)."""
    names = model.parameter_names(requested)
    pre = {n: why for n, why in (frozen_by_scene or {}).items() if n in names}
    continuous = [n for n in names if n not in DISCRETE and n not in pre]
    discrete = [n for n in names if n in DISCRETE]
    if not continuous and not discrete:
        raise ValueError(
            f"nothing left to fit: {sorted(pre)} frozen by the scene ({list(pre.values())})"
        )
    problem = make_problem(model, start, continuous + discrete, on_device=on_device)
    frozen = dict(pre)
    id0 = None
    if continuous:
        _, J0 = model.residual_and_jacobian(start, continuous)
        id0 = identify(J0, continuous, scales=[problem.params[n].typical for n in continuous])
        frozen.update({n: id0.reasons[n] for n in continuous if id0.freeze[n]})
    free = [n for n in continuous if n not in frozen]
    for n, why in frozen.items():
        _log(f"calibrate: freezing {n} at {get_value(start, n):.4g}: {why}")
    sigma = getattr(model, "reference_stderr", None)
    sigma_m = None if sigma is None else sigma[model.mask].astype(np.float64).ravel()
    sol, frozen, free, fits, losses, restart, scanned = fit_rounds(
        model, problem, start, free, frozen, solver, max_steps, sigma_m, scan_basins, basin_check
    )
    if sol is not None and not free:  # every constant frozen in the end: the start values
        sol.fitted = start
    measured = sol is not None and sol.id1 is not None and bool(sol.live)
    refined = None
    if halves is not None and measured:
        refined = refine_decorrelated(model, halves, problem, sol)
    fitted = sol.fitted if sol is not None else start
    bound = sol.bound if sol is not None else {}
    # the reference's noise in the last round's live columns (it decides nothing in the rounds)
    noise_se = {}
    if measured and sol.live and sigma is not None:
        noise_se = dict(zip(sol.live_names, noise_errors(sol.J1[:, sol.live], sigma_m, sol.vals)))
    scans = {}
    if scan_basins and measured and sol.live:
        scans = basin_scans(model, fitted, sol.live_names, sigma_m, scanned, restart)
    ident = {"start": _ident_dict(id0, continuous)} if id0 is not None else {}
    if sol is not None and sol.id1 is not None:
        inner = list(sol.id1.names)
        ident["solution"] = _ident_dict(sol.id1, inner)
        ident["solution"]["rel_std_error"] = [sol.se.get(n) for n in inner]
        if sol.se_tiles:
            ident["solution"]["rel_tile_error"] = [sol.se_tiles.get(n) for n in inner]
        if noise_se:
            ident["solution"]["rel_noise_error"] = [noise_se.get(n) for n in inner]
    sweep = None
    if discrete:
        sweep = step_sweep(problem, fitted, discrete)
        fitted = with_values(fitted, sweep["best"])
    params = _parameter_table(
        names, start, fitted, frozen, bound, discrete, continuous, id0, ident, noise_se, scans
    )
    return Calibration(
        start, fitted, params, ident, _fit_summary(sol, fits, refined, solver), losses, sweep
    )


def calibrate_experiment(
    model: CalibrationModel,
    exp,
    start: Constants | dict | None = None,
    requested: list[str] | None = None,
    halves: tuple | None = None,
) -> Calibration:
    """:func:`calibrate_model` of a model already built, with the experiment's fit settings
    (``fit.parameters``, ``fit.solver``, ``fit.max_steps``, the scene's own frozen constants)
    and no basin scan: the benchmarks' and tests' shortcut (every command and sweep fits
    through ``study.calibration.fitting.fit_frames``, whose options add the basin scan). From
    ``start`` (default: the model's start constants for the experiment) over ``requested``
    (default: ``fit.parameters``); ``halves`` as there (``fit.input_noise``:
    ``study.fit.decorrelated.half_models``)."""
    return calibrate_model(
        model,
        model.start_constants(exp) if start is None else start,
        exp.fit.parameters if requested is None else requested,
        exp.fit.solver,
        exp.fit.max_steps,
        frozen_by_scene=scene_frozen(exp),
        halves=halves,
    )


def step_sweep(problem: FitProblem, at: Constants, names: list[str]) -> dict:
    """Loss over the step-count grid (both counts, or one) at the other constants ``at``."""
    base = {n: get_value(at, n) for n in problem.names}
    if len(names) == 2:
        a, b = "steps_grazing", "steps_steep"
        grid = sweep_2d(problem, a, STEP_GRID[a], b, STEP_GRID[b], x=base)
        if not np.isfinite(grid).any():
            return {
                "names": [a, b],
                "grid": {a: STEP_GRID[a], b: STEP_GRID[b]},
                "loss": grid.tolist(),
                "best": {a: base[a], b: base[b]},
                "note": "every grid point was non-finite; kept the start",
            }
        i, j = np.unravel_index(np.nanargmin(grid), grid.shape)
        best = {a: STEP_GRID[a][i], b: STEP_GRID[b][j]}
        return {
            "names": [a, b],
            "grid": {a: STEP_GRID[a], b: STEP_GRID[b]},
            "loss": grid.tolist(),
            "best": best,
        }
    n = names[0]
    losses = sweep_1d(problem, n, STEP_GRID[n], x=base)
    if not np.isfinite(losses).any():
        return {
            "names": [n],
            "grid": {n: STEP_GRID[n]},
            "loss": losses.tolist(),
            "best": {n: base[n]},
            "note": "every grid point was non-finite; kept the start",
        }
    return {
        "names": [n],
        "grid": {n: STEP_GRID[n]},
        "loss": losses.tolist(),
        "best": {n: STEP_GRID[n][int(np.nanargmin(losses))]},
    }


def timed(timings: dict, key: str):
    class _T:
        def __enter__(self):
            self.t = time.perf_counter()

        def __exit__(self, *exc):
            timings[key] = time.perf_counter() - self.t

    return _T()
