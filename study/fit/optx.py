"""The optimistix solvers (Levenberg-Marquardt, Gauss-Newton, dogleg, BFGS, Nelder-Mead), run
whole or one step at a time under the study's stopping rule."""

from __future__ import annotations

import numpy as np

from .bridge import DrJitResidual
from .problem import LEAST_SQUARES
from .steps import Trace, aborted


def optx_solver(name: str, rtol: float, atol: float):
    """The optimistix solver. Gauss-Newton and Dogleg get a rank-revealing least-squares
    linear solver (``AutoLinearSolver(well_posed=False)``): a Jacobian column can vanish at a
    trial point (e.g. the attenuation clamp saturating), and the default solver, which
    assumes a well-posed operator, then returns NaN and stops the fit."""
    import lineax as lx
    import optimistix as optx

    if name in ("gauss_newton", "dogleg"):
        cls = optx.GaussNewton if name == "gauss_newton" else optx.Dogleg
        return cls(rtol=rtol, atol=atol, linear_solver=lx.AutoLinearSolver(well_posed=False))
    return {
        "levenberg_marquardt": optx.LevenbergMarquardt,
        "bfgs": optx.BFGS,
        "nelder_mead_optimistix": optx.NelderMead,
    }[name](rtol=rtol, atol=atol)


def optimistix_fit(res: DrJitResidual, solver: str, u0, max_steps, rtol, atol, nm_step):
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    s = optx_solver(solver, rtol, atol)

    @jax.jit
    def run(y0):
        if solver in LEAST_SQUARES:
            sol = optx.least_squares(lambda y, _: res(y), s, y0, max_steps=max_steps, throw=False)
        elif solver == "nelder_mead_optimistix":
            nm = optx.NelderMead(rtol=rtol, atol=atol, rdelta=0.0, adelta=nm_step)
            sol = optx.minimise(
                lambda y, _: 0.5 * jnp.sum(res(y) ** 2), nm, y0, max_steps=max_steps, throw=False
            )
        else:
            sol = optx.minimise(
                lambda y, _: 0.5 * jnp.sum(res(y) ** 2), s, y0, max_steps=max_steps, throw=False
            )
        return sol.value, sol.result, sol.stats["num_steps"]

    y0 = np.asarray(u0, np.float64)
    try:
        value, result, steps = run(jnp.asarray(y0, jnp.float64))
    except Exception as e:
        return aborted(res, e, u0, 0)
    steps = int(steps)
    ok = bool(result == optx.RESULTS.successful)
    msg = "converged" if ok else optx.RESULTS[result]
    u = np.asarray(value, np.float64)
    return _finite_or_best(res, u, u0, steps, ok, f"{msg} after {steps} steps")


def optimistix_stepped(
    res: DrJitResidual, solver: str, u0, max_steps, rtol, atol, ftol, window, trace: Trace
):
    """The optimistix solver driven one step at a time from Python (its ``init``/``step``/
    ``terminate`` interface, each step jitted), so that the loss-stall rule (:meth:`Trace.stalled`)
    can stop it; otherwise the same iteration as ``optx.least_squares`` / ``optx.minimise``.
    Returns (u, steps, ok, msg)."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    s = optx_solver(solver, rtol, atol)
    if solver in LEAST_SQUARES:

        def fn(y, args):
            return res(y), None

        f_struct = jax.ShapeDtypeStruct((res.m,), jnp.float64)
    else:

        def fn(y, args):
            return 0.5 * jnp.sum(res(y) ** 2), None

        f_struct = jax.ShapeDtypeStruct((), jnp.float64)
    tags = frozenset()

    @eqx.filter_jit
    def init(y):
        return s.init(fn, y, None, {}, f_struct, None, tags)

    @eqx.filter_jit
    def step(y, state):
        y1, state1, _ = s.step(fn, y, None, {}, state, tags)
        done, result = s.terminate(fn, y1, None, {}, state1, tags)
        return y1, state1, done, result

    y = jnp.asarray(np.asarray(u0, np.float64), jnp.float64)
    steps, ok, msg = 0, False, f"maximum number of steps reached (max_steps={max_steps})"
    try:
        state = init(y)
        while steps < max_steps:
            y, state, done, result = step(y, state)
            steps += 1
            trace.note(res.stats.best_loss)
            if not bool(jnp.all(jnp.isfinite(y))):
                ok, msg = False, "solver returned non-finite parameters"
                break
            if bool(done):
                ok = bool(result == optx.RESULTS.successful)
                msg = (
                    f"converged (optimistix's step and loss tolerances) after {steps} steps"
                    if ok
                    else f"{optx.RESULTS[result]} after {steps} steps"
                )
                break
            if trace.stalled(ftol, window):
                ok, msg = (
                    True,
                    (
                        f"converged: the loss fell by less than {ftol:g} (relative) over "
                        f"the last {window} steps, after {steps} steps"
                    ),
                )
                break
    except Exception as e:
        return aborted(res, e, u0, steps)
    u = np.asarray(y, np.float64)
    return _finite_or_best(res, u, u0, steps, ok, msg)


def _finite_or_best(res: DrJitResidual, u, u0, steps: int, ok: bool, msg: str):
    """``(u, steps, ok, msg)``, or where the solver returned non-finite parameters the best
    point evaluated (else the start), not converged."""
    if np.all(np.isfinite(u)):
        return u, steps, ok, msg
    best = res.stats.best_x if res.stats.best_x is not None else np.asarray(u0)
    return (
        np.asarray(best),
        steps,
        False,
        "solver returned non-finite parameters; returning the best point evaluated",
    )
