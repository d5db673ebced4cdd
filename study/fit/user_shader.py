"""Calibrating a user's own GLSL shader (``shaders_port.spirv.user_shader``) against a reference.

:func:`calibrate` fits the declared constants of a
:class:`~shaders_port.spirv.user_shader.UserShader` as the built-in calibration fits the study's
shaders (``study.fit.calibrate``): the residual shader - reference over the water pixels is a
:class:`~study.fit.problem.FitProblem` whose Jacobian is the shader's forward-mode derivative
executed through SPIR-V; the constants the image does not identify at the start (insensitive, or
confounded with others: ``study.fit.identify``) are frozen at their start values; the rest are
fitted by the experiment's solver (``study.fit.solvers.fit``, optimistix) in the transformed
coordinates that keep each in its declared range, with the study's stopping rule; at the solution
each constant is ``fitted`` (with its relative standard error), ``bound`` (the loss still falls
beyond its range) or ``frozen`` (not identified at the start, or a relative standard error above
``study.fit.rounds.REL_SE_MAX`` at the fit: held at its start value and the rest refitted, at most
``SE_ROUNDS`` times). :meth:`UserShader.written` writes the fitted values back into the file.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field

import numpy as np

from .._metrics import erode
from .identify import identify
from .params import Param
from .problem import FTOL, FTOL_SE, FTOL_WINDOW, SOLVERS, FitProblem
from .rounds import FIT_ATOL, FIT_RTOL, REL_SE_MAX, SE_ROUNDS, std_errors
from .solvers import fit as solve

__all__ = ["UserFit", "calibrate", "user_problem"]


@dataclass
class UserFit:
    """The result: ``values`` (GLSL name -> float | tuple, every declared constant),
    ``scalars`` (the fitted scalar names -> value), ``rmse_start`` / ``rmse`` (linear RGB over
    the scored water pixels), ``iterations`` and ``reason`` (why the solver stopped),
    ``parameters`` (scalar name -> {"start", "value", "status": fitted | bound | frozen,
    "reason", "rel_std_error"}), ``identifiability`` (at the start: singular values,
    condition number, each constant's relative sensitivity) and ``residual`` (at the fit)."""

    values: dict
    scalars: dict
    mask: np.ndarray  # (H, W) bool: the scored water pixels
    pixels: int
    rmse_start: float
    rmse: float
    iterations: int
    reason: str
    solver: str = "levenberg_marquardt"
    parameters: dict = field(default_factory=dict)
    identifiability: dict = field(default_factory=dict)
    residual: np.ndarray | None = None  # (M,) float64: fitted - reference on ``mask``, RGB


class _Residual:
    """The residual (M,) float64 of ``shader`` against ``reference`` on ``mask`` and its
    Jacobian (M, k), as functions of {scalar name: value} over the start ``values``."""

    def __init__(self, shader, inputs, reference, mask, values):
        self.shader, self.inputs, self.reference = shader, inputs, reference
        self.mask, self.values = mask, values

    def _check(self, out: dict) -> np.ndarray:
        r = (out["color"][self.mask] - self.reference[self.mask]).astype(np.float64).ravel()
        bad = int((~np.isfinite(out["color"][self.mask])).any(-1).sum())
        if bad:
            raise FloatingPointError(
                f"{self.shader.label} produced {bad} non-finite water pixels; check the "
                "shader's divisions, logarithms and powers over its constants' ranges"
            )
        return r

    def residual(self, scalars: dict) -> np.ndarray:
        vals = self.shader.with_scalars(self.values, scalars)
        return self._check(self.shader.render(self.inputs, vals).numpy())

    def residual_and_jacobian(self, scalars: dict, names: list[str]):
        vals = self.shader.with_scalars(self.values, scalars)
        out, J = self.shader.render_with_jacobian(self.inputs, vals, names)
        return self.masked(out.numpy(), J, names)

    def masked(self, out: dict, J: np.ndarray, names: list[str]):
        """(residual (M,), Jacobian (M, k)) on the mask from a render ``out`` and its image
        Jacobian ``J`` (H, W, 3, k)."""
        r = self._check(out)
        J = J[self.mask].reshape(-1, len(names)).astype(np.float64)
        if not np.isfinite(J).all():
            raise FloatingPointError(f"{self.shader.label}: non-finite derivatives in {names}")
        return r, J


def user_problem(shader, residual: _Residual, names: list[str], start: dict) -> FitProblem:
    """The fit problem over the scalar ``names`` of ``shader``, each kept in its declared range
    (a logistic transform; ``clip`` when the start value lies on a bound)."""
    params = []
    for n in names:
        lo, hi = shader.bounds(n)
        v = start[n]
        # a range from 0 (a best value of 0 must be reachable), or a start on a bound: clipped
        clip = lo == 0.0 or not lo < v < hi
        scale = 0.5 * abs(v) if v else (hi - lo) / 10
        params.append(Param(n, v, lo, hi, scale=scale, transform="clip" if clip else "auto"))
    return FitProblem(
        params, residual.residual, residual.residual_and_jacobian, name=f"{shader.label} fit"
    )


def _scalars(shader, values: dict, names: list[str]) -> dict:
    out = {}
    for n in names:
        base, _, idx = n.partition("[")
        v = values[base]
        out[n] = float(v[int(idx[:-1])] if idx else v)
    return out


def _water(cover: np.ndarray, reference, reference_mask) -> np.ndarray:
    """The scored pixels: the shader's coverage ``cover`` (H, W) bool (and ``reference_mask``)
    eroded by one pixel."""
    mask = erode(cover & reference_mask if reference_mask is not None else cover, 1)
    if not mask.any():
        raise ValueError("no water pixel in view: check the camera and the water quad")
    if not np.isfinite(reference[mask]).all():
        raise ValueError("the reference has non-finite water pixels; render it again")
    return mask


def _rounds(problem, res: _Residual, x0: dict, free: list, solver: str, max_steps: int):
    """Fit ``free`` from ``x0``; while some fitted constant's relative standard error exceeds
    ``REL_SE_MAX``, hold those at their start values and refit the rest (at most ``SE_ROUNDS``
    times). Returns (values, the last solver result, {name: side} of those on a bound,
    {name: relative standard error}, {name: why held})."""
    held = {}
    for round_ in range(SE_ROUNDS + 1):
        fitting = [n for n in free if n not in held]
        if not fitting:
            return dict(x0), None, {}, {}, held
        result = solve(
            problem, x0, solver=solver, free=fitting, max_steps=max_steps, rtol=FIT_RTOL,
            atol=FIT_ATOL, ftol=FTOL, ftol_window=FTOL_WINDOW, ftol_se=FTOL_SE,
        )  # fmt: skip
        print(file=sys.stderr)
        x = {**x0, **{n: float(result.constants[n]) for n in fitting}}
        at_bound = result.extra.get("at_bound", {})
        inner = [n for n in fitting if n not in at_bound]
        se = {}
        if inner:
            r1, J1 = res.residual_and_jacobian(x, inner)
            se = dict(zip(inner, std_errors(J1, r1, np.array([x[n] for n in inner]))))
        loose = {n: e for n, e in se.items() if e is not None and e > REL_SE_MAX}
        if not loose or round_ == SE_ROUNDS:
            return x, result, at_bound, se, held
        for n, e in loose.items():
            held[n] = (
                f"not identified: relative standard error {100 * e:.3g} % > "
                f"{100 * REL_SE_MAX:g} % at the fit; held at its start value"
            )


def calibrate(
    shader,
    inputs,
    reference: np.ndarray,
    names: list[str] | None = None,
    start: dict | None = None,
    max_iterations: int = 30,
    reference_mask: np.ndarray | None = None,
    solver: str = "levenberg_marquardt",
) -> UserFit:
    """Fit the scalar ``names`` (default: all of the declaration) of ``shader`` so that its
    render of ``inputs`` matches ``reference`` ((H, W, 3) float32 linear RGB at the inputs'
    resolution) on the water pixels (the shader's coverage, and ``reference_mask`` (H, W) bool
    when given, eroded by one pixel), with ``solver`` (a gradient solver of
    ``study.fit.problem.SOLVERS``) for at most ``max_iterations`` steps (see the module doc)."""
    if solver not in SOLVERS or solver == "adam":
        raise ValueError(
            f"fit.solver = {solver!r} cannot fit a user shader; choose one of "
            f"{', '.join(s for s in SOLVERS if s != 'adam')}"
        )
    names = list(names or shader.scalar_names())
    reference = np.asarray(reference, np.float32)
    if reference.shape != (inputs.height, inputs.width, 3):
        raise ValueError(
            f"reference is {reference.shape}, the inputs are {inputs.height}x{inputs.width}"
        )
    values = dict(shader.defaults() if start is None else {**shader.defaults(), **start})
    out0, J_img = shader.render_with_jacobian(inputs, values, names)
    out0 = out0.numpy()
    mask = _water(out0["mask"] > 0.5, reference, reference_mask)
    res = _Residual(shader, inputs, reference, mask, values)
    x0 = _scalars(shader, values, names)
    problem = user_problem(shader, res, names, x0)
    r0, J0 = res.masked(out0, J_img, names)
    scales = [problem.params[n].typical for n in names]
    id0 = identify(J0, names, scales=scales)
    free = [n for n in names if not id0.freeze[n]]
    if not free:
        raise ValueError(
            f"{shader.label}: the image identifies none of {names} at the start values "
            f"({'; '.join(f'{n}: {id0.reasons[n]}' for n in names)}); widen what the reference "
            "shows or declare other constants"
        )
    x, result, at_bound, se, held = _rounds(problem, res, x0, free, solver, max_iterations)
    r1 = res.residual(x)
    parameters = {}
    for n in names:
        if id0.freeze[n] or n in held:
            status, why = "frozen", held.get(n) or id0.reasons[n]
        elif n in at_bound:
            status = "bound"
            why = f"on its {at_bound[n]} bound: the loss still falls beyond the declared range"
        else:
            status, why = "fitted", id0.reasons[n]
        parameters[n] = {"start": x0[n], "value": x[n], "status": status, "reason": why,
                         "rel_std_error": se.get(n)}  # fmt: skip
    m = r0.size
    return UserFit(
        shader.with_scalars(values, x),
        x,
        mask,
        int(mask.sum()),
        float(np.sqrt(r0 @ r0 / m)),
        float(np.sqrt(r1 @ r1 / m)),
        int(result.iterations) if result else 0,
        result.message if result else "every constant held at its start value",
        solver,
        parameters,
        {
            "names": names,
            "singular_values": id0.singular_values.tolist(),
            "condition": id0.condition if np.isfinite(id0.condition) else None,
            "sensitivity": [id0.sensitivity[n] for n in names],
        },
        r1,
    )
