"""A residual computed by Dr.Jit, seen by JAX (and so by optimistix) as a differentiable function.

:func:`make_jax_residual` wraps two NumPy-level callables that run Dr.Jit:

* ``fn_value(x)``: ``x`` (k,) float64 -> residual ``r`` (m,) float64;
* ``fn_value_and_jac(x)``: ``x`` (k,) float64 -> ``(r (m,), J (m, k))`` float64, the Jacobian
  ``J[i, j] = d r_i / d x_j`` (in practice from Dr.Jit forward-mode AD, one pass per column).

The returned :class:`DrJitResidual` is a JAX function ``x -> r`` that works under ``jax.jit``,
``jax.jvp``, ``jax.linearize``, ``jax.grad`` / ``jax.vjp`` and inside optimistix's least-squares
solvers and minimisers. It is a ``jax.custom_jvp`` function: the primal calls ``fn_value``
through one ``jax.pure_callback``; the JVP rule calls ``fn_value_and_jac`` through *one*
``jax.pure_callback`` and returns ``J @ t`` computed in JAX. ``J @ t`` is linear in the tangent
``t`` and transposable, so reverse mode (``J.T @ ct``) works too, with no further Dr.Jit call.
The NumPy solvers call the same computation directly (:meth:`DrJitResidual.value`,
:meth:`DrJitResidual.value_and_jac`); every call, from either side, is counted in
:class:`CallStats`, which also keeps the lowest-loss point evaluated.

Precision: building a residual switches JAX to 64-bit floats for the whole process
(``jax.config.update("jax_enable_x64", True)``), because the solvers' convergence tests need
more than float32 once the residual is small. Code that imports this module is not affected
until it builds a residual; after that, JAX arrays created from Python floats default to
float64 in that process. Dr.Jit itself may compute in float32; values are cast to float64.

Non-finite values: a parameter vector holding NaN or infinity is refused before the model runs
(:class:`NonFiniteParameterError`); a NaN or an infinity in what ``fn_value`` or
``fn_value_and_jac`` returns raises :class:`NonFiniteResidualError` (naming the parameter vector
and how many entries were bad). Both are ``FloatingPointError``s. JAX re-raises them from a
jitted computation wrapped in its runtime error, so the residual also keeps the original in
``last_error``, where the solver loop (``study.fit.solver_loop``) reads the cause of an aborted
solve. Nothing continues with NaN.
"""

from __future__ import annotations

import functools
import itertools
import weakref
from dataclasses import dataclass, field
from typing import Callable

import numpy as np


class NonFiniteResidualError(FloatingPointError):
    """The Dr.Jit residual or Jacobian contained NaN or infinity at some parameter vector."""


class NonFiniteParameterError(FloatingPointError):
    """A solver asked for the residual at a parameter vector holding NaN or infinity (a step that
    blew up); raised before the model is called."""


class ResidualShapeError(ValueError):
    """A Dr.Jit callable returned an array of the wrong shape."""


def enable_x64() -> None:
    """Switch JAX to 64-bit floats for this process (see the module docstring)."""
    import jax

    if not jax.config.jax_enable_x64:
        jax.config.update("jax_enable_x64", True)


@dataclass
class CallStats:
    """Bookkeeping of the Dr.Jit calls made through a :class:`DrJitResidual`.

    ``losses`` holds ``0.5 * ||r||^2`` at every evaluated point, in call order, including trial
    points a solver later rejects; ``kinds`` says for each whether it was a value ('v') or a
    value-and-Jacobian ('j') call. ``best_x`` / ``best_loss`` is the lowest-loss point seen.
    """

    n_value_calls: int = 0
    n_jac_calls: int = 0
    seconds_in_drjit: float = 0.0
    losses: list = field(default_factory=list)
    kinds: list = field(default_factory=list)
    best_x: np.ndarray | None = None
    best_loss: float = float("inf")


class DrJitResidual:
    """JAX-callable residual ``x (k,) float64 -> r (m,) float64`` backed by Dr.Jit callables.

    Attributes: ``k``, ``m``, ``count`` (the residuals the ``m`` entries stand for: ``m``, or
    more for a compressed system, ``study.fit.problem.FitProblem.jax_residual``), ``stats``
    (:class:`CallStats`), ``last_error`` (the last
    :class:`NonFiniteResidualError` / :class:`ResidualShapeError` raised inside a callback, or
    None), ``handle`` (int: what names this residual to :func:`shared_residual`'s function).
    Call :meth:`value` / :meth:`value_and_jac` for the same computation from NumPy (counted the
    same way).
    """

    def __init__(
        self, fn_value: Callable, fn_value_and_jac: Callable, k: int, m: int, name: str = "residual"
    ):
        if int(k) < 1 or int(m) < 1:
            raise ValueError(
                f"{name}: need k >= 1 parameters and m >= 1 residuals, got k={k}, m={m}"
            )
        enable_x64()
        self.fn_value, self.fn_value_and_jac = fn_value, fn_value_and_jac
        self.k, self.m, self.name = int(k), int(m), name
        self.count = self.m  # the residuals the m entries stand for (a compressed system: more)
        self.stats = CallStats()
        self.last_error: Exception | None = None
        self.handle = next(_HANDLES)
        self._jax_fn = self._build()

    # -- NumPy side (runs Dr.Jit) ------------------------------------------------------------
    def _fail(self, exc: Exception):
        self.last_error = exc
        raise exc

    def _check_x(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64).reshape(-1)
        if x.shape != (self.k,):
            self._fail(
                ResidualShapeError(
                    f"{self.name}: parameter vector has shape {x.shape}, expected ({self.k},)"
                )
            )
        if not np.all(np.isfinite(x)):
            self._fail(
                NonFiniteParameterError(
                    f"{self.name}: the solver proposed non-finite parameters "
                    f"x={np.array2string(x, precision=6)} (its step diverged)"
                )
            )
        return x

    def _check_r(self, r, x) -> np.ndarray:
        r = np.asarray(r, dtype=np.float64)
        if r.shape != (self.m,):
            self._fail(
                ResidualShapeError(
                    f"{self.name}: residual has shape {r.shape}, expected "
                    f"({self.m},); the residual length must not change "
                    "between calls (fix the pixel mask once)"
                )
            )
        bad = ~np.isfinite(r)
        if bad.any():
            self._fail(
                NonFiniteResidualError(
                    f"{self.name}: {int(bad.sum())} of {self.m} residual entries are non-finite at "
                    f"x={np.array2string(x, precision=6)}; the model produced "
                    "NaN/inf there (check the "
                    "parameter bounds or the model's 'nonfinite' diagnostics)"
                )
            )
        return r

    def _record(self, x, r, kind: str):
        loss = 0.5 * float(r @ r)
        s = self.stats
        s.losses.append(loss)
        s.kinds.append(kind)
        if loss < s.best_loss:
            s.best_loss, s.best_x = loss, x.copy()

    def value(self, x) -> np.ndarray:
        """Residual (m,) float64 at ``x`` (k,)."""
        import time

        x = self._check_x(x)
        t0 = time.perf_counter()
        try:
            r = self.fn_value(x)
        except Exception as exc:  # kept: JAX re-raises callback errors wrapped
            self._fail(exc)
        self.stats.seconds_in_drjit += time.perf_counter() - t0
        self.stats.n_value_calls += 1
        r = self._check_r(r, x)
        self._record(x, r, "v")
        return r

    def value_and_jac(self, x) -> tuple[np.ndarray, np.ndarray]:
        """(residual (m,), Jacobian (m, k)) float64 at ``x`` (k,)."""
        import time

        x = self._check_x(x)
        t0 = time.perf_counter()
        try:
            r, J = self.fn_value_and_jac(x)
        except Exception as exc:
            self._fail(exc)
        self.stats.seconds_in_drjit += time.perf_counter() - t0
        self.stats.n_jac_calls += 1
        r = self._check_r(r, x)
        J = np.asarray(J, dtype=np.float64)
        if J.shape != (self.m, self.k):
            self._fail(
                ResidualShapeError(
                    f"{self.name}: Jacobian has shape {J.shape}, expected ({self.m}, {self.k})"
                )
            )
        bad = ~np.isfinite(J)
        if bad.any():
            cols = sorted(set(np.nonzero(bad)[1].tolist()))
            self._fail(
                NonFiniteResidualError(
                    f"{self.name}: {int(bad.sum())} Jacobian entries are non-finite "
                    f"(columns {cols}) at "
                    f"x={np.array2string(x, precision=6)}; a derivative of the "
                    "model is undefined there"
                )
            )
        self._record(x, r, "j")
        return r, J

    # -- JAX side ------------------------------------------------------------------------------
    def _build(self):
        import jax.numpy as jnp

        _LIVE[self.handle] = self
        return shared_residual(self.k, self.m), jnp.asarray(self.handle, jnp.int64)

    def __call__(self, x):
        """JAX: ``x`` (k,) float64 array -> ``r`` (m,) float64 array (differentiable)."""
        import jax.numpy as jnp

        x = jnp.asarray(x, dtype=jnp.float64)
        if x.shape != (self.k,):
            raise ResidualShapeError(
                f"{self.name}: parameter vector has shape {x.shape}, expected ({self.k},)"
            )
        fn, handle = self._jax_fn
        return fn(handle, x)


# every live residual by its handle: the shared JAX functions below find the residual a call is
# for by the handle it passes as an argument, so that one trace (and one compilation of a solver
# step around it) serves every residual of the same sizes
_LIVE: weakref.WeakValueDictionary = weakref.WeakValueDictionary()
_HANDLES = itertools.count(1)


@functools.lru_cache(maxsize=None)
def shared_residual(k: int, m: int) -> Callable:
    """The JAX function ``(handle int64 scalar, x (k,) float64) -> r (m,) float64`` of every
    :class:`DrJitResidual` with ``k`` parameters and ``m`` residuals: a ``jax.custom_jvp``
    function whose primal calls the residual ``handle`` names through one ``jax.pure_callback``
    and whose JVP rule calls its ``value_and_jac`` through one and returns ``J @ t``. The
    handle is a traced argument, not a constant of the trace: a function jitted around it
    (a solver's step) compiles once for all residuals of these sizes."""
    import jax
    import jax.numpy as jnp

    r_spec = jax.ShapeDtypeStruct((m,), jnp.float64)
    j_spec = jax.ShapeDtypeStruct((m, k), jnp.float64)

    def cb_value(h, x):
        return _LIVE[int(h)].value(x)

    def cb_value_and_jac(h, x):
        return _LIVE[int(h)].value_and_jac(x)

    @jax.custom_jvp
    def residual(h, x):
        return jax.pure_callback(cb_value, r_spec, h, x, vmap_method="sequential")

    @residual.defjvp
    def residual_jvp(primals, tangents):
        (h, x), (_, t) = primals, tangents
        r, J = jax.pure_callback(cb_value_and_jac, (r_spec, j_spec), h, x, vmap_method="sequential")
        return r, J @ t

    return residual


def make_jax_residual(
    fn_value: Callable, fn_value_and_jac: Callable, k: int, m: int, name: str = "residual"
) -> DrJitResidual:
    """Wrap Dr.Jit callables as a JAX-differentiable residual (see the module docstring).

    ``fn_value(x (k,) float64) -> r (m,)``; ``fn_value_and_jac(x) -> (r (m,), J (m, k))``.
    Switches JAX to float64 for the process. Returns a :class:`DrJitResidual`.
    """
    return DrJitResidual(fn_value, fn_value_and_jac, k, m, name=name)
