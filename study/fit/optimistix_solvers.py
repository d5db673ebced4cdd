"""The optimistix solvers - Levenberg-Marquardt, Gauss-Newton, dogleg (least squares on ``r``)
and BFGS (a minimiser of ``0.5*||r||^2``) - as :class:`~study.fit.solver_loop.Solver`\\ s: each
step is optimistix's own ``step`` followed by its ``terminate``, jitted together, so that the
study's loop (``study.fit.solver_loop.run_solver``) can stop them by its loss-stall rule; the
iteration is otherwise that of ``optx.least_squares`` / ``optx.minimise``."""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass, replace
from typing import Any, Callable, ClassVar

import numpy as np

from .solver_loop import Objective, Solution, Solver, Stop


@dataclass(frozen=True)
class _Jitted:
    """optimistix's ``init`` and ``step`` + ``terminate`` of one solver on one residual, jitted."""

    init: Callable
    step: Callable


@dataclass(frozen=True)
class OptimistixState:
    """``y``: the current ``u``; ``inner``: optimistix's own state; ``done`` / ``result``: what
    its ``terminate`` said after the last step; ``jitted``: the compiled functions of the run."""

    y: Any
    inner: Any
    jitted: _Jitted
    done: bool = False
    result: Any = None


class OptimistixSolver(Solver[OptimistixState]):
    """A solver of optimistix driven one step at a time from Python."""

    least_squares: ClassVar[bool] = True

    @abstractmethod
    def optx_solver(self):
        """The optimistix solver, with this fit's ``rtol`` / ``atol``."""

    def _jit(self, objective: Objective) -> _Jitted:
        import equinox as eqx
        import jax
        import jax.numpy as jnp

        s, res, tags = self.optx_solver(), objective.residual, frozenset()
        if self.least_squares:

            def fn(y, args):
                return res(y), None

            f_struct = jax.ShapeDtypeStruct((res.m,), jnp.float64)
        else:

            def fn(y, args):
                return 0.5 * jnp.sum(res(y) ** 2), None

            f_struct = jax.ShapeDtypeStruct((), jnp.float64)

        @eqx.filter_jit
        def init(y):
            return s.init(fn, y, None, {}, f_struct, None, tags)

        @eqx.filter_jit
        def step(y, state):
            y1, state1, _ = s.step(fn, y, None, {}, state, tags)
            done, result = s.terminate(fn, y1, None, {}, state1, tags)
            return y1, state1, done, result

        return _Jitted(init, step)

    def init(self, objective: Objective, u0) -> OptimistixState:
        import jax.numpy as jnp

        jitted = self._jit(objective)
        y = jnp.asarray(np.asarray(u0, np.float64), jnp.float64)
        return OptimistixState(y, jitted.init(y), jitted)

    def step(self, objective: Objective, state: OptimistixState) -> OptimistixState:
        y, inner, done, result = state.jitted.step(state.y, state.inner)
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

    def optx_solver(self):
        import optimistix as optx

        return optx.LevenbergMarquardt(rtol=self.settings.rtol, atol=self.settings.atol)


class GaussNewton(OptimistixSolver):
    name = "gauss_newton"

    def optx_solver(self):
        import optimistix as optx

        s = self.settings
        return optx.GaussNewton(rtol=s.rtol, atol=s.atol, linear_solver=_rank_revealing())


class Dogleg(OptimistixSolver):
    name = "dogleg"

    def optx_solver(self):
        import optimistix as optx

        s = self.settings
        return optx.Dogleg(rtol=s.rtol, atol=s.atol, linear_solver=_rank_revealing())


class BFGS(OptimistixSolver):
    """BFGS on ``0.5*||r||^2`` (a minimiser: it sees the loss, not the residual vector)."""

    name = "bfgs"
    least_squares = False

    def optx_solver(self):
        import optimistix as optx

        return optx.BFGS(rtol=self.settings.rtol, atol=self.settings.atol)
