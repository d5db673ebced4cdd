"""Calibrating a user's own GLSL shader (``shaders_port.user_shader``) against a reference.

:func:`calibrate` fits the declared constants of a :class:`~shaders_port.user_shader.UserShader`
to a reference image by damped Gauss-Newton (Levenberg-Marquardt) steps on the residual
shader - reference over the water pixels, with the forward-mode Jacobian of the shader executed
through SPIR-V, each scalar kept in its declared range. It returns the fitted values, which
:meth:`UserShader.written` writes back into the user's file.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._metrics import erode

__all__ = ["UserFit", "calibrate"]


@dataclass
class UserFit:
    """The result: ``values`` (GLSL name -> float | tuple, every declared constant),
    ``scalars`` (the fitted scalar names -> value), ``rmse_start`` / ``rmse`` (linear RGB over
    the scored water pixels), ``iterations`` and ``reason`` (why it stopped)."""

    values: dict
    scalars: dict
    mask: np.ndarray  # (H, W) bool: the scored water pixels
    pixels: int
    rmse_start: float
    rmse: float
    iterations: int
    reason: str


def calibrate(
    shader,
    inputs,
    reference: np.ndarray,
    names: list[str] | None = None,
    start: dict | None = None,
    max_iterations: int = 30,
    tolerance: float = 1e-10,
    reference_mask: np.ndarray | None = None,
) -> UserFit:
    """Fit the scalar ``names`` (default: all of the declaration) of ``shader`` so that its
    render of ``inputs`` matches ``reference`` ((H, W, 3) float32 linear RGB at the inputs'
    resolution) on the water pixels (the shader's coverage, and ``reference_mask`` (H, W) bool
    when given, eroded by one pixel)."""
    names = list(names or shader.scalar_names())
    reference = np.asarray(reference, np.float32)
    if reference.shape != (inputs.height, inputs.width, 3):
        raise ValueError(
            f"reference is {reference.shape}, the inputs are {inputs.height}x{inputs.width}"
        )
    values = dict(shader.defaults() if start is None else {**shader.defaults(), **start})
    lo = np.array([shader.bounds(n)[0] for n in names])
    hi = np.array([shader.bounds(n)[1] for n in names])

    def scalars(vals):
        out = []
        for n in names:
            base, _, idx = n.partition("[")
            v = vals[base]
            out.append(float(v[int(idx[:-1])] if idx else v))
        return np.array(out)

    def residual(x, jac: bool):
        vals = shader.with_scalars(values, dict(zip(names, map(float, x))))
        if jac:
            out, J = shader.render_with_jacobian(inputs, vals, names)
        else:
            out, J = shader.render(inputs, vals), None
        o = out.numpy()
        return o, J

    x = scalars(values)
    o, J = residual(x, True)
    cover = o["mask"] > 0.5
    mask = erode(cover & reference_mask if reference_mask is not None else cover, 1)
    if not mask.any():
        raise ValueError("no water pixel in view: check the camera and the water quad")
    if not np.isfinite(reference[mask]).all():
        raise ValueError("the reference has non-finite water pixels; render it again")
    r = (o["color"] - reference)[mask].ravel()
    cost0 = cost = float(r @ r)
    lam, reason, it = 1e-3, "iteration limit", 0
    for it in range(1, max_iterations + 1):
        A = J[mask].reshape(-1, len(names))
        g, H = A.T @ r, A.T @ A
        step_ok = False
        for _ in range(12):
            dx = -np.linalg.solve(H + lam * np.diag(np.diag(H) + 1e-12), g)
            xn = np.clip(x + dx, lo, hi)
            on, _ = residual(xn, False)
            rn = (on["color"] - reference)[mask].ravel()
            cn = float(rn @ rn)
            if np.isfinite(cn) and cn < cost:
                step_ok = True
                break
            lam *= 10.0
        if not step_ok:
            reason = "no step lowers the cost"
            break
        decrease = cost - cn
        x, cost, lam = xn, cn, max(lam / 10.0, 1e-9)
        if decrease <= tolerance * max(cost0, 1e-30) or cost <= 1e-20:
            reason = "converged"
            break
        o, J = residual(x, True)
        r = (o["color"] - reference)[mask].ravel()
    n = int(mask.sum()) * 3
    fitted = shader.with_scalars(values, dict(zip(names, map(float, x))))
    return UserFit(
        fitted,
        dict(zip(names, map(float, x))),
        mask,
        int(mask.sum()),
        (cost0 / n) ** 0.5,
        (cost / n) ** 0.5,
        it,
        reason,
    )
