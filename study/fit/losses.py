"""Which error the fit minimises (``fit.loss``): one registry of residual transforms.

The fit minimises ``0.5*||r||^2`` over a residual ``r``; each loss wraps a
:class:`~study.fit.protocol.ImageModel` so that its ``r`` is:

* ``linear``: the model's own, ``port - reference`` per water pixel and RGB channel (linear
  RGB): the squared error. Glints dominate it, and a glint a pixel off costs twice a glint
  removed, so it prefers a blur to sharp glints slightly misplaced.
* ``log``: ``f(port) - f(reference)``, ``f(x) = log(max(x, 0) + LOG_EPS)`` (``LOG_EPS = 0.02``,
  linear RGB): a relative error above ~0.02; ``J_f = f'(port) J``.
* ``flip``: ``sqrt(FLIP_p + FLIP_DELTA)`` per water pixel ``p``, with ``FLIP_p`` the LDR-FLIP
  map (``study.fit.flip_jax``, the algorithm of ``flip-evaluator`` that the study reports) of
  the port's image, the reference's outside the water, against the reference; so ``0.5*||r||^2``
  is half the sum of the map over the water pixels plus a constant, and the minimum is the
  minimum of the mean FLIP the report gives at the fit's resolution. The Jacobian is
  ``dFLIP/d image`` (JAX forward mode, one pass per column) applied to the model's ``J``,
  divided by ``2 r``. FLIP compares tone-free, perceptually encoded, CSF-filtered colour and
  edge/point features, so a sharp glint near its place beats a blur.

Every wrapper is a :class:`~study.fit.protocol.CalibrationModel` (the model's parameters,
ranges, start constants and renders). ``reference_stderr`` is carried through ``log`` to first
order; ``flip`` has none (its residual mixes a neighbourhood of pixels), so the basin scan's
noise test, which needs it, does not run under ``flip``. Only ``linear`` has ``loss_ad``
(Adam's reverse mode); the others are refused by Adam with one line.
"""

from __future__ import annotations

import numpy as np

LOG_EPS = 0.02
#: added to the FLIP map before its square root, so that a pixel with no error has a finite
#: derivative (the minimiser is unchanged: a constant per pixel)
FLIP_DELTA = 1e-4

_PASSED = ("label", "defines", "parameter_names", "bounds", "start_constants", "render",
           "reference", "inputs", "variant", "user_shader", "n_renders", "n_jacobians",
           "resolution", "texture_size", "shader", "mask")  # fmt: skip


class _Wrapped:
    """A loss over ``model``: the model's parameters, ranges and renders pass through."""

    loss_name = ""

    def __init__(self, model):
        self.base = model

    def __getattr__(self, name):
        if name in _PASSED:
            return getattr(self.base, name)
        raise AttributeError(name)

    def loss_ad(self, constants):
        raise NotImplementedError(
            f"fit.loss = {self.loss_name!r} has no reverse-mode loss for Adam; use a least-squares "
            'solver (fit.solver = "levenberg_marquardt") or fit.loss = "linear"'
        )


class Linear:
    """The model itself: ``port - reference`` (linear RGB)."""

    loss_name = "linear"

    def __init__(self, model):
        self.base = model

    def __getattr__(self, name):
        return getattr(self.base, name)


class LogResidual(_Wrapped):
    """``model`` seen through ``f(x) = log(max(x, 0) + eps)`` (see the module docstring)."""

    loss_name = "log"

    def __init__(self, model, eps: float = LOG_EPS):
        super().__init__(model)
        self.eps = float(eps)
        self._ref = model.reference[model.mask].astype(np.float64).ravel()
        # the reference's standard error carried through f to first order,
        # sigma / (max(ref, 0) + eps)
        se = getattr(model, "reference_stderr", None)
        self.reference_stderr = (
            None
            if se is None
            else (se / (np.maximum(model.reference, 0.0) + self.eps)).astype(np.float32)
        )

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


class FlipResidual(_Wrapped):
    """``sqrt(FLIP map + FLIP_DELTA)`` over the water pixels (see the module docstring)."""

    loss_name = "flip"
    reference_stderr = None

    def __init__(self, model):
        from .jax_residual import enable_x64

        super().__init__(model)
        enable_x64()
        self._image = np.asarray(model.reference, np.float64)
        self._ref = self._image[model.mask].ravel()

    def _composite(self, port: np.ndarray) -> np.ndarray:
        """(H, W, 3): the reference with its water pixels replaced by ``port`` (3n,)."""
        img = self._image.copy()
        img[self.base.mask] = port.reshape(-1, 3)
        return img

    def residual(self, constants) -> np.ndarray:
        from .flip_jax import flip_map

        port = self.base.residual(constants) + self._ref
        fmap = np.asarray(flip_map(self._image, self._composite(port)))
        return np.sqrt(fmap[self.base.mask] + FLIP_DELTA)

    def residual_and_jacobian(self, constants, names):
        import jax

        from .flip_jax import flip_map

        r_lin, J = self.base.residual_and_jacobian(constants, names)
        mask = self.base.mask
        fmap, lin = jax.linearize(
            lambda img: flip_map(self._image, img), self._composite(r_lin + self._ref)
        )
        tangents = np.zeros((J.shape[1], *self._image.shape))
        tangents[:, mask] = J.T.reshape(J.shape[1], -1, 3)
        dmap = np.asarray(jax.vmap(lin)(tangents))[:, mask].T  # (n, k)
        r = np.sqrt(np.asarray(fmap)[mask] + FLIP_DELTA)
        return r, dmap / (2.0 * r[:, None])


LOSSES = {cls.loss_name: cls for cls in (Linear, LogResidual, FlipResidual)}


def transformed(model, loss: str = "linear"):
    """``model`` with the residual of ``loss`` (a key of :data:`LOSSES`); ValueError naming
    the choices for any other."""
    if loss not in LOSSES:
        raise ValueError(f"unknown fit.loss {loss!r}; choose one of {', '.join(LOSSES)}")
    return LOSSES[loss](model)
