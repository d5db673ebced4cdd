"""Nelder-Mead (SciPy), the derivative-free solver."""

from __future__ import annotations

import numpy as np

from .bridge import DrJitResidual
from .steps import Trace


def nelder_mead(res: DrJitResidual, u0, max_steps, rtol, atol, nm_step, trace: Trace | None = None):
    """Nelder-Mead on ``0.5*||r(u)||^2`` (NumPy; values only). Converged when every vertex is
    within ``atol + rtol*|u_best|`` of the best (max norm) and every value within
    ``atol + rtol*|f_best|`` of the best one (optimistix's criterion). Returns (u, steps, ok,
    msg)."""
    k = len(u0)
    a_r, a_e, a_c, a_s = 1.0, 2.0, 0.5, 0.5

    def f(u):
        r = res.value(u)
        return 0.5 * float(r @ r)

    try:
        X = np.vstack([u0, u0[None, :] + nm_step * np.eye(k)])
        F = np.array([f(x) for x in X])
        for step in range(1, max_steps + 1):
            order = np.argsort(F)
            X, F = X[order], F[order]
            if trace is not None and step > 1:
                trace.note(float(F[0]))
            if np.max(np.abs(X - X[0])) <= atol + rtol * np.max(np.abs(X[0])) and np.max(
                np.abs(F - F[0])
            ) <= atol + rtol * abs(F[0]):
                return X[0], step - 1, True, f"converged after {step - 1} steps"
            c = X[:-1].mean(axis=0)
            xr = c + a_r * (c - X[-1])
            fr = f(xr)
            if fr < F[0]:
                xe = c + a_e * (xr - c)
                fe = f(xe)
                X[-1], F[-1] = (xe, fe) if fe < fr else (xr, fr)
            elif fr < F[-2]:
                X[-1], F[-1] = xr, fr
            else:
                xc = c + a_c * (xr - c) if fr < F[-1] else c - a_c * (c - X[-1])
                fc = f(xc)
                if fc < min(fr, F[-1]):
                    X[-1], F[-1] = xc, fc
                else:
                    X[1:] = X[0] + a_s * (X[1:] - X[0])
                    F[1:] = [f(x) for x in X[1:]]
        i = int(np.argmin(F))
        return X[i], max_steps, False, f"stopped at max_steps={max_steps} before converging"
    except FloatingPointError as e:
        best = res.stats.best_x if res.stats.best_x is not None else np.asarray(u0)
        return (
            np.asarray(best),
            0,
            False,
            f"solver aborted ({type(e).__name__}): {e}; returning the best point evaluated",
        )
