"""The fitting rounds of a calibration (steps 3-5 of ``calibrate``'s module docstring): fit the
free constants, judge the solution (bounds, one-sided constants, standard errors), freeze the
worst-identified constant and refit, restart once from a lower basin of the loss, refine on the
texture halves' decorrelated loss, and scan the loss along the constants that have basins."""

from __future__ import annotations

import sys
from dataclasses import dataclass, field

import numpy as np

from shaders_port import Constants

from .._progress import log as _log
from .basins import BASIN_PARAMETERS, scan, texture_delta
from .decorrelated import refine
from .identify import identify
from .model import get_value, with_values
from .solvers import CALIBRATION_SETTINGS, fit

# a constant whose standard error at the solution exceeds this fraction of its value is not
# identified (frozen at its start value, the rest refitted); at most SE_ROUNDS such rounds
REL_SE_MAX, SE_ROUNDS = 0.5, 4


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


def tile_errors(J: np.ndarray, r: np.ndarray, tiles: np.ndarray, values: np.ndarray):
    """Relative standard errors that hold when the model is wrong in ways correlated over the
    image: the cluster sandwich ``(J^T J)^-1 (sum_t J_t^T r_t r_t^T J_t) (J^T J)^-1 G / (G - 1)``
    with the residuals (M,) grouped by image tile, ``tiles`` (M,) int (a tile's residuals may
    share an error: a glint the shader puts elsewhere, a wave it does not have), its diagonal's
    square root over |value|. Unlike :func:`std_errors` it does not assume independent residuals
    of one variance; None for every constant where there are not more tiles than constants."""
    m, k = J.shape
    ids, inverse = np.unique(np.asarray(tiles), return_inverse=True)
    g = len(ids)
    if g <= k or len(tiles) != m:
        return [None] * k
    try:
        bread = np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return [None] * k
    scores = np.zeros((g, k))
    np.add.at(scores, inverse, J * r[:, None])
    cov = bread @ (scores.T @ scores) @ bread * (g / (g - 1))
    d = np.sqrt(np.maximum(np.diag(cov), 0.0))
    return [float(x / abs(v)) if v else None for x, v in zip(d, values)]


@dataclass
class Solution:
    """One round's solution and what was measured at it: the solver's ``result``, the fitted
    constants, the constants that ended on a bound (name -> reason), the ``inner`` ones (fitted,
    not on a bound) with the residual ``r1`` (m,) and Jacobian ``J1`` (m, len(inner)) there,
    their identifiability ``id1``, the ``live`` columns (a free direction) with their values,
    relative standard errors ``se`` and those robust to model error over image tiles
    ``se_tiles`` (:func:`tile_errors`). ``id1`` is None when nothing was left inside the bounds."""

    result: object
    fitted: Constants
    bound: dict
    inner: list
    r1: np.ndarray | None = None
    J1: np.ndarray | None = None
    id1: object = None
    live: list = field(default_factory=list)
    vals: np.ndarray | None = None
    se: dict = field(default_factory=dict)
    se_tiles: dict = field(default_factory=dict)

    @property
    def live_names(self) -> list[str]:
        return [self.inner[i] for i in self.live]


def solve_round(model, problem, start, x0, free, solver, max_steps) -> Solution:
    """One fit of the ``free`` constants from ``x0``, then its bounds, identifiability and
    standard errors (a constant the image stops depending on at the solution is one-sided)."""
    result = fit(
        problem, x0, solver=solver, free=free, settings=CALIBRATION_SETTINGS, max_steps=max_steps
    )
    print(file=sys.stderr)
    fitted = with_values(start, {n: result.constants[n] for n in free})
    _log(
        f"calibrate: {solver}: loss {result.loss_start:.6g} -> {result.loss:.6g} "
        f"in {result.iterations} steps: {result.message.removeprefix('converged: ')}"
    )
    bound = {
        n: (
            f"on its {side} bound {get_value(fitted, n):.4g}: the loss still falls beyond "
            "it, so the data want a value outside the constant's range; exported at the bound"
        )
        for n, side in result.at_bound.items()
    }
    inner = [n for n in free if n not in bound]
    sol = Solution(result, fitted, bound, inner)
    if not inner:
        return sol
    sol.r1, sol.J1 = model.residual_and_jacobian(fitted, inner)
    sol.id1 = identify(sol.J1, inner, scales=[problem.params[n].typical for n in inner])
    for n in inner:
        if sol.id1.freeze[n]:
            bound[n] = (
                f"one-sided: at the solution ({get_value(fitted, n):.4g}) the image no longer "
                f"depends on it ({sol.id1.reasons[n]}); any value beyond it in the same direction "
                "gives the same image, so only a bound is identified"
            )
            _log(f"calibrate: {n} is only bounded by the data: {bound[n]}")
    sol.live = [i for i, n in enumerate(inner) if n not in bound]  # columns with a free direction
    _standard_errors(sol)
    tiles = getattr(model, "residual_tiles", None)
    if sol.live and tiles is not None:
        errs = tile_errors(sol.J1[:, sol.live], sol.r1, tiles(), sol.vals)
        sol.se_tiles = dict(zip(sol.live_names, errs))
    return sol


def _standard_errors(sol: Solution) -> None:
    """``sol.vals`` and ``sol.se`` of the live columns, from ``sol.J1`` and ``sol.r1``."""
    sol.vals = np.array([get_value(sol.fitted, n) for n in sol.live_names])
    sol.se = (
        dict(zip(sol.live_names, std_errors(sol.J1[:, sol.live], sol.r1, sol.vals)))
        if sol.live
        else {}
    )


def fit_rounds(
    model, problem, start, free, frozen, solver, max_steps, sigma_m, scan_basins, basin_check
):
    """Steps 3-4: fit, freeze the worst-identified constant and refit (at most ``SE_ROUNDS``
    times), and once, from a lower basin of the loss. Returns ``(solution or None, frozen,
    free, fits, losses, restart, scanned)``; ``frozen`` is updated in place."""
    sol, fits, losses, x0 = None, [], [], None
    restart, before_restart = None, None
    scanned: dict = {}  # name -> (the constants it was scanned at, the scan)
    for rnd in range(SE_ROUNDS + 2):  # one more round than freezing needs: a basin restart
        if not free:
            break
        sol = solve_round(model, problem, start, x0, free, solver, max_steps)
        fits.append(sol.result)
        losses += list(sol.result.losses)
        if sol.id1 is None:
            break
        judged = {n: v for n, v in sol.se.items() if v is not None}
        worst = max(judged, key=judged.get) if judged else None
        if worst is None or judged[worst] <= REL_SE_MAX or rnd >= SE_ROUNDS:
            if scan_basins and restart is None:
                restart = basin_restart(
                    model,
                    sol.fitted,
                    sol.live_names,
                    sigma_m,
                    sol.result.loss,
                    scanned,
                    basin_check,
                )
                if restart:
                    before_restart = (sol, dict(frozen), list(free))
                    x0 = {n: sol.result.constants[n] for n in problem.names}
                    x0[restart["name"]] = restart["to"]
                    continue
            break
        frozen[worst] = (
            f"not identified at the solution: relative standard error {judged[worst]:.3g} "
            f"> {REL_SE_MAX:g} (at {get_value(sol.fitted, worst):.4g}); frozen at the start "
            "value, the rest refitted"
        )
        _log(f"calibrate: freezing {worst} at {get_value(start, worst):.4g}: {frozen[worst]}")
        free = [n for n in free if n != worst]
        x0 = {n: sol.result.constants[n] for n in problem.names if n != worst}
        x0[worst] = get_value(start, worst)
    if restart and before_restart is not None:
        restart["loss_after"] = float(sol.result.loss)
        restart["kept"] = bool(sol.result.loss < restart["loss_before"])
        if not restart["kept"]:  # the restart found nothing better: back to the first solution
            sol, frozen_before, free = before_restart
            frozen.clear()
            frozen.update(frozen_before)
        _log(
            f"calibrate: restart from the {restart['name']} basin at {restart['to']:.4g}: loss "
            f"{restart['loss_before']:.6g} -> {restart['loss_after']:.6g}, "
            + ("kept" if restart["kept"] else "not lower; the first solution kept")
        )
    return sol, frozen, free, fits, losses, restart, scanned


def refine_decorrelated(model, halves, problem, sol: Solution):
    """Step 5 with ``fit.input_noise``: the live constants refined on the decorrelated loss of
    the texture's two halves; ``sol`` updated in place when the refinement is accepted."""
    refined = refine(halves[0], halves[1], problem.params, sol.fitted, sol.live_names)
    _log(
        f"calibrate: decorrelated loss {refined.loss_start:.6g} -> {refined.loss:.6g} in "
        f"{refined.steps} damped Newton steps ({refined.message})"
    )
    if refined.accepted:
        sol.fitted = refined.fitted
        for n, side in refined.at_bound.items():
            sol.bound[n] = (
                f"on its {side} bound {get_value(sol.fitted, n):.4g} after the decorrelated "
                "refinement (fit.input_noise); exported at the bound"
            )
        sol.live = [i for i in sol.live if sol.inner[i] not in sol.bound]
        sol.r1, sol.J1 = model.residual_and_jacobian(sol.fitted, sol.inner)
        _standard_errors(sol)
    return refined


def basin_scans(model, fitted, live_names, sigma_m, scanned, restart) -> dict:
    """The loss scanned along each fitted constant of ``BASIN_PARAMETERS`` at the solution
    (reusing a scan made at the same constants), with what it found logged."""
    scans = {}
    for n in BASIN_PARAMETERS:
        if n not in live_names:
            continue
        at, done = scanned.get(n, (None, None))
        scans[n] = done if at is fitted else scan(model, fitted, n, sigma_m)  # moved since: again
        if restart and restart["name"] == n:
            scans[n]["restart"] = restart
        told = {o["value"] for o in scans[n].get("unconfirmed", [])}  # reported as such
        for key, what in (
            ("indistinguishable", "other basins the reference's noise cannot tell from the fit's"),
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
    return scans


def basin_restart(
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
                f"({get_value(fitted, n):.4g}) by {-best['delta_loss']:.4g} (+- "
                f"{best['noise_sd']:.2g} from the "
                "reference's noise"
            )
            if td is not None and td >= 0.0:
                s["unconfirmed"].append({**best, "texture_delta": td})
                _log(
                    f"{head}), but higher by {td:.4g} in the decorrelated loss of the "
                    "texture's independent "
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
