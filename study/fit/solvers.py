"""The fitting engine: parameters and their transforms, optimistix solvers, the Adam baseline.

Parameters. Each fitted scalar is a :class:`Param` with a default, bounds ``(lo, hi)`` and a
``scale`` (a typical change, in the parameter's own units). Solvers never see the physical
value ``p``: they work on an unconstrained, dimensionless ``u = (g(p) - g(default)) / s``
with ``s = g'(default) * scale``, so ``u = 0`` at the default and one unit of ``u`` is about
one ``scale`` near the default, whatever the parameter's units. ``g`` (``transform``):

* ``linear`` (no bounds): ``g(p) = p``;
* ``log`` (only ``lo`` finite): ``g(p) = log(p - lo)``;
* ``neglog`` (only ``hi`` finite): ``g(p) = -log(hi - p)``;
* ``logit`` (both finite): ``g(p) = logit((p - lo) / (hi - lo))``;
* ``log_logit`` (both finite, ``lo > 0``): ``logit(log(p / lo) / log(hi / lo))`` - the
  default when ``hi / lo >= 1e3``, where a linear logit would squash the useful range;
* ``clip`` (never chosen by ``auto``): ``p = clip(default + scale*u, lo, hi)``, linear inside
  the box and flat outside it, so a bound is *reached* in finite ``u`` (one solver step can
  land on it) instead of approached forever: for a parameter whose best value may be its bound
  (a colour channel at 0, no highlight). ``dp/du`` is 0 outside the box; :func:`fit` then
  checks the sign of the loss gradient at the bound (the Karush-Kuhn-Tucker condition) and
  restarts the solver from just inside when the loss falls inwards, so a parameter clipped by
  an early, overshooting step is not left stranded there.

so every ``u`` maps inside (``clip``: onto) the bounds. The chain rule is applied on the NumPy side, before
JAX sees the Jacobian: ``dr/du = dr/dp * dp/du`` (a column scaling).

Problem. A :class:`FitProblem` wraps two NumPy-level callables that run Dr.Jit:
``residual(values: dict name -> float) -> (m,)`` and
``residual_and_jacobian(values, names) -> ((m,), (m, len(names)))`` (derivatives only for the
parameters being fitted, since each Jacobian column costs a forward-mode pass), and
optionally ``loss_drjit(values: dict name -> Dr.Jit scalar) -> Dr.Jit scalar 0.5*||r||^2``
for reverse-mode Adam.

Solvers (:data:`SOLVERS`): ``levenberg_marquardt``, ``gauss_newton``, ``dogleg`` through
``optimistix.least_squares``; ``bfgs`` and ``nelder_mead`` through ``optimistix.minimise`` on
``0.5*||r||^2``; ``nelder_mead`` is a plain NumPy Nelder-Mead (Lagarias et al. 1998
coefficients) on the same loss, because optimistix 0.1.0's ``NelderMead`` builds a degenerate
start simplex for a parameter vector of length > 1 (vertex ``i`` is not ``y0 + delta*e_i``;
on ``sum((y - c)^2)`` in 3-D it stops at a wrong point) and its ``y0_simplex`` option rejects
valid simplices; ``nelder_mead_optimistix`` keeps the optimistix solver for comparison;
``adam``: the plain loop of Mitsuba's inverse-rendering tutorials with
``drjit.opt.Adam`` (the optimiser Mitsuba 3 exposes as ``mi.ad.Adam``), over the Dr.Jit
gradient of the loss (reverse mode through ``loss_drjit`` when given, else ``J^T r`` from the
forward-mode Jacobian); no JAX. Parameters marked ``derivative_free`` (step counts, loop caps)
are held at their start by the gradient solvers and fitted only by Nelder-Mead.

Failures (step cap, non-finite residual, solver error) never propagate: :func:`fit` returns
a :class:`FitResult` with ``converged=False``, the reason in ``message`` and, for a crash,
the best point evaluated. A start on a bound is moved inside by 1e-3 of the scale. Bad arguments (unknown solver or parameter, start outside the
bounds) raise ValueError.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .bridge import DrJitResidual, make_jax_residual

LEAST_SQUARES = ("levenberg_marquardt", "gauss_newton", "dogleg")
MINIMISERS = ("bfgs", "nelder_mead", "nelder_mead_optimistix")
SOLVERS = LEAST_SQUARES + MINIMISERS + ("adam",)
DERIVATIVE_FREE = ("nelder_mead", "nelder_mead_optimistix")
TRANSFORMS = ("auto", "linear", "log", "neglog", "logit", "log_logit", "clip")
# default stopping rule of the gradient solvers (see :func:`fit`): the fit has stopped improving
# when the lowest loss seen fell by less than FTOL (relative) over the last FTOL_WINDOW steps
# when the lowest loss seen fell by less than max(FTOL, FTOL_SE / (m - k)) (relative) over the
# last FTOL_WINDOW steps. FTOL_SE / (m - k): with m residuals and k parameters, moving one
# parameter by d standard errors from the optimum raises the loss by about d^2 * loss / (m - k),
# so an improvement below 1.0 * loss / (m - k) is worth less than one standard error
FTOL, FTOL_SE, FTOL_WINDOW = 1e-6, 1.0, 3


def _sigmoid(z, xp):
    return 0.5 + 0.5 * xp.tanh(0.5 * z)  # no overflow for large |z|


@dataclass(frozen=True)
class Param:
    """One fitted scalar: physical ``default``, bounds ``[lo, hi]``, ``scale`` (physical units;
    None: ``|default|``, or ``(hi - lo) / 10`` when the default is 0, or 1)."""

    name: str
    default: float
    lo: float = -math.inf
    hi: float = math.inf
    scale: float | None = None
    transform: str = "auto"
    derivative_free: bool = False

    def __post_init__(self):
        lo, hi, d = float(self.lo), float(self.hi), float(self.default)
        if self.transform not in TRANSFORMS:
            raise ValueError(
                f"parameter {self.name}: unknown transform {self.transform!r}; "
                f"choose one of {TRANSFORMS}"
            )
        if not math.isfinite(d) or not lo < hi:
            raise ValueError(
                f"parameter {self.name}: need a finite default and lo < hi, "
                f"got default={d}, lo={lo}, hi={hi}"
            )
        kind = self.kind
        if kind == "clip" and not lo <= d <= hi:
            raise ValueError(f"parameter {self.name}: default {d} must lie inside [{lo}, {hi}]")
        if kind not in ("linear", "clip") and not lo < d < hi:
            raise ValueError(
                f"parameter {self.name}: default {d} must lie strictly inside "
                f"({lo}, {hi}) for the {kind} transform; move it or widen the bounds"
            )
        if kind in ("logit", "log_logit") and not (math.isfinite(lo) and math.isfinite(hi)):
            raise ValueError(f"parameter {self.name}: transform {kind} needs finite bounds")
        if kind == "log_logit" and lo <= 0:
            raise ValueError(f"parameter {self.name}: transform log_logit needs lo > 0, got {lo}")
        if kind == "log" and not math.isfinite(lo):
            raise ValueError(f"parameter {self.name}: transform log needs a finite lo")
        if kind == "neglog" and not math.isfinite(hi):
            raise ValueError(f"parameter {self.name}: transform neglog needs a finite hi")
        if self.scale is not None and not (math.isfinite(self.scale) and self.scale > 0):
            raise ValueError(
                f"parameter {self.name}: scale must be finite and > 0, got {self.scale}"
            )

    @property
    def kind(self) -> str:
        """The transform actually used (``auto`` resolved from the bounds)."""
        if self.transform != "auto":
            return self.transform
        lo_f, hi_f = math.isfinite(self.lo), math.isfinite(self.hi)
        if lo_f and hi_f:
            return "log_logit" if self.lo > 0 and self.hi / self.lo >= 1e3 else "logit"
        return "log" if lo_f else ("neglog" if hi_f else "linear")

    @property
    def typical(self) -> float:
        """The scale actually used (physical units)."""
        if self.scale is not None:
            return float(self.scale)
        if self.default != 0:
            return abs(float(self.default))
        return (self.hi - self.lo) / 10 if math.isfinite(self.hi - self.lo) else 1.0

    # g, g^-1, g' -------------------------------------------------------------------------
    def _g(self, p):
        lo, hi, k = self.lo, self.hi, self.kind
        if k in ("linear", "clip"):
            return p
        if k == "log":
            return np.log(p - lo)
        if k == "neglog":
            return -np.log(hi - p)
        q = (p - lo) / (hi - lo) if k == "logit" else np.log(p / lo) / np.log(hi / lo)
        return np.log(q) - np.log1p(-q)

    def _ginv(self, z, xp=np):
        lo, hi, k = self.lo, self.hi, self.kind
        if k == "linear":
            return z
        if k == "clip":
            return xp.clip(z, lo, hi) if xp is np else xp.clip(z, float(lo), float(hi))
        if k == "log":
            return lo + xp.exp(z)
        if k == "neglog":
            return hi - xp.exp(-z)
        # clipped: at saturation the float rounding of lo*exp(log(hi/lo)) can exceed hi
        if k == "logit":
            p = lo + (hi - lo) * _sigmoid(z, xp)
        else:
            p = lo * xp.exp(math.log(hi / lo) * _sigmoid(z, xp))
        return np.clip(p, lo, hi) if xp is np else xp.clip(p, float(lo), float(hi))

    def _gprime(self, p):
        lo, hi, k = self.lo, self.hi, self.kind
        if k in ("linear", "clip"):
            return np.ones_like(p)
        if k == "log":
            return 1.0 / (p - lo)
        if k == "neglog":
            return 1.0 / (hi - p)
        if k == "logit":
            q = (p - lo) / (hi - lo)
            return 1.0 / ((hi - lo) * q * (1 - q))
        L = math.log(hi / lo)
        q = np.log(p / lo) / L
        return 1.0 / (p * L * q * (1 - q))

    @property
    def _s(self) -> float:
        return float(self._gprime(np.float64(self.default))) * self.typical

    def to_u(self, p) -> np.ndarray:
        """Physical value(s) -> unconstrained ``u`` (float64)."""
        p = np.asarray(p, np.float64)
        if self.kind == "clip" and np.any((p < self.lo) | (p > self.hi)):
            raise ValueError(f"parameter {self.name}: value {p} is outside [{self.lo}, {self.hi}]")
        if self.kind not in ("linear", "clip") and np.any((p <= self.lo) | (p >= self.hi)):
            raise ValueError(
                f"parameter {self.name}: value {p} is not strictly inside ({self.lo}, {self.hi})"
            )
        return (self._g(p) - self._g(np.float64(self.default))) / self._s

    def from_u(self, u, xp=np):
        """Unconstrained ``u`` -> physical value; ``xp`` = ``numpy`` or ``drjit`` (differentiable)."""
        return self._ginv(float(self._g(np.float64(self.default))) + self._s * u, xp)

    def at_bound(self, u) -> str | None:
        """``'lower'`` / ``'upper'`` when ``u`` maps onto (or beyond) a bound of a ``clip``
        parameter, else None (the other transforms never reach their bounds)."""
        if self.kind != "clip":
            return None
        z = float(self.default) + self._s * float(u)
        return "lower" if z <= self.lo else "upper" if z >= self.hi else None

    def dp_du(self, u) -> np.ndarray:
        """Derivative of the physical value with respect to ``u`` (float64); computed from
        ``z = g(default) + s*u`` so that it tends to 0, not NaN, where ``p`` saturates at a bound."""
        z = float(self._g(np.float64(self.default))) + self._s * np.asarray(u, np.float64)
        k, lo, hi = self.kind, self.lo, self.hi
        if k == "linear":
            d = np.ones_like(z)
        elif k == "clip":  # one-sided at the bound itself (the inward derivative)
            d = ((z >= lo) & (z <= hi)).astype(np.float64)
        elif k == "log":
            d = np.exp(z)
        elif k == "neglog":
            d = np.exp(-z)
        else:
            sg = _sigmoid(z, np)
            d = (
                (hi - lo) * sg * (1 - sg)
                if k == "logit"
                else self._ginv(z) * math.log(hi / lo) * sg * (1 - sg)
            )
        return self._s * d


class FitProblem:
    """Residual over named parameters (see the module docstring for the callables' contract).

    ``params``: list of :class:`Param` (unique names). ``drjit_float``: the Dr.Jit float type
    of the Adam variables handed to ``loss_drjit`` (default ``drjit.llvm.ad.Float``).
    """

    def __init__(
        self,
        params: list[Param],
        residual: Callable,
        residual_and_jacobian: Callable,
        *,
        loss_drjit: Callable | None = None,
        drjit_float=None,
        name: str = "problem",
    ):
        names = [p.name for p in params]
        if not names or len(set(names)) != len(names):
            raise ValueError(
                f"{name}: need a non-empty list of uniquely named parameters, got {names}"
            )
        self.params = {p.name: p for p in params}
        self.names = names
        self.residual, self.residual_and_jacobian = residual, residual_and_jacobian
        self.loss_drjit, self.drjit_float, self.name = loss_drjit, drjit_float, name

    def start_values(self, x0: dict | None) -> dict:
        """Full dict name -> float: ``x0`` over the defaults, checked against the bounds."""
        x0 = dict(x0 or {})
        unknown = set(x0) - set(self.names)
        if unknown:
            raise ValueError(
                f"{self.name}: unknown parameter(s) {sorted(unknown)}; known: {self.names}"
            )
        vals = {n: float(x0.get(n, p.default)) for n, p in self.params.items()}
        for n, v in vals.items():
            p = self.params[n]
            if not (math.isfinite(v) and p.lo <= v <= p.hi):
                raise ValueError(
                    f"{self.name}: start value {n}={v} is not finite or outside [{p.lo}, {p.hi}]"
                )
        return vals

    def bridge(self, base: dict, free: list[str]) -> DrJitResidual:
        """JAX residual of ``u`` (len(free),) with the other parameters held at ``base``."""
        ps = [self.params[n] for n in free]

        def values(u):
            v = dict(base)
            v.update({p.name: float(p.from_u(ui)) for p, ui in zip(ps, u)})
            return v

        def fn_value(u):
            return self.residual(values(u))

        def fn_value_and_jac(u):
            r, J = self.residual_and_jacobian(values(u), list(free))
            J = np.asarray(J, np.float64)
            if J.ndim != 2 or J.shape[1] != len(free):
                raise ValueError(
                    f"{self.name}: residual_and_jacobian returned J of shape {J.shape} "
                    f"for {len(free)} names"
                )
            return r, J * np.array([p.dp_du(ui) for p, ui in zip(ps, u)])[None, :]

        m = len(np.asarray(self.residual(base)).reshape(-1))
        return make_jax_residual(fn_value, fn_value_and_jac, len(free), m, name=self.name)


@dataclass
class FitResult:
    """Outcome of :func:`fit`.

    ``names``: fitted parameters; ``x`` (k,) their physical values; ``u`` (k,) unconstrained;
    ``constants``: every parameter's value (fitted and held); ``losses``: ``0.5*||r||^2`` at each
    evaluation in call order (optimistix: every evaluated point, trial points included; Adam:
    one per iteration); ``iterations``: solver steps.
    """

    solver: str
    names: list
    x: np.ndarray
    u: np.ndarray
    constants: dict
    loss_start: float
    loss: float
    losses: list
    iterations: int
    n_value_calls: int
    n_jac_calls: int
    n_grad_calls: int
    seconds: float
    converged: bool
    message: str
    extra: dict = field(default_factory=dict)

    def summary(self) -> dict:
        """JSON-serialisable summary (no history)."""
        return {
            "solver": self.solver,
            "constants": self.constants,
            "loss_start": self.loss_start,
            "loss": self.loss,
            "iterations": self.iterations,
            "n_value_calls": self.n_value_calls,
            "n_jac_calls": self.n_jac_calls,
            "n_grad_calls": self.n_grad_calls,
            "seconds": self.seconds,
            "converged": self.converged,
            "message": self.message,
        }


def _optx_solver(name: str, rtol: float, atol: float):
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


def _free_names(problem: FitProblem, solver: str, free, treat_as_continuous) -> list[str]:
    cont = set(treat_as_continuous or ())
    unknown = (set(free or ()) | cont) - set(problem.names)
    if unknown:
        raise ValueError(f"unknown parameter(s) {sorted(unknown)}; known: {problem.names}")
    gradient = solver not in DERIVATIVE_FREE
    if free is None:
        free = [
            n
            for n in problem.names
            if not (gradient and problem.params[n].derivative_free and n not in cont)
        ]
    free = list(free)
    if gradient:
        bad = [n for n in free if problem.params[n].derivative_free and n not in cont]
        if bad:
            raise ValueError(
                f"parameter(s) {bad} are marked derivative_free; fit them with "
                "solver='nelder_mead' or sweep_1d/sweep_2d, or pass "
                "treat_as_continuous=[...] to measure what a gradient solver does"
            )
    if not free:
        raise ValueError("nothing to fit: no free parameter for this solver")
    return free


def _inside(p: Param, v: float) -> float:
    """A start on a bound of a bounded transform (where ``u`` would be infinite) is moved
    inside by 1e-3 of the parameter's scale (at most a tenth of the interval)."""
    if p.kind in ("linear", "clip"):
        return v
    eps = min(1e-3 * p.typical, 0.1 * (p.hi - p.lo))
    return min(max(v, p.lo + eps), p.hi - eps)


def fit(
    problem: FitProblem,
    x0: dict | None = None,
    *,
    solver: str,
    max_steps: int = 200,
    rtol: float = 1e-8,
    atol: float = 1e-12,
    free: list[str] | None = None,
    treat_as_continuous: list[str] = (),
    lr: float = 0.05,
    patience: int | None = None,
    nm_step: float = 0.5,
    ftol: float | None = None,
    ftol_window: int = FTOL_WINDOW,
    ftol_se: float | None = None,
    kkt_restarts: int = 3,
) -> FitResult:
    """Fit ``problem`` from ``x0`` (dict name -> physical value; missing: defaults).

    ``solver``: one of :data:`SOLVERS`. ``free``: names to fit (default: every parameter the
    solver can fit; the rest stay at ``x0``). ``rtol``/``atol``: optimistix's tolerances (its
    Cauchy test: the step in ``u`` *and* the change of the loss both below ``atol + rtol*|.|``).
    ``ftol`` (None: off): the loss-stall rule, checked after every step of the optimistix
    solvers and Adam: stop (converged) when the lowest loss seen fell by less than
    ``ftol * loss`` over the last ``ftol_window`` steps - the fit has stopped improving, whatever
    the parameters still do (a parameter crawling towards an unreachable bound would otherwise
    run the solver to its cap). ``ftol_se`` (None: off) raises the tolerance to
    ``ftol_se / (m - k)`` when that is larger (an improvement worth less than
    ``sqrt(ftol_se)`` standard errors of one parameter, see :data:`FTOL_SE`). The calibration
    uses ``ftol = FTOL = 1e-6``, ``ftol_se = FTOL_SE = 1`` over ``FTOL_WINDOW = 3`` steps. For Adam (the tutorial loop runs to the cap), with ``patience``
    set, the run also stops (converged) when the best loss improved by less than
    ``rtol*loss + atol`` over the last ``patience`` iterations; Adam returns the lowest-loss
    iterate. ``lr``: Adam's learning rate in ``u`` units (one unit is about one ``scale``).
    ``max_steps``: step cap (Adam: iterations; with restarts, over all of them).
    ``nm_step``: edge of Nelder-Mead's start simplex in ``u`` units (vertices ``u0`` and
    ``u0 + nm_step*e_i``; optimistix's own default is 2.5e-4 at ``u = 0``, which stalled far
    from the minimum). ``kkt_restarts``: how many times a ``clip`` parameter the solver left on
    a bound may be moved back inside when the loss gradient there points inwards.

    ``FitResult.extra``: ``step_losses`` / ``step_seconds`` (lowest loss seen and seconds since
    the start, after each step), ``at_bound`` (name -> ``'lower'``/``'upper'`` for ``clip``
    parameters on a bound at the end), ``restarts`` (how many KKT restarts ran).
    """
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; valid solvers: {', '.join(SOLVERS)}")
    if max_steps < 1:
        raise ValueError(f"max_steps must be >= 1, got {max_steps}")
    if ftol is not None and not (ftol >= 0 and ftol_window >= 1):
        raise ValueError(f"need ftol >= 0 and ftol_window >= 1, got {ftol}, {ftol_window}")
    base = problem.start_values(x0)
    names = _free_names(problem, solver, free, treat_as_continuous)
    ps = [problem.params[n] for n in names]
    u0 = np.array([float(p.to_u(_inside(p, base[p.name]))) for p in ps])
    t0 = time.perf_counter()
    res = problem.bridge(base, names)
    n_grad = 0
    try:
        loss0 = 0.5 * float(np.sum(res.value(u0) ** 2))
    except FloatingPointError as e:
        return _result(
            problem,
            solver,
            names,
            base,
            u0,
            math.nan,
            [],
            0,
            res,
            0,
            t0,
            False,
            f"start point rejected: {e}",
        )
    trace = _Trace(t0, loss0)
    if ftol is not None and ftol_se:
        ftol = max(ftol, ftol_se / max(res.m - len(names), 1))
    u, iters, restarts, adam_losses = u0, 0, 0, []
    while True:
        left = max_steps - iters
        if solver == "nelder_mead":
            u, it, ok, msg = _nelder_mead(res, u, left, rtol, atol, nm_step, trace)
        elif solver == "adam":
            u, it, ok, msg, ng, ls = _adam(
                problem,
                res,
                base,
                names,
                u,
                left,
                lr,
                rtol,
                atol,
                patience,
                trace,
                ftol,
                ftol_window,
            )
            n_grad += ng
            adam_losses += ls
        elif solver == "nelder_mead_optimistix":
            u, it, ok, msg = _optimistix(res, solver, u, left, rtol, atol, nm_step)
            trace.note(res.stats.best_loss)
        else:
            u, it, ok, msg = _optimistix_steps(
                res, solver, u, left, rtol, atol, ftol, ftol_window, trace
            )
        iters += it
        if not ok or restarts >= kkt_restarts or iters >= max_steps:
            break
        inward = _kkt_violations(problem, base, ps, u, res, ftol)
        if not inward:
            break
        restarts += 1
        u = np.array(u, np.float64)
        for j, side in inward.items():  # just inside the bound the loss falls inwards
            p = ps[j]
            step = 0.05 * p.typical
            u[j] = float(
                p.to_u(
                    min(max(p.lo + step, p.lo), p.hi)
                    if side == "lower"
                    else max(min(p.hi - step, p.hi), p.lo)
                )
            )
        msg += f"; restarted from inside the bound for {[ps[j].name for j in inward]}"
    if restarts:
        msg += f" ({iters} steps in all)"
    try:
        loss = 0.5 * float(np.sum(res.value(u) ** 2))
    except FloatingPointError as e:
        loss, ok, msg = math.nan, False, f"{msg}; final point non-finite: {e}"
    if res.stats.best_x is not None and res.stats.best_loss < loss and solver != "adam":
        u, loss = np.asarray(res.stats.best_x, np.float64), float(res.stats.best_loss)
    out = _result(
        problem,
        solver,
        names,
        base,
        u,
        loss0,
        adam_losses if solver == "adam" else list(res.stats.losses),
        iters,
        res,
        n_grad,
        t0,
        ok,
        msg,
        loss,
    )
    out.extra.update(
        {
            "step_losses": trace.losses,
            "step_seconds": trace.seconds,
            "at_bound": {p.name: p.at_bound(ui) for p, ui in zip(ps, out.u) if p.at_bound(ui)},
            "restarts": restarts,
        }
    )
    return out


class _Trace:
    """Lowest loss seen and seconds since the start, after each solver step."""

    def __init__(self, t0: float, loss0: float):
        self.t0, self.best = t0, loss0
        self.losses, self.seconds = [], []

    def note(self, loss: float) -> None:
        if math.isfinite(loss):
            self.best = min(self.best, float(loss))
        self.losses.append(self.best)
        self.seconds.append(time.perf_counter() - self.t0)

    def stalled(self, ftol: float | None, window: int) -> bool:
        """The lowest loss fell by less than ``ftol * loss`` over the last ``window`` steps."""
        if ftol is None or len(self.losses) <= window:
            return False
        return self.losses[-window - 1] - self.losses[-1] <= ftol * self.losses[-1]


def _kkt_violations(
    problem: FitProblem, base: dict, ps: list, u, res: DrJitResidual, ftol: float | None = None
) -> dict:
    """Index -> side for the ``clip`` parameters on a bound where the loss decreases inwards
    (``dL/dp < 0`` at a lower bound, ``> 0`` at an upper one) by a worthwhile amount: the
    Gauss-Newton gain of moving that parameter alone inwards, ``g^2 / (2 ||J_j||^2)``, exceeds
    ``ftol * loss`` (the stopping tolerance; 1e-9 without one). The solver left them there by
    overshooting, not because the data want it."""
    at = {j: p.at_bound(ui) for j, (p, ui) in enumerate(zip(ps, u)) if p.at_bound(ui)}
    if not at:
        return {}
    vals = dict(base)
    vals.update({p.name: float(p.from_u(ui)) for p, ui in zip(ps, u)})
    names = [ps[j].name for j in at]
    try:
        r, J = problem.residual_and_jacobian(vals, names)
    except FloatingPointError:
        return {}
    r, J = np.asarray(r, np.float64), np.asarray(J, np.float64)
    g = J.T @ r  # dL/dp, physical units
    loss = 0.5 * float(r @ r)
    out = {}
    tol = (ftol if ftol is not None else 1e-9) * max(loss, 1e-300)
    for q, ((j, side), gj) in enumerate(zip(at.items(), g)):
        inward = gj if side == "lower" else -gj  # dL per unit step inwards
        h = float(J[:, q] @ J[:, q])
        if inward < 0 and h > 0 and gj * gj / (2 * h) > tol:
            out[j] = side
    return out


def _result(
    problem, solver, names, base, u, loss0, losses, iters, res, n_grad, t0, ok, msg, loss=math.nan
) -> FitResult:
    ps = [problem.params[n] for n in names]
    x = np.array([float(p.from_u(ui)) for p, ui in zip(ps, u)])
    consts = dict(base)
    consts.update(dict(zip(names, x.tolist())))
    return FitResult(
        solver,
        names,
        x,
        np.asarray(u, np.float64),
        consts,
        loss0,
        loss,
        losses,
        iters,
        res.stats.n_value_calls,
        res.stats.n_jac_calls,
        n_grad,
        time.perf_counter() - t0,
        bool(ok),
        msg,
    )


def _aborted(res: DrJitResidual, exc: Exception, u0, steps: int):
    """A jitted optimistix solve or step raised. A non-finite model value inside it (JAX wraps the
    callback's error) is reported and the best point evaluated returned, as the solvers' result
    tuple; any other error is a bug and propagates."""
    if not isinstance(res.last_error, FloatingPointError):
        raise (res.last_error or exc) from exc
    cause = res.last_error
    best = res.stats.best_x if res.stats.best_x is not None else np.asarray(u0)
    first = str(cause).strip().splitlines()[0] if str(cause).strip() else repr(cause)
    return (
        np.asarray(best),
        steps,
        False,
        (f"solver aborted ({type(cause).__name__}): {first}; returning the best point evaluated"),
    )


def _optimistix(res: DrJitResidual, solver: str, u0, max_steps, rtol, atol, nm_step):
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    s = _optx_solver(solver, rtol, atol)

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
        return _aborted(res, e, u0, 0)
    steps = int(steps)
    ok = bool(result == optx.RESULTS.successful)
    msg = "converged" if ok else optx.RESULTS[result]
    u = np.asarray(value, np.float64)
    if not np.all(np.isfinite(u)):
        best = res.stats.best_x if res.stats.best_x is not None else np.asarray(u0)
        return (
            np.asarray(best),
            steps,
            False,
            "solver returned non-finite parameters; returning the best point evaluated",
        )
    return u, steps, ok, f"{msg} after {steps} steps"


def _optimistix_steps(
    res: DrJitResidual, solver: str, u0, max_steps, rtol, atol, ftol, window, trace: _Trace
):
    """The optimistix solver driven one step at a time from Python (its ``init``/``step``/
    ``terminate`` interface, each step jitted), so that the loss-stall rule (:meth:`_Trace.stalled`)
    can stop it; otherwise the same iteration as ``optx.least_squares`` / ``optx.minimise``.
    Returns (u, steps, ok, msg)."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    s = _optx_solver(solver, rtol, atol)
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
        return _aborted(res, e, u0, steps)
    u = np.asarray(y, np.float64)
    if not np.all(np.isfinite(u)):
        best = res.stats.best_x if res.stats.best_x is not None else np.asarray(u0)
        return (
            np.asarray(best),
            steps,
            False,
            "solver returned non-finite parameters; returning the best point evaluated",
        )
    return u, steps, ok, msg


def _adam(
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
    trace: _Trace | None = None,
    ftol: float | None = None,
    window: int = FTOL_WINDOW,
):
    """The tutorial loop: Dr.Jit Adam on ``u``; gradient from ``dr.backward`` of ``loss_drjit``
    or, without it, ``J^T r`` (forward-mode Jacobian). Returns (u, iters, ok, msg, n_grad, losses)."""
    import drjit as dr
    import drjit.opt  # noqa: F401  (registers dr.opt)

    ps = [problem.params[n] for n in names]
    Float = problem.drjit_float
    if Float is None:
        import drjit.llvm.ad as m

        Float = m.Float
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


def _nelder_mead(
    res: DrJitResidual, u0, max_steps, rtol, atol, nm_step, trace: _Trace | None = None
):
    """Nelder-Mead on ``0.5*||r(u)||^2`` (NumPy; values only). Converged when every vertex is
    within ``atol + rtol*|u_best|`` of the best (max norm) and every value within
    ``atol + rtol*|f_best|`` of the best one (optimistix's criterion). Returns (u, steps, ok, msg)."""
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
