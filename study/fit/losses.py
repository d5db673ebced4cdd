"""Which residual the fit minimises: linear RGB (the default) or a perceptual alternative.

The fit minimises ``0.5*||r||^2``; the report judges FLIP, which compares tone-mapped,
perceptually encoded images, so bright glints dominate a linear-RGB residual far more than
they dominate FLIP. :func:`transformed` wraps a :class:`~study.fit.model.ShaderModel` so that
its residual is ``f(port) - f(reference)`` per water pixel and channel:

* ``linear``: ``f(x) = x`` (the model itself);
* ``log``: ``f(x) = log(max(x, 0) + LOG_EPS)`` with ``LOG_EPS = 0.02`` (linear RGB): a relative
  error above ~0.02, which compresses glints and weighs dark water as the eye does; the
  Jacobian by the chain rule, ``J_f = f'(port) J``.

The wrapper is a :class:`~study.fit.protocol.CalibrationModel` (the model's parameters, ranges,
start constants and renders; ``reference_stderr`` carried through ``f`` to first order);
``loss_ad`` (Adam's reverse mode) exists only for ``linear``.
"""

from __future__ import annotations

import numpy as np

LOSSES = ("linear", "log")
LOG_EPS = 0.02


class LogResidualModel:
    """``model`` seen through ``f(x) = log(max(x, 0) + eps)`` (see the module docstring)."""

    def __init__(self, model, eps: float = LOG_EPS):
        self.base, self.eps = model, float(eps)
        self.shader, self.mask = model.shader, model.mask
        self._ref = model.reference[model.mask].astype(np.float64).ravel()
        # the reference's standard error carried through f to first order,
        # sigma / (max(ref, 0) + eps)
        se = getattr(model, "reference_stderr", None)
        self.reference_stderr = (
            None
            if se is None
            else (se / (np.maximum(model.reference, 0.0) + self.eps)).astype(np.float32)
        )

    def __getattr__(self, name):
        # the parameters, ranges, start constants, label and renders are the model's own
        if name in ("label", "defines", "parameter_names", "bounds", "start_constants",
                    "render", "reference", "inputs", "variant", "user_shader"):  # fmt: skip
            return getattr(self.base, name)
        raise AttributeError(name)

    def _f(self, x):
        return np.log(np.maximum(x, 0.0) + self.eps)

    def residual(self, constants) -> np.ndarray:
        port = self.base.residual(constants) + self._ref
        return self._f(port) - self._f(self._ref)

    def residual_and_jacobian(self, constants, names):
        r, J = self.base.residual_and_jacobian(constants, names)
        port = r + self._ref
        d = np.where(port > 0, 1.0 / (np.maximum(port, 0.0) + self.eps), 0.0)
        return self._f(port) - self._f(self._ref), d[:, None] * J

    def loss_ad(self, constants):
        raise NotImplementedError(
            "the log residual has no reverse-mode loss; fit it with a "
            "least-squares solver, not Adam"
        )


class _Linear:
    """The model itself, with ``base`` for a uniform interface."""

    def __init__(self, model):
        self.base = model

    def __getattr__(self, name):
        return getattr(self.base, name)


def transformed(model, loss: str = "linear"):
    """``model`` with residual ``loss`` (one of :data:`LOSSES`)."""
    if loss == "linear":
        return _Linear(model)
    if loss == "log":
        return LogResidualModel(model)
    raise ValueError(f"unknown loss {loss!r}; choose one of {LOSSES}")
