"""The interface every solver implements and the one loop that drives them.

A solver is written as optimistix writes its own (``AbstractMinimiser``): :meth:`Solver.init`
builds a typed state at the start point, :meth:`Solver.step` returns the state after one
iteration, :meth:`Solver.terminate` says whether the solver's own criterion is met (a
:class:`Stop`) and :meth:`Solver.postprocess` gives the point to return (a :class:`Solution`).
A solver keeps nothing of a run outside its state; it reads its settings
(:class:`~study.fit.problem.SolverSettings`) and the :class:`Objective` it minimises.

:func:`run_solver` owns what every solver shares: the step cap, the :class:`Trace` of the lowest
loss after each step, the loss-stall rule (:meth:`Trace.stalled`: over the last
``ftol_window * stall_window_scale`` steps that moved the point, or twice as many of any kind),
the guard against non-finite parameters and the residual that aborts a solve. A non-finite
model value (a ``FloatingPointError``, raised directly or wrapped by JAX from inside a jitted
step) ends the run not converged with the best point evaluated; any other error is a bug and
propagates.
"""

from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import ClassVar, Generic, TypeVar

import numpy as np

from .jax_residual import DrJitResidual
from .params import Param
from .problem import FitProblem, SolverSettings

State = TypeVar("State")

#: how many loss-stall windows of steps, rejected trials included, end a run (Trace.stalled)
SEARCH_WINDOWS = 2


@dataclass(frozen=True)
class Objective:
    """What a solver minimises: ``0.5*||r(u)||^2`` of ``residual`` (the JAX/NumPy residual of the
    unconstrained ``u`` of the ``names`` being fitted), the others held at ``base``."""

    residual: DrJitResidual
    problem: FitProblem
    base: dict
    names: list

    @property
    def params(self) -> list[Param]:
        return [self.problem.params[n] for n in self.names]

    def loss(self, u) -> float:
        """``0.5*||r(u)||^2`` through the NumPy side of the residual (counted in its stats)."""
        r = self.residual.value(u)
        return 0.5 * float(r @ r)

    def best_evaluated(self, u0) -> np.ndarray:
        """The lowest-loss point the residual evaluated, else ``u0``."""
        best = self.residual.stats.best_x
        return np.asarray(best if best is not None else u0, np.float64)


@dataclass(frozen=True)
class Stop:
    """A solver's own criterion met: ``converged`` or not, and why."""

    converged: bool
    reason: str


@dataclass(frozen=True)
class Solution:
    """What a solver returns at the end: the point ``u``, the gradient evaluations it made outside
    the residual and, for a solver whose losses do not all go through the residual, the loss
    of each iterate (None: every loss is in the residual's ``CallStats``)."""

    u: np.ndarray
    grad_calls: int = 0
    iterate_losses: list | None = None


@dataclass(frozen=True)
class SolverRun:
    """One run of a solver from one start: the :class:`Solution`'s fields, the steps taken,
    whether it converged and the message saying how it stopped."""

    u: np.ndarray
    steps: int
    converged: bool
    message: str
    grad_calls: int = 0
    iterate_losses: list | None = None


class Solver(ABC, Generic[State]):
    """A solver (see the module docstring). Class attributes: ``name`` (its key in
    ``study.fit.solvers.SOLVER_CLASSES``), ``derivative_free`` (it needs no derivative, so it may
    fit ``derivative_free`` parameters), ``stall_window_scale`` (the loss-stall rule looks over
    this many times ``ftol_window`` steps; None: the rule does not apply) and
    ``keeps_best_evaluated`` (the fit returns the lowest-loss point the residual evaluated when
    that is lower than the solver's own)."""

    name: ClassVar[str]
    derivative_free: ClassVar[bool] = False
    stall_window_scale: ClassVar[int | None] = 1
    keeps_best_evaluated: ClassVar[bool] = True

    def __init__(self, settings: SolverSettings):
        self.settings = settings

    @abstractmethod
    def init(self, objective: Objective, u0: np.ndarray) -> State:
        """The state at the start point ``u0``."""

    @abstractmethod
    def step(self, objective: Objective, state: State) -> State:
        """The state after one iteration."""

    @abstractmethod
    def terminate(self, objective: Objective, state: State) -> Stop | None:
        """The solver's own stopping criterion at ``state`` (None: go on)."""

    @abstractmethod
    def postprocess(self, objective: Objective, state: State) -> Solution:
        """The point to return from ``state``, with the solver's own counts."""

    def trace_loss(self, objective: Objective, state: State) -> float:
        """The loss the trace records after a step: the lowest the residual evaluated."""
        return objective.residual.stats.best_loss


class Trace:
    """Lowest loss seen and seconds since the start, after each solver step, and the lowest
    loss after each step that moved the solver's point (``moved_losses``)."""

    def __init__(self, t0: float, loss0: float):
        self.t0, self.best = t0, loss0
        self.losses, self.seconds, self.moved_losses = [], [], [loss0]

    def note(self, loss: float, moved: bool = True) -> None:
        if math.isfinite(loss):
            self.best = min(self.best, float(loss))
        self.losses.append(self.best)
        self.seconds.append(time.perf_counter() - self.t0)
        if moved:
            self.moved_losses.append(self.best)

    def stalled(self, ftol: float | None, window: int) -> bool:
        """The lowest loss fell by less than ``ftol * loss`` over the last ``window`` steps that
        moved the point, or over the last ``SEARCH_WINDOWS * window`` steps of any kind. A step
        that did not move (a trust-region solver rejecting its trial and shrinking its radius)
        is a search, given that longer window before it counts as a stall."""
        if ftol is None:
            return False

        def fell_less(v, n):
            return len(v) > n and v[-n - 1] - v[-1] <= ftol * v[-1]

        return fell_less(self.moved_losses, window) or fell_less(
            self.losses, SEARCH_WINDOWS * window
        )


@dataclass
class _Progress:
    """The loop's own bookkeeping: the solver's latest state (None before ``init`` returned),
    the steps taken and how the run stopped."""

    state: object = None
    steps: int = 0
    stop: Stop | None = field(default=None)


def run_solver(
    solver: Solver,
    objective: Objective,
    u0: np.ndarray,
    max_steps: int,
    trace: Trace,
    ftol: float | None,
) -> SolverRun:
    """Run ``solver`` from ``u0`` for at most ``max_steps`` steps. After each step: the trace
    notes the solver's loss, then the run stops at the solver's own criterion, at the loss-stall
    rule (``ftol``, already raised by ``ftol_se``; None: off) or at the cap, in that order."""
    run = _Progress()
    window = solver.settings.ftol_window * (solver.stall_window_scale or 0)
    try:
        run.state = solver.init(objective, u0)
        while (stop := solver.terminate(objective, run.state)) is None:
            if run.steps and window and trace.stalled(ftol, window):
                stop = Stop(
                    True,
                    f"converged: the loss fell by less than {ftol:g} (relative) over the last "
                    f"{window} steps,",
                )
                break
            if run.steps >= max_steps:
                return _finished(
                    solver,
                    objective,
                    run,
                    u0,
                    Stop(False, f"maximum number of steps reached (max_steps={max_steps})"),
                )
            before = solver.postprocess(objective, run.state).u
            run.state = solver.step(objective, run.state)
            run.steps += 1
            moved = not np.array_equal(before, solver.postprocess(objective, run.state).u)
            trace.note(solver.trace_loss(objective, run.state), moved)
    except Exception as exc:  # a non-finite model value aborts the run; anything else propagates
        return _aborted(solver, objective, run, u0, _floating_point_cause(exc, objective.residual))
    return _finished(
        solver, objective, run, u0, Stop(stop.converged, f"{stop.reason} after {run.steps} steps")
    )


def _finished(solver: Solver, objective: Objective, run: _Progress, u0, stop: Stop) -> SolverRun:
    """The run's result: the solver's point, or where that is not finite the best point
    evaluated, not converged."""
    sol = solver.postprocess(objective, run.state)
    u, converged, message = np.asarray(sol.u, np.float64), stop.converged, stop.reason
    if not np.all(np.isfinite(u)):
        u, converged = objective.best_evaluated(u0), False
        message = "solver returned non-finite parameters; returning the best point evaluated"
    return SolverRun(u, run.steps, converged, message, sol.grad_calls, sol.iterate_losses)


def _aborted(solver: Solver, objective: Objective, run: _Progress, u0, cause) -> SolverRun:
    """A run the residual aborted: the best point evaluated (the solver's own best, for a
    solver whose losses do not go through the residual), not converged, naming the cause."""
    sol = solver.postprocess(objective, run.state) if run.state is not None else Solution(u0)
    u = objective.best_evaluated(u0) if solver.keeps_best_evaluated else sol.u
    text = str(cause).strip()
    first = text.splitlines()[0] if text else repr(cause)
    message = (
        f"solver aborted ({type(cause).__name__}): {first}; returning the best point evaluated"
    )
    return SolverRun(
        np.asarray(u, np.float64), run.steps, False, message, sol.grad_calls, sol.iterate_losses
    )


def _floating_point_cause(exc: Exception, residual: DrJitResidual) -> FloatingPointError:
    """The non-finite value behind ``exc``: ``exc`` itself, or the residual's error that JAX
    wrapped when it re-raised it from a jitted step. Any other error is re-raised."""
    if isinstance(exc, FloatingPointError):
        return exc
    cause = residual.last_error
    if isinstance(cause, FloatingPointError):
        return cause
    if cause is not None and cause is not exc:
        raise cause from exc
    raise exc
