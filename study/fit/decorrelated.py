"""The decorrelated loss: a fit whose target is unbiased by noise in the shader's texture.

Noise in the top-down refraction texture ``T`` is noise in the shader's *inputs*, not in its
target. With ``r(theta; T)`` the masked residual (port - reference, (m,) linear RGB) and a
texture ``T + n`` with zero-mean noise ``n``,
``E ||r(theta; T + n)||^2 = ||r(theta; T)||^2 + sum_i Var r_i(theta)``, and the variance term
depends on the constants (a shorter attenuation distance shows less of the noisy floor), so
least squares on a noisy texture is pulled towards constants that hide the noise: the
attenuation distance shortens as the texture's noise grows.

Every shader here is affine in its textures (bilinear lookups, scaled and mixed by the
constants; no clamp of the output: ``tests/test_decorrelated.py`` checks it on the port), so
with two *independent* estimates ``A`` and ``B`` of the texture, ``E r(theta; A) = r(theta; T)``
and the decorrelated loss

    ``L(theta) = 0.5 * sum_i r_i(theta; A) * r_i(theta; B)``

has the expectation ``0.5 ||r(theta; T)||^2`` of the noise-free loss: texture noise costs
variance, no longer bias. Its gradient is ``g = 0.5 (J_A^T r_B + J_B^T r_A)`` and, as in
Gauss-Newton, its curvature ``H = 0.5 (J_A^T J_B + J_B^T J_A)``. :func:`refine` starts from the
least-squares solution and takes damped Newton steps ``-(H + lambda diag(H))^-1 g`` in the
solver's unconstrained coordinates ``u`` (``study.fit.solvers.Param``, so bounds hold), the
damping raised tenfold until the step lowers ``L`` and lowered after each accepted step
(Levenberg-Marquardt's rule, applied to a loss that is not a sum of squares: optimistix's
least-squares solvers need one, and its BFGS would rebuild from the identity the curvature that
``H`` gives for free). It stops when a step lowers ``L`` by less than one standard error's worth
(``FTOL_SE * L / (m - k)``, as ``study.fit.solvers``) and moves no ``u`` by more than ``XTOL``,
or when no damping lowers ``L`` and the Newton decrement ``g^T H^-1 g`` is below twice that. The
result is accepted only when it converged and ``H`` is positive definite there over the parameters
not on a bound (a minimum of ``L``, not a saddle); otherwise the start is kept and the reason
returned. Each step costs two forward-mode Jacobian passes (one per half), each trial two renders.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from shaders_port import Constants

from ..scene.shader_inputs import half_inputs
from .model import get_value, with_values
from .solvers import FTOL_SE

MAX_STEPS = 30
# damping of the Newton steps (Levenberg-Marquardt style, on the diagonal of H) and stopping:
# a step that lowers L by less than FTOL_SE * L / (m - k) (worth less than one standard error,
# as in study.fit.solvers) and moves no u by more than XTOL
LAMBDA0, LAMBDA_MAX, XTOL = 1e-4, 1e8, 1e-3


@dataclass
class Refined:
    """Outcome of :func:`refine`: the constants (``fitted``; the start when not ``accepted``),
    the decorrelated loss at the start and at the end, damped Newton steps, evaluations of both
    halves (each a residual, or a residual and Jacobian), ``message`` (why a result was refused)
    ``shift`` (name -> [start, end]) and ``at_bound`` (name -> 'lower' / 'upper': a ``clip``
    parameter the refinement left on its bound)."""

    fitted: Constants
    accepted: bool
    loss_start: float
    loss: float
    steps: int
    evaluations: int
    message: str
    shift: dict = field(default_factory=dict)
    at_bound: dict = field(default_factory=dict)

    def summary(self) -> dict:
        """Plain Python types (JSON-ready)."""
        return {
            "method": "decorrelated",
            "accepted": bool(self.accepted),
            "loss_start": float(self.loss_start),
            "loss": float(self.loss),
            "steps": int(self.steps),
            "evaluations": int(self.evaluations),
            "message": self.message,
            "shift": {n: [float(a), float(b)] for n, (a, b) in self.shift.items()},
            "at_bound": dict(self.at_bound),
        }


def decorrelated_loss(r_a: np.ndarray, r_b: np.ndarray) -> float:
    """``0.5 * sum(r_a * r_b)`` of two (m,) residuals."""
    return 0.5 * float(np.dot(np.asarray(r_a, np.float64), np.asarray(r_b, np.float64)))


def loss_grad_hessian(model_a, model_b, constants: Constants, names: list[str]):
    """(L, g (k,), H (k, k)) of the decorrelated loss at ``constants`` over scalar ``names``, in
    the constants' own units (H: the Gauss-Newton form, see the module docstring)."""
    r_a, j_a = model_a.residual_and_jacobian(constants, names)
    r_b, j_b = model_b.residual_and_jacobian(constants, names)
    j_a, j_b = np.asarray(j_a, np.float64), np.asarray(j_b, np.float64)
    g = 0.5 * (j_a.T @ r_b + j_b.T @ r_a)
    h = j_a.T @ j_b
    return decorrelated_loss(r_a, r_b), g, 0.5 * (h + h.T)


def refine(
    model_a, model_b, params: dict, start: Constants, names: list[str], max_steps: int = MAX_STEPS
) -> Refined:
    """Minimise the decorrelated loss of ``model_a`` / ``model_b`` (the same port and reference,
    the texture's two halves) over ``names`` from ``start``, the others held at ``start``.
    ``params``: name -> ``study.fit.solvers.Param`` (bounds and the ``u`` transform)."""
    ps = [params[n] for n in names]
    u = np.array([float(p.to_u(get_value(start, n))) for p, n in zip(ps, names)])
    passes = {"n": 0}

    def at(u) -> Constants:
        return with_values(start, {n: float(p.from_u(float(x))) for n, p, x in zip(names, ps, u)})

    def value(u) -> float:
        passes["n"] += 1
        c = at(u)
        return decorrelated_loss(model_a.residual(c), model_b.residual(c))

    def derivatives(u):
        passes["n"] += 1
        loss, g, h = loss_grad_hessian(model_a, model_b, at(u), names)
        d = np.array([float(p.dp_du(x)) for p, x in zip(ps, u)])  # chain rule to u
        return loss, d * g, d[:, None] * h * d[None, :]

    loss, g, h = derivatives(u)
    l0, lam, steps, ok, why = loss, LAMBDA0, 0, False, ""
    tol = FTOL_SE * abs(loss) / max(model_a.residual(start).size - len(names), 1)
    while steps < max_steps:
        if not np.all(np.isfinite(g)) or not np.all(np.isfinite(h)):
            why = "non-finite gradient"
            break
        steps += 1
        dh = np.maximum(np.diag(h), 1e-12 * max(np.abs(np.diag(h)).max(), 1e-300))
        while lam <= LAMBDA_MAX:
            try:
                step = -np.linalg.solve(h + lam * np.diag(dh), g)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            pred = -(g @ step + 0.5 * step @ h @ step)  # predicted decrease of L
            trial = value(u + step)
            if pred > 0 and np.isfinite(trial) and trial < loss:
                break
            lam *= 10.0
        else:
            ok = bool(abs(g @ np.linalg.lstsq(h, g, rcond=None)[0]) < 2 * tol)  # Newton decrement
            why = (
                "converged (no step lowers the loss further)"
                if ok
                else "no step lowers the decorrelated loss, yet its gradient is not small"
            )
            break
        u, drop = u + step, loss - trial
        loss, g, h = derivatives(u)
        lam = max(lam / 10.0, LAMBDA0)
        if drop < tol and np.max(np.abs(step)) < XTOL:
            ok = True
            break
    else:
        why = f"no convergence in {max_steps} steps"
    fitted = at(u)
    # a clip parameter may land on its bound (a colour channel at 0): its u-derivative is 0
    # there, so it leaves H; the curvature is judged over the others
    at_bound = {n: side for n, p, x in zip(names, ps, u) if (side := p.at_bound(float(x)))}
    inner = [i for i, n in enumerate(names) if n not in at_bound]
    if ok and inner:
        eig = np.linalg.eigvalsh(h[np.ix_(inner, inner)])
        if not (np.all(np.isfinite(eig)) and eig.min() > 0):
            ok, why = (
                False,
                (
                    f"not a minimum of the decorrelated loss (smallest curvature {eig.min():.3g}); "
                    "kept the least-squares solution"
                ),
            )
    if not ok:
        fitted, loss, at_bound = start, l0, {}
        why = why or "no convergence"
    shift = {n: [get_value(start, n), get_value(fitted, n)] for n in names}
    return Refined(fitted, ok, l0, loss, steps, passes["n"], why or "converged", shift, at_bound)


def half_models(exp, inputs, model_of) -> tuple | None:
    """The two models of ``exp`` on the refraction texture's halves
    (``study.scene.shader_inputs.half_inputs``, which raises ExperimentError without them) when
    ``fit.input_noise = "decorrelate"``, else None. ``model_of(inputs)``: the model of the
    shader fitted on those inputs (``study.calibration.shader.Shader.model``)."""
    if exp.fit.input_noise != "decorrelate":
        return None
    return tuple(model_of(h) for h in half_inputs(exp, inputs))


def texture_half_models(exp, inputs, model_of) -> tuple | None:
    """The same two models whenever the inputs carry halves (``reference.texture_method =
    "lighting"``), whatever ``fit.input_noise`` says, else None: the basin scan's check of a
    lower basin (``study.fit.basins.texture_delta``)."""
    if inputs.refraction_halves is None:
        return None
    return tuple(model_of(h) for h in half_inputs(exp, inputs))
