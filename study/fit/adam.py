"""Adam, Mitsuba's tutorial loop (the baseline the least-squares solvers are measured against)."""

from __future__ import annotations

import math

import numpy as np

from shaders_port.pipeline.texture import backend_types

from .bridge import DrJitResidual
from .problem import FTOL_WINDOW, FitProblem
from .steps import Trace


def adam(
    problem: FitProblem,
    res: DrJitResidual,
    base: dict,
    names,
    u0,
    max_steps,
    lr,
    rtol,
    atol,
    patience,
    trace: Trace | None = None,
    ftol: float | None = None,
    window: int = FTOL_WINDOW,
):
    """The tutorial loop: Dr.Jit Adam on ``u``; gradient from ``dr.backward`` of ``loss_drjit``
    or, without it, ``J^T r`` (forward-mode Jacobian). Returns (u, iters, ok, msg, n_grad,
    losses)."""
    import drjit as dr
    import drjit.opt  # noqa: F401  (registers dr.opt)

    ps = [problem.params[n] for n in names]
    Float = problem.drjit_float
    if Float is None:  # the run's backend (``study._backend.init_backend``)
        Float = backend_types().Float
    opt = dr.opt.Adam(lr=lr)
    for p, ui in zip(ps, u0):
        opt[p.name] = Float(float(ui))
    losses, n_grad, ok, best_u = [], 0, False, np.asarray(u0, np.float64)
    msg = f"stopped at the iteration cap max_steps={max_steps}"
    it = 0
    for it in range(1, max_steps + 1):
        if problem.loss_drjit is not None:
            vals = dict(base)
            vals.update({p.name: p.from_u(opt[p.name], xp=dr) for p in ps})
            try:
                loss = problem.loss_drjit(vals)
            except FloatingPointError as e:
                return best_u, it, False, f"stopped: {e}", n_grad, losses
            dr.backward(loss)
            value = float(dr.detach(loss)[0] if dr.width(loss) else loss)
            n_grad += 1
            grads = np.array([float(dr.grad(opt[p.name])[0]) for p in ps])
        else:
            u = np.array([float(opt[p.name][0]) for p in ps])
            try:
                r, J = res.value_and_jac(u)
            except FloatingPointError as e:
                return best_u, it, False, f"stopped: {e}", n_grad, losses
            value, g = 0.5 * float(r @ r), J.T @ r
            for p, gi in zip(ps, g):
                dr.set_grad(opt[p.name], Float(float(gi)))
            grads = g
        if not (math.isfinite(value) and np.all(np.isfinite(grads))):
            return (
                best_u,
                it,
                False,
                f"stopped at iteration {it}: non-finite loss or gradient",
                n_grad,
                losses,
            )
        losses.append(value)
        if value <= min(losses):
            best_u = np.array([float(opt[p.name][0]) for p in ps])
        if trace is not None:
            trace.note(value)
        opt.step()
        if trace is not None and trace.stalled(ftol, window * 10):
            ok, msg = (
                True,
                (
                    f"converged: the best loss fell by less than {ftol:g} (relative) over "
                    f"the last {window * 10} iterations (iteration {it})"
                ),
            )
            break
        if (
            patience is not None
            and len(losses) > patience
            and min(losses[:-patience]) - min(losses[-patience:]) <= rtol * value + atol
        ):
            ok, msg = (
                True,
                (
                    f"best loss improved by less than rtol*loss+atol over the last "
                    f"{patience} iterations (iteration {it})"
                ),
            )
            break
    return best_u, it, ok, msg, n_grad, losses
