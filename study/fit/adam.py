"""Adam, the loop of Mitsuba's inverse-rendering tutorials (the baseline the least-squares solvers
are measured against), as a :class:`~study.fit.solver_loop.Solver`.

``drjit.opt.Adam`` (the optimiser Mitsuba 3 exposes as ``mi.ad.Adam``) steps ``u`` with the
learning rate ``SolverSettings.lr`` (``u`` units: one unit is about one ``scale``). The gradient
of the loss comes from ``dr.backward`` through the problem's ``loss_drjit`` when it has one
(reverse mode; the residual is not called), else as ``J^T r`` from the forward-mode Jacobian.
No JAX. The run returns the lowest-loss iterate. Its loss-stall rule looks over ten times as
many steps as the other solvers' (Adam's steps are small and noisy); with
``SolverSettings.patience`` it also stops (converged) when its best loss improved by less than
``rtol*loss + atol`` over the last ``patience`` iterations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shaders_port.pipeline.texture import backend_types

from .solver_loop import Objective, Solution, Solver, Stop


@dataclass(frozen=True)
class AdamState:
    """``opt``: the Dr.Jit optimiser holding ``u`` and its moments (stepped in place);
    ``losses``: the loss of each iterate; ``best_u``: the lowest-loss iterate; ``grad_calls``:
    reverse-mode gradients taken; ``finite``: the last loss and gradient were finite."""

    opt: object
    losses: tuple
    best_u: np.ndarray
    grad_calls: int = 0
    finite: bool = True


class Adam(Solver[AdamState]):
    name = "adam"
    stall_window_scale = 10
    keeps_best_evaluated = False

    def init(self, objective: Objective, u0) -> AdamState:
        import drjit as dr
        import drjit.opt  # noqa: F401  (registers dr.opt)

        Float = _float_type(objective)
        opt = dr.opt.Adam(lr=self.settings.lr)
        for p, ui in zip(objective.params, u0):
            opt[p.name] = Float(float(ui))
        return AdamState(opt, (), np.asarray(u0, np.float64))

    def step(self, objective: Objective, state: AdamState) -> AdamState:
        """The loss and its gradient at the current iterate, then one Adam update."""
        opt, ps = state.opt, objective.params
        value, grads, grad_calls = _loss_and_gradient(objective, opt, state.grad_calls)
        if not (math.isfinite(value) and np.all(np.isfinite(grads))):
            return AdamState(opt, state.losses, state.best_u, grad_calls, finite=False)
        losses = (*state.losses, value)
        best_u = state.best_u
        if value <= min(losses):
            best_u = np.array([float(opt[p.name][0]) for p in ps])
        opt.step()
        return AdamState(opt, losses, best_u, grad_calls)

    def trace_loss(self, objective: Objective, state: AdamState) -> float:
        return state.losses[-1] if state.finite else math.nan

    def terminate(self, objective: Objective, state: AdamState) -> Stop | None:
        if not state.finite:
            return Stop(False, "stopped: non-finite loss or gradient")
        patience, losses, s = self.settings.patience, state.losses, self.settings
        if (
            patience is not None
            and len(losses) > patience
            and min(losses[:-patience]) - min(losses[-patience:]) <= s.rtol * losses[-1] + s.atol
        ):
            return Stop(
                True,
                f"converged: the best loss improved by less than rtol*loss+atol over the last "
                f"{patience} iterations,",
            )
        return None

    def postprocess(self, objective: Objective, state: AdamState) -> Solution:
        return Solution(state.best_u, state.grad_calls, list(state.losses))


def _loss_and_gradient(objective: Objective, opt, grad_calls: int):
    """``(loss, dL/du (k,), grad_calls)`` at the iterate ``opt`` holds: reverse mode through
    ``loss_drjit`` (one more gradient call), else ``J^T r`` with the gradient set on ``opt``."""
    import drjit as dr

    problem, ps = objective.problem, objective.params
    if problem.loss_drjit is not None:
        vals = dict(objective.base)
        vals.update({p.name: p.from_u(opt[p.name], xp=dr) for p in ps})
        loss = problem.loss_drjit(vals)
        dr.backward(loss)
        value = float(dr.detach(loss)[0] if dr.width(loss) else loss)
        return value, np.array([float(dr.grad(opt[p.name])[0]) for p in ps]), grad_calls + 1
    u = np.array([float(opt[p.name][0]) for p in ps])
    r, J = objective.residual.value_and_jac(u)
    value, g = 0.5 * float(r @ r), J.T @ r
    Float = _float_type(objective)
    for p, gi in zip(ps, g):
        dr.set_grad(opt[p.name], Float(float(gi)))
    return value, g, grad_calls


def _float_type(objective: Objective):
    """The Dr.Jit float type of the iterate: the problem's, else the run's backend's
    (``study._backend.init_backend``)."""
    Float = objective.problem.drjit_float
    return Float if Float is not None else backend_types().Float
