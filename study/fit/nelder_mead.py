"""Nelder-Mead, the derivative-free solver: NumPy, values of ``0.5*||r(u)||^2`` only, with the
coefficients of Lagarias et al. (1998) (reflection 1, expansion 2, contraction 1/2, shrink 1/2).

The start simplex is ``u0`` and ``u0 + nm_step * e_i`` (``SolverSettings.nm_step``, in ``u``
units). It stops (converged) when every vertex is within ``atol + rtol*|u_best|`` of the best
(max norm) and every value within ``atol + rtol*|f_best|`` of the best one (optimistix's
criterion). The loss-stall rule does not apply: the best vertex of a shrinking simplex may not
improve for many steps.

Written here rather than taken from optimistix: optimistix 0.1.0's ``NelderMead`` builds a
degenerate start simplex for more than one parameter (vertex ``i`` is not ``y0 + delta*e_i``) and
its ``y0_simplex`` option rejects valid simplices.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .solver_loop import Objective, Solution, Solver, Stop

REFLECT, EXPAND, CONTRACT, SHRINK = 1.0, 2.0, 0.5, 0.5


@dataclass(frozen=True)
class Simplex:
    """The ``k + 1`` vertices ``X`` (k+1, k) and their losses ``F`` (k+1,), best first."""

    X: np.ndarray
    F: np.ndarray

    @staticmethod
    def sorted(X: np.ndarray, F: np.ndarray) -> Simplex:
        order = np.argsort(F)
        return Simplex(X[order], F[order])


class NelderMead(Solver[Simplex]):
    name = "nelder_mead"
    derivative_free = True
    stall_window_scale = None

    def init(self, objective: Objective, u0) -> Simplex:
        u0 = np.asarray(u0, np.float64)
        X = np.vstack([u0, u0[None, :] + self.settings.nm_step * np.eye(len(u0))])
        return Simplex.sorted(X, np.array([objective.loss(x) for x in X]))

    def step(self, objective: Objective, state: Simplex) -> Simplex:
        f = objective.loss
        X, F = state.X.copy(), state.F.copy()
        c = X[:-1].mean(axis=0)
        xr = c + REFLECT * (c - X[-1])
        fr = f(xr)
        if fr < F[0]:
            xe = c + EXPAND * (xr - c)
            fe = f(xe)
            X[-1], F[-1] = (xe, fe) if fe < fr else (xr, fr)
        elif fr < F[-2]:
            X[-1], F[-1] = xr, fr
        else:
            xc = c + CONTRACT * (xr - c) if fr < F[-1] else c - CONTRACT * (c - X[-1])
            fc = f(xc)
            if fc < min(fr, F[-1]):
                X[-1], F[-1] = xc, fc
            else:
                X[1:] = X[0] + SHRINK * (X[1:] - X[0])
                F[1:] = [f(x) for x in X[1:]]
        return Simplex.sorted(X, F)

    def terminate(self, objective: Objective, state: Simplex) -> Stop | None:
        s = self.settings
        X, F = state.X, state.F
        close = np.max(np.abs(X - X[0])) <= s.atol + s.rtol * np.max(np.abs(X[0]))
        if close and np.max(np.abs(F - F[0])) <= s.atol + s.rtol * abs(F[0]):
            return Stop(True, "converged")
        return None

    def postprocess(self, objective: Objective, state: Simplex) -> Solution:
        return Solution(state.X[int(np.argmin(state.F))])
