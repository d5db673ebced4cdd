"""The fit problem (a residual over named parameters), the settings of a fit, its typed result
and the default stopping rule."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .jax_residual import DrJitResidual, make_jax_residual
from .params import Param

# default stopping rule of the gradient solvers (see ``solvers.fit``): the fit has stopped
# improving when the lowest loss seen fell by less than max(FTOL, FTOL_SE / (m - k)) (relative) over
# the last FTOL_WINDOW steps. FTOL_SE / (m - k): with m residuals and k parameters, moving one
# parameter by d standard errors from the optimum raises the loss by about d^2 * loss / (m - k),
# so an improvement below 1.0 * loss / (m - k) is worth less than one standard error
FTOL, FTOL_SE, FTOL_WINDOW = 1e-6, 1.0, 3


@dataclass(frozen=True)
class SolverSettings:
    """How a fit runs (see :func:`study.fit.solvers.fit`).

    ``max_steps``: step cap (Adam: iterations; with restarts, over all of them). ``rtol`` /
    ``atol``: the solvers' own tolerances (optimistix's Cauchy test: the step in ``u`` *and* the
    change of the loss both below ``atol + rtol*|.|``; Nelder-Mead's simplex and values; Adam's
    ``patience`` rule). ``ftol`` (None: off): the loss-stall rule - stop (converged) when the
    lowest loss seen fell by less than ``ftol * loss`` over the last ``ftol_window`` steps;
    ``ftol_se`` (None: off) raises that tolerance to ``ftol_se / (m - k)`` when larger.
    ``lr``: Adam's learning rate in ``u`` units; ``patience`` (None: off): Adam also stops when
    its best loss improved by less than ``rtol*loss + atol`` over that many iterations.
    ``nm_step``: edge of Nelder-Mead's start simplex in ``u`` units. ``kkt_restarts``: how many
    times a ``clip`` parameter left on a bound may be moved back inside when the loss gradient
    there points inwards.
    """

    max_steps: int = 200
    rtol: float = 1e-8
    atol: float = 1e-12
    ftol: float | None = None
    ftol_window: int = FTOL_WINDOW
    ftol_se: float | None = None
    lr: float = 0.05
    patience: int | None = None
    nm_step: float = 0.5
    kkt_restarts: int = 3

    def __post_init__(self):
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {self.max_steps}")
        if self.ftol is not None and not (self.ftol >= 0 and self.ftol_window >= 1):
            raise ValueError(
                f"need ftol >= 0 and ftol_window >= 1, got {self.ftol}, {self.ftol_window}"
            )

    def stall_tolerance(self, m: int, k: int) -> float | None:
        """The relative tolerance of the loss-stall rule for ``m`` residuals and ``k`` fitted
        parameters: ``ftol``, raised to ``ftol_se / (m - k)`` when that is larger."""
        if self.ftol is None or not self.ftol_se:
            return self.ftol
        return max(self.ftol, self.ftol_se / max(m - k, 1))


# the settings of a calibration's fits: tolerances on u (one unit is about a 50 % change) and on
# the loss far below the parameters' standard errors, and the loss-stall rule
CALIBRATION_SETTINGS = SolverSettings(
    rtol=1e-6, atol=1e-9, ftol=FTOL, ftol_window=FTOL_WINDOW, ftol_se=FTOL_SE
)


class FitProblem:
    """Residual over named parameters (the callables' contract: ``study.fit.solvers``).

    ``params``: list of :class:`Param` (unique names). ``drjit_float``: the Dr.Jit float type
    of the Adam variables handed to ``loss_drjit`` (default: the ``Float`` of the run's backend,
    ``shaders_port.pipeline.texture.backend_types()``). ``normal_equations``: None, or
    ``(values, free) -> study.fit.normal_equations.NormalEquations`` of the residual; when given,
    the solvers see the compressed system of ``len(free) + 1`` rows in place of the residual
    (:meth:`jax_residual`).
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
        normal_equations: Callable | None = None,
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
        self.normal_equations = normal_equations

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

    def jax_residual(self, base: dict, free: list[str]) -> DrJitResidual:
        """JAX residual of ``u`` (len(free),) with the other parameters held at ``base``: the
        residual itself, or with ``normal_equations`` the compressed system
        (``study.fit.normal_equations``), whose ``count`` is the residuals it stands for."""
        ps = [self.params[n] for n in free]

        def values(u):
            v = dict(base)
            v.update({p.name: float(p.from_u(ui)) for p, ui in zip(ps, u)})
            return v

        m = len(np.asarray(self.residual(base)).reshape(-1))
        if self.normal_equations is not None:
            return self._compressed(values, ps, list(free), m)

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

        return make_jax_residual(fn_value, fn_value_and_jac, len(free), m, name=self.name)

    def _compressed(self, values: Callable, ps: list, free: list[str], m: int) -> DrJitResidual:
        """The residual of (k + 1) rows with the problem's normal equations and loss. A value
        call (no Jacobian) gives ``[0, ..., 0, |r|]``: the same loss; the solvers read a
        residual's entries only together with its Jacobian, from one call."""
        k = len(free)

        def fn_value(u):
            r = np.asarray(self.residual(values(u)), np.float64).reshape(-1)
            out = np.zeros(k + 1)
            out[k] = np.sqrt(float(r @ r))
            return out

        def fn_value_and_jac(u):
            ne = self.normal_equations(values(u), free)
            return ne.scaled([p.dp_du(ui) for p, ui in zip(ps, u)]).compressed()

        res = make_jax_residual(fn_value, fn_value_and_jac, k, k + 1, name=self.name)
        res.count = m
        return res


@dataclass
class FitResult:
    """Outcome of :func:`study.fit.solvers.fit`.

    ``names``: fitted parameters; ``x`` (k,) their physical values; ``u`` (k,) unconstrained;
    ``constants``: every parameter's value (fitted and held); ``losses``: ``0.5*||r||^2`` at each
    evaluation in call order (every evaluated point, trial points included; Adam: one per
    iteration); ``iterations``: solver steps (over every restart). ``step_losses`` /
    ``step_seconds``: lowest loss seen and seconds since the start, after each step;
    ``at_bound``: name -> ``'lower'``/``'upper'`` for the ``clip`` parameters on a bound at the
    end; ``restarts``: how many times the fit restarted from inside a bound.
    ``seconds_in_model``: of ``seconds``, those in the model's evaluations (the shader on its
    backend and what reads its results back; the rest is the solver on the host).
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
    step_losses: list = field(default_factory=list)
    step_seconds: list = field(default_factory=list)
    seconds_in_model: float = 0.0
    at_bound: dict = field(default_factory=dict)
    restarts: int = 0

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
            "seconds_in_model": self.seconds_in_model,
            "converged": self.converged,
            "message": self.message,
        }
