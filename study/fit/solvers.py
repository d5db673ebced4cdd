"""The fitting engine: parameters and their transforms, optimistix solvers, the Adam baseline.

Parameters. Each fitted scalar is a :class:`Param` with a default, bounds ``(lo, hi)`` and a
``scale`` (a typical change, in the parameter's own units). Solvers never see the physical
value ``p``: they work on an unconstrained, dimensionless ``u = (g(p) - g(default)) / s``
with ``s = g'(default) * scale``, so ``u = 0`` at the default and one unit of ``u`` is about
one ``scale`` near the default, whatever the parameter's units. ``g`` (``transform``):

* ``linear`` (no bounds): ``g(p) = p``;
* ``log`` (only ``lo`` finite): ``g(p) = log(p - lo)``;
* ``neglog`` (only ``hi`` finite): ``g(p) = -log(hi - p)``;
* ``logit`` (both finite): ``g(p) = logit((p - lo) / (hi - lo))``;
* ``log_logit`` (both finite, ``lo > 0``): ``logit(log(p / lo) / log(hi / lo))`` - the
  default when ``hi / lo >= 1e3``, where a linear logit would squash the useful range;
* ``clip`` (never chosen by ``auto``): ``p = clip(default + scale*u, lo, hi)``, linear inside
  the box and flat outside it, so a bound is *reached* in finite ``u`` (one solver step can
  land on it) instead of approached forever: for a parameter whose best value may be its bound
  (a colour channel at 0, no highlight). ``dp/du`` is 0 outside the box; :func:`fit` then
  checks the sign of the loss gradient at the bound (the Karush-Kuhn-Tucker condition) and
  restarts the solver from just inside when the loss falls inwards, so a parameter clipped by
  an early, overshooting step is not left stranded there.

so every ``u`` maps inside (``clip``: onto) the bounds. The chain rule is applied on the NumPy side,
before JAX sees the Jacobian: ``dr/du = dr/dp * dp/du`` (a column scaling).

Problem. A :class:`FitProblem` wraps two NumPy-level callables that run Dr.Jit:
``residual(values: dict name -> float) -> (m,)`` and
``residual_and_jacobian(values, names) -> ((m,), (m, len(names)))`` (derivatives only for the
parameters being fitted, since each Jacobian column costs a forward-mode pass), and
optionally ``loss_drjit(values: dict name -> Dr.Jit scalar) -> Dr.Jit scalar 0.5*||r||^2``
for reverse-mode Adam.

Solvers (:data:`SOLVERS`): ``levenberg_marquardt``, ``gauss_newton``, ``dogleg`` through
``optimistix.least_squares``; ``bfgs`` and ``nelder_mead`` through ``optimistix.minimise`` on
``0.5*||r||^2``; ``nelder_mead`` is a plain NumPy Nelder-Mead (Lagarias et al. 1998
coefficients) on the same loss, because optimistix 0.1.0's ``NelderMead`` builds a degenerate
start simplex for a parameter vector of length > 1 (vertex ``i`` is not ``y0 + delta*e_i``;
on ``sum((y - c)^2)`` in 3-D it stops at a wrong point) and its ``y0_simplex`` option rejects
valid simplices; ``nelder_mead_optimistix`` keeps the optimistix solver for comparison;
``adam``: the plain loop of Mitsuba's inverse-rendering tutorials with
``drjit.opt.Adam`` (the optimiser Mitsuba 3 exposes as ``mi.ad.Adam``), over the Dr.Jit
gradient of the loss (reverse mode through ``loss_drjit`` when given, else ``J^T r`` from the
forward-mode Jacobian); no JAX. Parameters marked ``derivative_free`` (step counts, loop caps)
are held at their start by the gradient solvers and fitted only by Nelder-Mead.

Failures (step cap, non-finite residual, solver error) never propagate: :func:`fit` returns
a :class:`FitResult` with ``converged=False``, the reason in ``message`` and, for a crash,
the best point evaluated. A start on a bound is moved inside by 1e-3 of the scale. Bad arguments
(unknown solver or parameter, start outside the bounds) raise ValueError.
"""

from __future__ import annotations

import math
import time

import numpy as np

from .adam import adam
from .bridge import DrJitResidual
from .nelder_mead import nelder_mead
from .optx import optimistix_fit, optimistix_stepped
from .params import TRANSFORMS, Param
from .problem import (
    DERIVATIVE_FREE,
    FTOL,
    FTOL_SE,
    FTOL_WINDOW,
    LEAST_SQUARES,
    MINIMISERS,
    SOLVERS,
    FitProblem,
    FitResult,
)
from .steps import Trace

__all__ = [
    "DERIVATIVE_FREE",
    "FTOL",
    "FTOL_SE",
    "FTOL_WINDOW",
    "LEAST_SQUARES",
    "MINIMISERS",
    "SOLVERS",
    "TRANSFORMS",
    "FitProblem",
    "FitResult",
    "Param",
    "fit",
]


def _free_names(problem: FitProblem, solver: str, free, treat_as_continuous) -> list[str]:
    cont = set(treat_as_continuous or ())
    unknown = (set(free or ()) | cont) - set(problem.names)
    if unknown:
        raise ValueError(f"unknown parameter(s) {sorted(unknown)}; known: {problem.names}")
    gradient = solver not in DERIVATIVE_FREE
    if free is None:
        free = [
            n
            for n in problem.names
            if not (gradient and problem.params[n].derivative_free and n not in cont)
        ]
    free = list(free)
    if gradient:
        bad = [n for n in free if problem.params[n].derivative_free and n not in cont]
        if bad:
            raise ValueError(
                f"parameter(s) {bad} are marked derivative_free; fit them with "
                "solver='nelder_mead' or sweep_1d/sweep_2d, or pass "
                "treat_as_continuous=[...] to measure what a gradient solver does"
            )
    if not free:
        raise ValueError("nothing to fit: no free parameter for this solver")
    return free


def _inside(p: Param, v: float) -> float:
    """A start on a bound of a bounded transform (where ``u`` would be infinite) is moved
    inside by 1e-3 of the parameter's scale (at most a tenth of the interval)."""
    if p.kind in ("linear", "clip"):
        return v
    eps = min(1e-3 * p.typical, 0.1 * (p.hi - p.lo))
    return min(max(v, p.lo + eps), p.hi - eps)


def fit(
    problem: FitProblem,
    x0: dict | None = None,
    *,
    solver: str,
    max_steps: int = 200,
    rtol: float = 1e-8,
    atol: float = 1e-12,
    free: list[str] | None = None,
    treat_as_continuous: list[str] = (),
    lr: float = 0.05,
    patience: int | None = None,
    nm_step: float = 0.5,
    ftol: float | None = None,
    ftol_window: int = FTOL_WINDOW,
    ftol_se: float | None = None,
    kkt_restarts: int = 3,
) -> FitResult:
    """Fit ``problem`` from ``x0`` (dict name -> physical value; missing: defaults).

    ``solver``: one of :data:`SOLVERS`. ``free``: names to fit (default: every parameter the
    solver can fit; the rest stay at ``x0``). ``rtol``/``atol``: optimistix's tolerances (its
    Cauchy test: the step in ``u`` *and* the change of the loss both below ``atol + rtol*|.|``).
    ``ftol`` (None: off): the loss-stall rule, checked after every step of the optimistix
    solvers and Adam: stop (converged) when the lowest loss seen fell by less than
    ``ftol * loss`` over the last ``ftol_window`` steps - the fit has stopped improving, whatever
    the parameters still do (a parameter crawling towards an unreachable bound would otherwise
    run the solver to its cap). ``ftol_se`` (None: off) raises the tolerance to
    ``ftol_se / (m - k)`` when that is larger (an improvement worth less than
    ``sqrt(ftol_se)`` standard errors of one parameter, see :data:`FTOL_SE`). The calibration
    uses ``ftol = FTOL = 1e-6``, ``ftol_se = FTOL_SE = 1`` over ``FTOL_WINDOW = 3`` steps. For Adam
    (the tutorial loop runs to the cap), with ``patience`` set, the run also stops (converged) when
    the best loss improved by less than ``rtol*loss + atol`` over the last ``patience`` iterations;
    Adam returns the lowest-loss iterate. ``lr``: Adam's learning rate in ``u`` units (one unit is
    about one ``scale``). ``max_steps``: step cap (Adam: iterations; with restarts, over all of
    them). ``nm_step``: edge of Nelder-Mead's start simplex in ``u`` units (vertices ``u0`` and
    ``u0 + nm_step*e_i``; optimistix's own default is 2.5e-4 at ``u = 0``, which stalled far
    from the minimum). ``kkt_restarts``: how many times a ``clip`` parameter the solver left on
    a bound may be moved back inside when the loss gradient there points inwards.

    ``FitResult.extra``: ``step_losses`` / ``step_seconds`` (lowest loss seen and seconds since
    the start, after each step), ``at_bound`` (name -> ``'lower'``/``'upper'`` for ``clip``
    parameters on a bound at the end), ``restarts`` (how many KKT restarts ran).
    """
    _check_settings(solver, max_steps, ftol, ftol_window)
    base = problem.start_values(x0)
    names = _free_names(problem, solver, free, treat_as_continuous)
    ps = [problem.params[n] for n in names]
    u0 = np.array([float(p.to_u(_inside(p, base[p.name]))) for p in ps])
    t0 = time.perf_counter()
    res = problem.bridge(base, names)
    n_grad = 0
    try:
        loss0 = 0.5 * float(np.sum(res.value(u0) ** 2))
    except FloatingPointError as e:
        msg = f"start point rejected: {e}"
        return _result(problem, solver, names, base, u0, math.nan, [], 0, res, 0, t0, False, msg)
    trace = Trace(t0, loss0)
    if ftol is not None and ftol_se:
        ftol = max(ftol, ftol_se / max(res.m - len(names), 1))
    u, iters, restarts, adam_losses = u0, 0, 0, []
    settings = dict(rtol=rtol, atol=atol, lr=lr, patience=patience, nm_step=nm_step)
    settings.update(ftol=ftol, ftol_window=ftol_window)
    while True:
        u, it, ok, msg, ng, ls = _run_solver(
            solver, problem, res, base, names, u, max_steps - iters, trace, settings
        )
        n_grad, adam_losses, iters = n_grad + ng, adam_losses + ls, iters + it
        if not ok or restarts >= kkt_restarts or iters >= max_steps:
            break
        inward = _kkt_violations(problem, base, ps, u, res, ftol)
        if not inward:
            break
        restarts += 1
        u = _moved_inside(ps, u, inward)
        msg += f"; restarted from inside the bound for {[ps[j].name for j in inward]}"
    if restarts:
        msg += f" ({iters} steps in all)"
    try:
        loss = 0.5 * float(np.sum(res.value(u) ** 2))
    except FloatingPointError as e:
        loss, ok, msg = math.nan, False, f"{msg}; final point non-finite: {e}"
    if res.stats.best_x is not None and res.stats.best_loss < loss and solver != "adam":
        u, loss = np.asarray(res.stats.best_x, np.float64), float(res.stats.best_loss)
    losses = adam_losses if solver == "adam" else list(res.stats.losses)
    out = _result(problem, solver, names, base, u, loss0, losses, iters, res, n_grad, t0, ok, msg)
    out.loss = loss
    out.extra.update(
        {
            "step_losses": trace.losses,
            "step_seconds": trace.seconds,
            "at_bound": {p.name: p.at_bound(ui) for p, ui in zip(ps, out.u) if p.at_bound(ui)},
            "restarts": restarts,
        }
    )
    return out


def _check_settings(solver: str, max_steps: int, ftol, ftol_window: int) -> None:
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; valid solvers: {', '.join(SOLVERS)}")
    if max_steps < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}")
    if ftol is not None and not (ftol >= 0 and ftol_window >= 1):
        raise ValueError(f"need ftol >= 0 and ftol_window >= 1, got {ftol}, {ftol_window}")


def _run_solver(solver, problem, res, base, names, u, left, trace, o: dict):
    """One run of ``solver`` from ``u`` for at most ``left`` steps; ``o``: the settings of
    :func:`fit`. Returns ``(u, steps, ok, message, gradient calls, Adam's losses)``."""
    if solver == "nelder_mead":
        return (*nelder_mead(res, u, left, o["rtol"], o["atol"], o["nm_step"], trace), 0, [])
    if solver == "adam":
        return adam(
            problem,
            res,
            base,
            names,
            u,
            left,
            o["lr"],
            o["rtol"],
            o["atol"],
            o["patience"],
            trace,
            o["ftol"],
            o["ftol_window"],
        )
    if solver == "nelder_mead_optimistix":
        out = optimistix_fit(res, solver, u, left, o["rtol"], o["atol"], o["nm_step"])
        trace.note(res.stats.best_loss)
        return (*out, 0, [])
    out = optimistix_stepped(
        res, solver, u, left, o["rtol"], o["atol"], o["ftol"], o["ftol_window"], trace
    )
    return (*out, 0, [])


def _moved_inside(ps: list, u, inward: dict) -> np.ndarray:
    """``u`` with each parameter ``inward`` names (index -> 'lower'/'upper') moved from its
    bound to 5 % of its scale inside (where the loss falls inwards)."""
    u = np.array(u, np.float64)
    for j, side in inward.items():
        p = ps[j]
        step = 0.05 * p.typical
        inside = (
            min(max(p.lo + step, p.lo), p.hi)
            if side == "lower"
            else max(min(p.hi - step, p.hi), p.lo)
        )
        u[j] = float(p.to_u(inside))
    return u


def _kkt_violations(
    problem: FitProblem, base: dict, ps: list, u, res: DrJitResidual, ftol: float | None = None
) -> dict:
    """Index -> side for the ``clip`` parameters on a bound where the loss decreases inwards
    (``dL/dp < 0`` at a lower bound, ``> 0`` at an upper one) by a worthwhile amount: the
    Gauss-Newton gain of moving that parameter alone inwards, ``g^2 / (2 ||J_j||^2)``, exceeds
    ``ftol * loss`` (the stopping tolerance; 1e-9 without one). The solver left them there by
    overshooting, not because the data want it."""
    at = {j: p.at_bound(ui) for j, (p, ui) in enumerate(zip(ps, u)) if p.at_bound(ui)}
    if not at:
        return {}
    vals = dict(base)
    vals.update({p.name: float(p.from_u(ui)) for p, ui in zip(ps, u)})
    names = [ps[j].name for j in at]
    try:
        r, J = problem.residual_and_jacobian(vals, names)
    except FloatingPointError:
        return {}
    r, J = np.asarray(r, np.float64), np.asarray(J, np.float64)
    g = J.T @ r  # dL/dp, physical units
    loss = 0.5 * float(r @ r)
    out = {}
    tol = (ftol if ftol is not None else 1e-9) * max(loss, 1e-300)
    for q, ((j, side), gj) in enumerate(zip(at.items(), g)):
        inward = gj if side == "lower" else -gj  # dL per unit step inwards
        h = float(J[:, q] @ J[:, q])
        if inward < 0 and h > 0 and gj * gj / (2 * h) > tol:
            out[j] = side
    return out


def _result(
    problem, solver, names, base, u, loss0, losses, iters, res, n_grad, t0, ok, msg, loss=math.nan
) -> FitResult:
    ps = [problem.params[n] for n in names]
    x = np.array([float(p.from_u(ui)) for p, ui in zip(ps, u)])
    consts = dict(base)
    consts.update(dict(zip(names, x.tolist())))
    return FitResult(
        solver,
        names,
        x,
        np.asarray(u, np.float64),
        consts,
        loss0,
        loss,
        losses,
        iters,
        res.stats.n_value_calls,
        res.stats.n_jac_calls,
        n_grad,
        time.perf_counter() - t0,
        bool(ok),
        msg,
    )
