"""The optimistix solvers - Levenberg-Marquardt, Gauss-Newton, dogleg (least squares on ``r``)
and BFGS (a minimiser of ``0.5*||r||^2``) - as :class:`~study.fit.solver_loop.Solver`\\ s: each
step is optimistix's own ``step`` followed by its ``terminate``, jitted together, so that the
study's loop (``study.fit.solver_loop.run_solver``) can stop them by its loss-stall rule; the
iteration is otherwise that of ``optx.least_squares`` / ``optx.minimise``. The jitted functions
take the residual's handle as an argument (``jax_residual.shared_residual``): a process traces
and compiles them once per solver, tolerances and problem size, and every later fit of that
size (a sweep's next point, a calibration's next round) reuses them."""

from __future__ import annotations

import functools
from abc import abstractmethod
from dataclasses import dataclass, replace
from typing import Any, Callable, ClassVar

import numpy as np

from .jax_residual import shared_residual
from .solver_loop import Objective, Solution, Solver, Stop


@dataclass(frozen=True)
class _Jitted:
    """optimistix's ``init`` and ``step`` + ``terminate`` of a solver, jitted (:func:`_jitted`)."""

    init: Callable
    step: Callable


@dataclass(frozen=True)
class OptimistixState:
    """``y``: the current ``u``; ``inner``: optimistix's own state; ``done`` / ``result``: what
    its ``terminate`` said after the last step; ``jitted``: the compiled functions of the run;
    ``handle``: the residual's (``DrJitResidual.handle``, an int64 JAX scalar), their argument."""

    y: Any
    inner: Any
    jitted: _Jitted
    done: bool = False
    result: Any = None
    handle: Any = None


@functools.lru_cache(maxsize=64)
def _jitted(solver: type, rtol: float, atol: float, k: int, m: int) -> _Jitted:
    """optimistix's ``init(y, handle)`` and ``step(y, state, handle)`` + ``terminate`` of
    ``solver`` for every residual of ``k`` parameters and ``m`` entries: the residual is the one
    ``handle`` names (``jax_residual.shared_residual``), an argument of the compiled functions,
    so a process compiles them once per solver, tolerances and sizes, not once per fit."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    s, res, tags = solver.make(rtol, atol), shared_residual(k, m), frozenset()
    if solver.least_squares:

        def fn(y, handle):
            return res(handle, y), None

        f_struct = jax.ShapeDtypeStruct((m,), jnp.float64)
    else:

        def fn(y, handle):
            return 0.5 * jnp.sum(res(handle, y) ** 2), None

        f_struct = jax.ShapeDtypeStruct((), jnp.float64)

    @eqx.filter_jit
    def init(y, handle):
        return s.init(fn, y, handle, {}, f_struct, None, tags)

    @eqx.filter_jit
    def step(y, state, handle):
        y1, state1, _ = s.step(fn, y, handle, {}, state, tags)
        done, result = s.terminate(fn, y1, handle, {}, state1, tags)
        return y1, state1, done, result

    return _Jitted(init, step)


class OptimistixSolver(Solver[OptimistixState]):
    """A solver of optimistix driven one step at a time from Python."""

    least_squares: ClassVar[bool] = True

    @classmethod
    @abstractmethod
    def make(cls, rtol: float, atol: float):
        """The optimistix solver with these tolerances."""

    def _jit(self, objective: Objective) -> _Jitted:
        res = objective.residual
        return _jitted(type(self), self.settings.rtol, self.settings.atol, res.k, res.m)

    def init(self, objective: Objective, u0) -> OptimistixState:
        import jax.numpy as jnp

        jitted = self._jit(objective)
        y = jnp.asarray(np.asarray(u0, np.float64), jnp.float64)
        handle = jnp.asarray(objective.residual.handle, jnp.int64)
        return OptimistixState(y, jitted.init(y, handle), jitted, handle=handle)

    def step(self, objective: Objective, state: OptimistixState) -> OptimistixState:
        y, inner, done, result = state.jitted.step(state.y, state.inner, state.handle)
        return replace(state, y=y, inner=inner, done=bool(done), result=result)

    def terminate(self, objective: Objective, state: OptimistixState) -> Stop | None:
        import jax.numpy as jnp
        import optimistix as optx

        if not bool(jnp.all(jnp.isfinite(state.y))):
            return Stop(False, "solver returned non-finite parameters")
        if not state.done:
            return None
        if state.result == optx.RESULTS.successful:
            return Stop(True, "converged (optimistix's step and loss tolerances)")
        return Stop(False, f"{optx.RESULTS[state.result]}")

    def postprocess(self, objective: Objective, state: OptimistixState) -> Solution:
        return Solution(np.asarray(state.y, np.float64))


def _rank_revealing():
    """Gauss-Newton's and dogleg's linear solver: rank-revealing least squares
    (``AutoLinearSolver(well_posed=False)``). A Jacobian column can vanish at a trial point
    (e.g. the attenuation clamp saturating), and the default solver, which assumes a well-posed
    operator, then returns NaN and stops the fit."""
    import lineax as lx

    return lx.AutoLinearSolver(well_posed=False)


class LevenbergMarquardt(OptimistixSolver):
    name = "levenberg_marquardt"

    @classmethod
    def make(cls, rtol: float, atol: float):
        import optimistix as optx

        return optx.LevenbergMarquardt(rtol=rtol, atol=atol)


class GaussNewton(OptimistixSolver):
    name = "gauss_newton"

    @classmethod
    def make(cls, rtol: float, atol: float):
        import optimistix as optx

        return optx.GaussNewton(rtol=rtol, atol=atol, linear_solver=_rank_revealing())


class Dogleg(OptimistixSolver):
    name = "dogleg"

    @classmethod
    def make(cls, rtol: float, atol: float):
        import optimistix as optx

        return optx.Dogleg(rtol=rtol, atol=atol, linear_solver=_rank_revealing())


class BFGS(OptimistixSolver):
    """BFGS on ``0.5*||r||^2`` (a minimiser: it sees the loss, not the residual vector)."""

    name = "bfgs"
    least_squares = False

    @classmethod
    def make(cls, rtol: float, atol: float):
        import optimistix as optx

        return optx.BFGS(rtol=rtol, atol=atol)
