"""What a scene can identify, and what to do with parameters a gradient cannot see.

:func:`identify` decides from a residual Jacobian which parameters to fit and which to freeze.
Columns are scaled by each parameter's ``scale`` (``Js[:, j] = J[:, j] * scale_j``: the change of
the residual for a typical change of the parameter). Two rules, in order:

1. *Insensitive*: relative sensitivity ``||Js[:, j]|| / max_i ||Js[:, i]||`` below ``sens_tol``
   (default 1e-3): a typical change of the parameter moves the residual by less than 1/1000 of
   what the most sensitive parameter does, so reference noise or model error, not the data,
   would set its value (a calm surface and the bump scaling; clear water and the attenuation).
2. *Null space*: of the remaining columns, normalised to unit norm (so that the test measures
   redundancy, not sensitivity), the smallest singular value relative to the largest is below
   ``rel_tol`` (default 1e-3). The parameter with the largest component in that singular
   vector is frozen (the direction is mostly along it), the others that share the direction
   (component > 0.3) are named in the reason, and the test repeats on the rest. With the
   normalised columns, ``s_min/s_max < 1e-3`` means some combination of parameters changes
   the residual 1000x less than the best-determined one: the fit would move along it by
   ~1000x its typical change per unit of noise.

:func:`sweep_1d` / :func:`sweep_2d` tabulate the loss over a grid (for piecewise-constant
parameters such as step counts, which are fitted by Nelder-Mead or chosen from a sweep), and
:func:`probe_gradient_solver` measures what happens when a gradient solver is pointed at a
``derivative_free`` parameter anyway.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .solvers import FitProblem, FitResult, fit

NULL_COMPONENT = 0.3


@dataclass
class IdentifyReport:
    """Result of :func:`identify`. ``singular_values``: of the column-scaled Jacobian (all
    parameters, descending); ``condition``: their ratio max/min (inf if min is 0);
    ``sensitivity``: name -> relative sensitivity in [0, 1]; ``freeze``: name -> bool;
    ``reasons``: name -> text; ``condition_kept``: condition number of the normalised columns
    of the kept parameters."""

    names: list
    singular_values: np.ndarray
    condition: float
    sensitivity: dict
    freeze: dict
    reasons: dict
    condition_kept: float

    @property
    def fitted(self) -> list:
        return [n for n in self.names if not self.freeze[n]]

    @property
    def frozen(self) -> list:
        return [n for n in self.names if self.freeze[n]]

    def summary(self) -> dict:
        return {
            "singular_values": self.singular_values.tolist(),
            "condition": self.condition,
            "condition_kept": self.condition_kept,
            "sensitivity": self.sensitivity,
            "freeze": self.freeze,
            "reasons": self.reasons,
        }


def _cond(s: np.ndarray) -> float:
    return float(s[0] / s[-1]) if len(s) and s[-1] > 0 else float("inf")


def identify(
    J: np.ndarray, names: list[str], *, scales=None, rel_tol: float = 1e-3, sens_tol: float = 1e-3
) -> IdentifyReport:
    """Freeze decisions from ``J`` (m, k) = d residual / d parameter (physical units).

    ``scales`` (k,): each parameter's typical change (default 1: ``J`` already scaled).
    """
    J = np.asarray(J, np.float64)
    k = len(names)
    if J.ndim != 2 or J.shape[1] != k:
        raise ValueError(f"J has shape {J.shape}; expected (m, {k}) for names {names}")
    if not np.all(np.isfinite(J)):
        raise ValueError("J contains non-finite entries; identifiability is undefined there")
    sc = np.ones(k) if scales is None else np.asarray(scales, np.float64)
    if sc.shape != (k,) or np.any(~np.isfinite(sc)) or np.any(sc <= 0):
        raise ValueError(f"scales must be {k} finite positive numbers, got {sc}")
    Js = J * sc[None, :]
    sv = np.linalg.svd(Js, compute_uv=False)
    norms = np.linalg.norm(Js, axis=0)
    top = norms.max()
    sens = norms / top if top > 0 else np.zeros(k)
    freeze, reasons = {}, {}
    for n, s in zip(names, sens):
        if s < sens_tol:
            freeze[n] = True
            reasons[n] = (
                f"insensitive: relative sensitivity {s:.3g} < {sens_tol:g} (a change of one "
                "scale barely moves the residual)"
            )
    kept = [i for i, n in enumerate(names) if n not in freeze]
    while len(kept) > 1:
        A = Js[:, kept] / norms[kept][None, :]
        _, s, vt = np.linalg.svd(A, full_matrices=False)
        ratio = s[-1] / s[0]
        if ratio >= rel_tol:
            break
        v = np.abs(vt[-1])
        j = int(np.argmax(v + 1e-9 * (1 - sens[kept])))  # ties: freeze the less sensitive
        i = kept[j]
        partners = [names[kept[q]] for q in range(len(kept)) if q != j and v[q] > NULL_COMPONENT]
        freeze[names[i]] = True
        reasons[names[i]] = (
            f"null space: normalised singular value ratio {ratio:.3g} < {rel_tol:g}, "
            f"component {v[j]:.2f} in its singular vector"
            + (f", confounded with {partners}" if partners else "")
        )
        kept.pop(j)
    for n in names:
        if n not in freeze:
            freeze[n] = False
            reasons[n] = f"identified (relative sensitivity {sens[names.index(n)]:.3g})"
    if kept:
        s_kept = np.linalg.svd(Js[:, kept] / norms[kept][None, :], compute_uv=False)
        cond_kept = _cond(s_kept)
    else:
        cond_kept = float("nan")
    return IdentifyReport(
        list(names), sv, _cond(sv), dict(zip(names, sens.tolist())), freeze, reasons, cond_kept
    )


def identify_problem(
    problem: FitProblem, x: dict | None = None, names: list[str] | None = None, **kw
) -> IdentifyReport:
    """:func:`identify` on the problem's Jacobian at ``x`` (default: the defaults) for ``names``
    (default: every parameter not marked ``derivative_free``), scaled by each ``Param.typical``."""
    vals = problem.start_values(x)
    names = (
        [n for n in problem.names if not problem.params[n].derivative_free]
        if names is None
        else list(names)
    )
    _, J = problem.residual_and_jacobian(vals, names)
    return identify(J, names, scales=[problem.params[n].typical for n in names], **kw)


def _loss(problem: FitProblem, vals: dict) -> float:
    r = np.asarray(problem.residual(vals), np.float64)
    return 0.5 * float(r @ r) if np.all(np.isfinite(r)) else float("nan")


def sweep_1d(problem: FitProblem, name: str, values, x: dict | None = None) -> np.ndarray:
    """Loss ``0.5*||r||^2`` (n,) at ``name`` = each of ``values``, the rest at ``x``.
    A non-finite residual gives NaN in the table (reported, not raised)."""
    base = problem.start_values(x)
    if name not in problem.params:
        raise ValueError(f"unknown parameter {name!r}; known: {problem.names}")
    return np.array([_loss(problem, {**base, name: float(v)}) for v in values])


def sweep_2d(
    problem: FitProblem, name_a: str, values_a, name_b: str, values_b, x: dict | None = None
) -> np.ndarray:
    """Loss table (len(values_a), len(values_b)) over two parameters, the rest at ``x``."""
    base = problem.start_values(x)
    for n in (name_a, name_b):
        if n not in problem.params:
            raise ValueError(f"unknown parameter {n!r}; known: {problem.names}")
    return np.array(
        [
            [_loss(problem, {**base, name_a: float(a), name_b: float(b)}) for b in values_b]
            for a in values_a
        ]
    )


def probe_gradient_solver(
    problem: FitProblem,
    name: str,
    x0: dict | None = None,
    *,
    solver: str = "levenberg_marquardt",
    free: list[str] | None = None,
    **fit_kw,
) -> dict:
    """Point a gradient solver at a ``derivative_free`` parameter and measure the outcome.

    Returns ``{"fit": FitResult, "ad_derivative": ||dr/dp|| by AD, "fd_derivative": ||dr/dp||
    by a central difference of one ``scale``, "moved": |p_end - p_start|}`` at ``x0``.
    """
    p = problem.params.get(name)
    if p is None:
        raise ValueError(f"unknown parameter {name!r}; known: {problem.names}")
    vals = problem.start_values(x0)
    _, J = problem.residual_and_jacobian(vals, [name])
    h = p.typical
    lo, hi = max(vals[name] - h, p.lo), min(vals[name] + h, p.hi)
    r_hi = np.asarray(problem.residual({**vals, name: hi}), np.float64)
    r_lo = np.asarray(problem.residual({**vals, name: lo}), np.float64)
    fd = np.linalg.norm((r_hi - r_lo) / (hi - lo))
    free = list(free) if free is not None else [name]
    if name not in free:
        free.append(name)
    res: FitResult = fit(
        problem, vals, solver=solver, free=free, treat_as_continuous=[name], **fit_kw
    )
    return {
        "fit": res,
        "ad_derivative": float(np.linalg.norm(J[:, 0])),
        "fd_derivative": float(fd),
        "moved": abs(res.constants[name] - vals[name]),
    }
