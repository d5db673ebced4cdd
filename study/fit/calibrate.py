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

import sys
import time
from dataclasses import dataclass

import numpy as np

from shaders_port import Constants

from .solvers import FTOL, FTOL_SE, FTOL_WINDOW, FitProblem, Param, fit
from .identify import identify, sweep_1d, sweep_2d
from .model import ShaderModel, bounds, expand_parameters, get_value, with_values

DISCRETE = ("steps_grazing", "steps_steep")
# solver stopping tolerances (on u = transformed parameters, where one unit is about a 50 %
# change, and on the loss): 1e-6 is far below the parameters' standard errors
FIT_RTOL, FIT_ATOL = 1e-6, 1e-9
# a constant whose standard error at the solution exceeds this fraction of its value is not
# identified (frozen at its start value, the rest refitted); at most SE_ROUNDS such rounds
REL_SE_MAX, SE_ROUNDS = 0.5, 4
STEP_GRID = {
    "steps_grazing": [4.0, 6.0, 8.0, 10.0, 14.0, 20.0],
    "steps_steep": [1.0, 2.0, 3.0, 4.0, 6.0],
}


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def make_problem(
    model: ShaderModel, start: Constants, names: list[str], progress: bool = True
) -> FitProblem:
    """The fit problem over scalar constant ``names`` (e.g. 'water_color[1]') of ``model``."""
    params = []
    for n in names:
        lo, hi = bounds(n)
        v = get_value(start, n)
        clip = lo == 0.0 and n not in DISCRETE  # a best value of 0 must be reachable
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
            print(
                f"\rfit: evaluation {count['n']}, loss {0.5 * float(r @ r):.6g}   ",
                end="",
                file=sys.stderr,
                flush=True,
            )
        return r

    def residual(values: dict):
        return note(model.residual(with_values(start, values)))

    def residual_and_jacobian(values: dict, free: list[str]):
        r, J = model.residual_and_jacobian(with_values(start, values), free)
        return note(r), J

    def loss_drjit(values: dict):
        return model.loss_ad(with_values(start, values))

    return FitProblem(
        params, residual, residual_and_jacobian, loss_drjit=loss_drjit, name="calibration"
    )


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


def noise_errors(J: np.ndarray, sigma: np.ndarray, values: np.ndarray) -> list[float | None]:
    """Relative standard errors of the constants from the reference's Monte Carlo noise alone:
    the sandwich ``A diag(sigma^2) A^T`` with ``A = (J^T J)^-1 J^T`` (the linearised least-squares
    solution's response to independent zero-mean noise of standard deviation ``sigma`` (M,) in
    the target), its diagonal's square root over |value|. Unlike :func:`std_errors` it does not
    read the residual, so it says how far another render of the same reference (another seed)
    moves each constant, whatever the model error."""
    m, k = J.shape
    if m < k:
        return [None] * k
    try:
        A = np.linalg.solve(J.T @ J, J.T)
    except np.linalg.LinAlgError:
        return [None] * k
    d = np.sqrt(np.maximum(np.einsum("km,m,km->k", A, np.square(sigma, dtype=np.float64), A), 0.0))
    return [float(x / abs(v)) if v else None for x, v in zip(d, values)]


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


def calibrate_model(
    model: ShaderModel,
    start: Constants,
    requested: list[str],
    solver: str,
    max_steps: int,
    frozen_by_scene: dict | None = None,
    halves: tuple | None = None,
    scan_basins: bool = False,
    basin_check: tuple | None = None,
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
    ``requested`` names the seed's constants; a variant fits its own in their place
    (``Variant.fit_names``, e.g. the Beer-Lambert absorptions for ``attenuation_distance``)."""
    names = expand_parameters(model.variant.fit_names(requested))
    pre = {n: why for n, why in (frozen_by_scene or {}).items() if n in names}
    continuous = [n for n in names if n not in DISCRETE and n not in pre]
    discrete = [n for n in names if n in DISCRETE]
    if not continuous and not discrete:
        raise ValueError(
            f"nothing left to fit: {sorted(pre)} frozen by the scene ({list(pre.values())})"
        )
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
    losses, result, bound, fits = [], None, {}, []
    fitted, x0 = start, None
    id1 = r1 = J1 = None
    se = {}
    sigma = getattr(model, "reference_stderr", None)
    sigma_m = None if sigma is None else sigma[model.mask].astype(np.float64).ravel()
    restart, before_restart = None, None
    scanned: dict = {}  # name -> (the constants it was scanned at, the scan)
    for rnd in range(SE_ROUNDS + 2):  # one more round than freezing needs: a basin restart
        if not free:
            break
        id1 = None
        result = fit(
            problem,
            x0,
            solver=solver,
            free=free,
            max_steps=max_steps,
            rtol=FIT_RTOL,
            atol=FIT_ATOL,
            ftol=FTOL,
            ftol_window=FTOL_WINDOW,
            ftol_se=FTOL_SE,
        )
        print(file=sys.stderr)
        fits.append(result)
        losses += list(result.losses)
        fitted = with_values(start, {n: result.constants[n] for n in free})
        _log(
            f"calibrate: {solver}: loss {result.loss_start:.6g} -> {result.loss:.6g} "
            f"in {result.iterations} iterations ({result.message})"
        )
        at_bound = result.extra.get("at_bound", {})
        bound = {
            n: (
                f"on its {side} bound {get_value(fitted, n):.4g}: the loss still falls beyond "
                "it, so the data want a value outside the constant's range; exported at the bound"
            )
            for n, side in at_bound.items()
        }
        inner = [n for n in free if n not in bound]
        if not inner:
            break
        r1, J1 = model.residual_and_jacobian(fitted, inner)
        id1 = identify(J1, inner, scales=[problem.params[n].typical for n in inner])
        for n in inner:
            if id1.freeze[n]:
                bound[n] = (
                    f"one-sided: at the solution ({get_value(fitted, n):.4g}) the image no longer "
                    f"depends on it ({id1.reasons[n]}); any value beyond it in the same direction "
                    "gives the same image, so only a bound is identified"
                )
                _log(f"calibrate: {n} is only bounded by the data: {bound[n]}")
        live = [i for i, n in enumerate(inner) if n not in bound]  # columns with a free direction
        vals = np.array([get_value(fitted, inner[i]) for i in live])
        se = dict(zip([inner[i] for i in live], std_errors(J1[:, live], r1, vals))) if live else {}
        judged = {n: v for n, v in se.items() if v is not None}
        worst = max(judged, key=judged.get) if judged else None
        if worst is None or judged[worst] <= REL_SE_MAX or rnd >= SE_ROUNDS:
            if scan_basins and restart is None:
                restart = _basin_restart(
                    model,
                    fitted,
                    [inner[i] for i in live],
                    sigma_m,
                    result.loss,
                    scanned,
                    basin_check,
                )
                if restart:
                    before_restart = (
                        result,
                        fitted,
                        bound,
                        inner,
                        r1,
                        J1,
                        id1,
                        live,
                        vals,
                        se,
                        dict(frozen),
                        list(free),
                    )
                    x0 = {n: result.constants[n] for n in problem.names}
                    x0[restart["name"]] = restart["to"]
                    continue
            break
        frozen[worst] = (
            f"not identified at the solution: relative standard error {judged[worst]:.3g} "
            f"> {REL_SE_MAX:g} (at {get_value(fitted, worst):.4g}); frozen at the start "
            "value, the rest refitted"
        )
        _log(f"calibrate: freezing {worst} at {get_value(start, worst):.4g}: {frozen[worst]}")
        free = [n for n in free if n != worst]
        x0 = {n: result.constants[n] for n in problem.names if n != worst}
        x0[worst] = get_value(start, worst)
    if restart and before_restart is not None:
        restart["loss_after"] = float(result.loss)
        restart["kept"] = bool(result.loss < restart["loss_before"])
        if not restart["kept"]:  # the restart found nothing better: back to the first solution
            result, fitted, bound, inner, r1, J1, id1, live, vals, se, frozen, free = before_restart
        _log(
            f"calibrate: restart from the {restart['name']} basin at {restart['to']:.4g}: loss "
            f"{restart['loss_before']:.6g} -> {restart['loss_after']:.6g}, "
            + ("kept" if restart["kept"] else "not lower; the first solution kept")
        )
    if not free:
        fitted = start
    refined = None
    if halves is not None and id1 is not None and live:
        from .decorrelated import refine

        refined = refine(halves[0], halves[1], problem.params, fitted, [inner[i] for i in live])
        _log(
            f"calibrate: decorrelated loss {refined.loss_start:.6g} -> {refined.loss:.6g} in "
            f"{refined.steps} damped Newton steps ({refined.message})"
        )
        if refined.accepted:
            fitted = refined.fitted
            for n, side in refined.at_bound.items():
                bound[n] = (
                    f"on its {side} bound {get_value(fitted, n):.4g} after the decorrelated "
                    "refinement (fit.input_noise); exported at the bound"
                )
            live = [i for i in live if inner[i] not in bound]
            r1, J1 = model.residual_and_jacobian(fitted, inner)
            vals = np.array([get_value(fitted, inner[i]) for i in live])
            se = (
                dict(zip([inner[i] for i in live], std_errors(J1[:, live], r1, vals)))
                if live
                else {}
            )
    # the reference's noise in the last round's live columns (it decides nothing in the rounds)
    noise_se = {}
    if id1 is not None and live and sigma is not None:
        noise_se = dict(zip([inner[i] for i in live], noise_errors(J1[:, live], sigma_m, vals)))
    scans = {}
    if scan_basins and id1 is not None and live:
        from .basins import BASIN_PARAMETERS, scan

        for n in BASIN_PARAMETERS:
            if n in [inner[i] for i in live]:
                at, done = scanned.get(n, (None, None))
                scans[n] = (
                    done if at is fitted else scan(model, fitted, n, sigma_m)
                )  # moved since: again
                if restart and restart["name"] == n:
                    scans[n]["restart"] = restart
                told = {o["value"] for o in scans[n].get("unconfirmed", [])}  # reported as such
                for key, what in (
                    (
                        "indistinguishable",
                        "other basins the reference's noise cannot tell from the fit's",
                    ),
                    (
                        "lower",
                        "basins lower than the fit's by more than the reference's noise "
                        "explains (the solver stopped short)",
                    ),
                ):
                    values = [v for v in scans[n][key] if v not in told]
                    if values:
                        _log(
                            f"calibrate: {n}: {what} ({get_value(fitted, n):.4g}): "
                            f"{', '.join(f'{v:.4g}' for v in values)}"
                        )
    ident = {"start": _ident_dict(id0, continuous)} if id0 is not None else {}
    if id1 is not None:
        inner = list(id1.names)
        ident["solution"] = _ident_dict(id1, inner)
        ident["solution"]["rel_std_error"] = [se.get(n) for n in inner]
        if noise_se:
            ident["solution"]["rel_noise_error"] = [noise_se.get(n) for n in inner]
    sweep = None
    if discrete:
        sweep = step_sweep(problem, fitted, discrete)
        fitted = with_values(fitted, sweep["best"])
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
    if result is not None:
        summary = result.summary()
        steps = [f.iterations for f in fits]
        trace = [v for f in fits for v in f.extra.get("step_losses", [])]
        summary.update(
            {
                "iterations": int(sum(steps)),
                "rounds": len(fits),
                "iterations_per_round": steps,
                "step_losses": trace,
                "steps_to_0.1pct_per_round": [
                    steps_to_within(f.extra.get("step_losses", [])) for f in fits
                ],
                "ftol": FTOL,
                "ftol_se": FTOL_SE,
                "ftol_window": FTOL_WINDOW,
                "rel_se_max": REL_SE_MAX,
                "converged": all(f.converged for f in fits),
            }
        )
        if refined is not None:
            summary["input_noise"] = refined.summary()
    else:
        summary = {
            "solver": solver,
            "iterations": 0,
            "converged": True,
            "message": "nothing to fit",
        }
    return Calibration(start, fitted, params, ident, summary, losses, sweep)


def _basin_restart(
    model,
    fitted: Constants,
    live: list[str],
    sigma_m,
    loss: float,
    scanned: dict,
    check: tuple | None = None,
) -> dict | None:
    """The restart the basin scan asks for: the lowest basin of a ``BASIN_PARAMETERS`` constant
    that is lower than the fit's by more than the reference's noise explains and, with ``check``
    (two models on the texture's halves), lower in their decorrelated loss too (``name``,
    ``from``, ``to``, ``loss_before``, ``texture_delta``), or None. Each scan goes into
    ``scanned`` (name -> (``fitted``, scan)), so that the report reuses it when the solution does
    not move; a lower basin the halves do not confirm is added to the scan's ``unconfirmed``."""
    from .basins import BASIN_PARAMETERS, scan, texture_delta

    for n in BASIN_PARAMETERS:
        if n not in live or sigma_m is None:
            continue
        s = scan(model, fitted, n, sigma_m)
        scanned[n] = (fitted, s)
        s["unconfirmed"] = []
        for best in sorted(
            (b for b in s["basins"] if b["value"] in s["lower"]), key=lambda b: b["delta_loss"]
        ):
            td = texture_delta(check[0], check[1], fitted, n, best["value"]) if check else None
            head = (
                f"calibrate: {n}: a basin at {best['value']:.4g} is lower than the fit's "
                f"({get_value(fitted, n):.4g}) by {-best['delta_loss']:.4g} (+- {best['noise_sd']:.2g} from the "
                "reference's noise"
            )
            if td is not None and td >= 0.0:
                s["unconfirmed"].append({**best, "texture_delta": td})
                _log(
                    f"{head}), but higher by {td:.4g} in the decorrelated loss of the texture's independent "
                    "halves: the texture's noise or denoiser makes it lower; not refitted"
                )
                continue
            _log(
                head
                + (f"; by {-td:.4g} in the texture halves' decorrelated loss" if check else "")
                + "); refitting from there"
            )
            return {
                "name": n,
                "from": get_value(fitted, n),
                "to": best["value"],
                "loss_before": float(loss),
                "texture_delta": td,
            }
    return None


def calibrate_experiment(
    model: ShaderModel,
    exp,
    start: Constants | None = None,
    requested: list[str] | None = None,
    halves: tuple | None = None,
) -> Calibration:
    """:func:`calibrate_model` with the experiment's fit settings (``fit.parameters``,
    ``fit.solver``, ``fit.max_steps``, the scene's own frozen constants), from ``start`` (default:
    the experiment's start constants) over ``requested`` (default: ``fit.parameters``);
    ``halves`` as there (``fit.input_noise``: ``study.fit.decorrelated.half_models``)."""
    from .model import constants_from_experiment

    return calibrate_model(
        model,
        constants_from_experiment(exp) if start is None else start,
        exp["fit.parameters"] if requested is None else requested,
        exp["fit.solver"],
        exp["fit.max_steps"],
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
