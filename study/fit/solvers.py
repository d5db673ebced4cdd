"""The fitting engine: parameters and their transforms, the solvers, and :func:`fit`.

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

Solvers (:data:`SOLVER_CLASSES`, keyed by the names in :data:`SOLVERS`), each a
:class:`~study.fit.solver_loop.Solver` run by the one loop of ``study.fit.solver_loop``:
``levenberg_marquardt``, ``gauss_newton``, ``dogleg`` (least squares on ``r``) and ``bfgs``
(on ``0.5*||r||^2``) from optimistix (``study.fit.optimistix_solvers``); ``nelder_mead``, a NumPy
Nelder-Mead on the same loss (``study.fit.nelder_mead``); ``adam``, Mitsuba's tutorial loop with
``drjit.opt.Adam`` (``study.fit.adam``). Parameters marked ``derivative_free`` (step counts,
loop caps) are held at their start by the gradient solvers and fitted only by Nelder-Mead.

Failures (step cap, non-finite residual, solver error) never propagate: :func:`fit` returns
a :class:`FitResult` with ``converged=False``, the reason in ``message`` and, for a crash,
the best point evaluated. A start on a bound is moved inside by 1e-3 of the scale. Bad arguments
(unknown solver, setting or parameter, start outside the bounds) raise ValueError or TypeError.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from .adam import Adam
from .nelder_mead import NelderMead
from .optimistix_solvers import BFGS, Dogleg, GaussNewton, LevenbergMarquardt
from .params import TRANSFORMS, Param
from .problem import (
    CALIBRATION_SETTINGS,
    FTOL,
    FTOL_SE,
    FTOL_WINDOW,
    FitProblem,
    FitResult,
    SolverSettings,
)
from .solver_loop import Objective, Solver, SolverRun, Trace, run_solver

SOLVER_CLASSES: dict[str, type[Solver]] = {
    cls.name: cls for cls in (LevenbergMarquardt, GaussNewton, Dogleg, BFGS, NelderMead, Adam)
}
SOLVERS = tuple(SOLVER_CLASSES)
DERIVATIVE_FREE = tuple(n for n, cls in SOLVER_CLASSES.items() if cls.derivative_free)

__all__ = [
    "CALIBRATION_SETTINGS",
    "DERIVATIVE_FREE",
    "FTOL",
    "FTOL_SE",
    "FTOL_WINDOW",
    "SOLVERS",
    "SOLVER_CLASSES",
    "TRANSFORMS",
    "FitProblem",
    "FitResult",
    "Param",
    "SolverSettings",
    "fit",
    "kkt_violations",
]


def solver_class(name: str) -> type[Solver]:
    """The solver registered as ``name``."""
    cls = SOLVER_CLASSES.get(name)
    if cls is None:
        raise ValueError(f"unknown solver {name!r}; valid solvers: {', '.join(SOLVERS)}")
    return cls


def fit(
    problem: FitProblem,
    x0: dict | None = None,
    *,
    solver: str,
    free: list[str] | None = None,
    treat_as_continuous: list[str] = (),
    settings: SolverSettings | None = None,
    **overrides,
) -> FitResult:
    """Fit ``problem`` from ``x0`` (dict name -> physical value; missing: defaults).

    ``solver``: one of :data:`SOLVERS`. ``free``: names to fit (default: every parameter the
    solver can fit; the rest stay at ``x0``). ``treat_as_continuous``: ``derivative_free``
    parameters a gradient solver may fit anyway (to measure what it does). ``settings``: a
    :class:`SolverSettings` (default: its defaults; the calibration uses
    :data:`CALIBRATION_SETTINGS`); keyword ``overrides`` replace single fields of it
    (``max_steps=50``, ``lr=0.1``...).

    The solver runs from ``x0``; when it converged with a ``clip`` parameter on a bound where the
    loss gradient points inwards (:func:`kkt_violations`), it runs again from just inside, at most
    ``kkt_restarts`` times and ``max_steps`` steps over all runs. The result is the solver's
    point or, when lower, the lowest-loss point the residual evaluated (except Adam, which
    returns its lowest-loss iterate).
    """
    settings = replace(settings or SolverSettings(), **overrides)
    cls = solver_class(solver)
    base = problem.start_values(x0)
    names = _free_names(problem, cls, free, treat_as_continuous)
    ps = [problem.params[n] for n in names]
    u0 = np.array([float(p.to_u(_inside(p, base[p.name]))) for p in ps])
    t0 = time.perf_counter()
    objective = Objective(problem.jax_residual(base, names), problem, base, names)
    try:
        loss0 = 0.5 * float(np.sum(objective.residual.value(u0) ** 2))
    except FloatingPointError as e:
        run = SolverRun(u0, 0, False, f"start point rejected: {e}")
        return _result(solver, objective, t0, run, math.nan, math.nan)
    trace = Trace(t0, loss0)
    ftol = settings.stall_tolerance(objective.residual.count, len(names))
    run, restarts = _run_with_restarts(cls(settings), objective, u0, trace, ftol)
    u, converged, message = run.u, run.converged, run.message
    try:
        loss = 0.5 * float(np.sum(objective.residual.value(u) ** 2))
    except FloatingPointError as e:
        loss, converged, message = math.nan, False, f"{message}; final point non-finite: {e}"
    stats = objective.residual.stats
    if cls.keeps_best_evaluated and stats.best_x is not None and stats.best_loss < loss:
        u, loss = np.asarray(stats.best_x, np.float64), float(stats.best_loss)
    run = replace(run, u=u, converged=converged, message=message)
    return _result(solver, objective, t0, run, loss0, loss, trace, restarts)


def _run_with_restarts(
    solver: Solver, objective: Objective, u0, trace: Trace, ftol: float | None
) -> tuple[SolverRun, int]:
    """The solver from ``u0``, then again from inside a bound while :func:`kkt_violations`
    finds a ``clip`` parameter the loss would move inwards. Returns the last run, with the steps,
    gradient calls and iterate losses of all of them, and the number of restarts."""
    s = solver.settings
    runs, u, restarts = [], u0, 0
    while True:
        runs.append(run_solver(solver, objective, u, s.max_steps - _steps(runs), trace, ftol))
        u = runs[-1].u
        if not runs[-1].converged or restarts >= s.kkt_restarts or _steps(runs) >= s.max_steps:
            break
        inward = kkt_violations(objective, u, ftol)
        if not inward:
            break
        restarts += 1
        u = _moved_inside(objective.params, u, inward)
    last = runs[-1]
    message = last.message + (f" ({_steps(runs)} steps in all)" if restarts else "")
    iterate_losses = (
        None if last.iterate_losses is None else [v for r in runs for v in (r.iterate_losses or [])]
    )
    return replace(
        last,
        steps=_steps(runs),
        message=message,
        grad_calls=sum(r.grad_calls for r in runs),
        iterate_losses=iterate_losses,
    ), restarts


def _steps(runs: list[SolverRun]) -> int:
    return sum(r.steps for r in runs)


def _free_names(problem: FitProblem, cls: type[Solver], free, treat_as_continuous) -> list[str]:
    cont = set(treat_as_continuous or ())
    unknown = (set(free or ()) | cont) - set(problem.names)
    if unknown:
        raise ValueError(f"unknown parameter(s) {sorted(unknown)}; known: {problem.names}")
    gradient = not cls.derivative_free
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


def _moved_inside(ps: list[Param], u, inward: dict) -> np.ndarray:
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


def kkt_violations(objective: Objective, u, ftol: float | None = None) -> dict:
    """Index -> side for the ``clip`` parameters on a bound where the loss decreases inwards
    (``dL/dp < 0`` at a lower bound, ``> 0`` at an upper one) by a worthwhile amount: the
    Gauss-Newton gain of moving that parameter alone inwards, ``g^2 / (2 ||J_j||^2)``, exceeds
    ``ftol * loss`` (the stopping tolerance; 1e-9 without one). The solver left them there by
    overshooting, not because the data want it."""
    ps = objective.params
    at = {j: p.at_bound(ui) for j, (p, ui) in enumerate(zip(ps, u)) if p.at_bound(ui)}
    if not at:
        return {}
    vals = dict(objective.base)
    vals.update({p.name: float(p.from_u(ui)) for p, ui in zip(ps, u)})
    names = [ps[j].name for j in at]
    try:
        r, J = objective.problem.residual_and_jacobian(vals, names)
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
    solver: str,
    objective: Objective,
    t0: float,
    run: SolverRun,
    loss_start: float,
    loss: float,
    trace: Trace | None = None,
    restarts: int = 0,
) -> FitResult:
    """The :class:`FitResult` of ``run`` (its point, steps, counts and message)."""
    ps, stats = objective.params, objective.residual.stats
    x = np.array([float(p.from_u(ui)) for p, ui in zip(ps, run.u)])
    constants = dict(objective.base)
    constants.update(dict(zip(objective.names, x.tolist())))
    u = np.asarray(run.u, np.float64)
    return FitResult(
        solver=solver,
        names=objective.names,
        x=x,
        u=u,
        constants=constants,
        loss_start=loss_start,
        loss=loss,
        losses=list(stats.losses) if run.iterate_losses is None else list(run.iterate_losses),
        iterations=run.steps,
        n_value_calls=stats.n_value_calls,
        n_jac_calls=stats.n_jac_calls,
        n_grad_calls=run.grad_calls,
        seconds=time.perf_counter() - t0,
        seconds_in_model=stats.seconds_in_drjit,
        converged=bool(run.converged),
        message=run.message,
        step_losses=trace.losses if trace is not None else [],
        step_seconds=trace.seconds if trace is not None else [],
        at_bound={p.name: p.at_bound(ui) for p, ui in zip(ps, u) if p.at_bound(ui)},
        restarts=restarts,
    )
