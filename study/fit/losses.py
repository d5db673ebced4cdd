"""Which error the fit minimises (``fit.loss``): one registry of residual transforms.

The fit minimises ``0.5*||r||^2`` over a residual ``r``; each loss wraps a
:class:`~study.fit.protocol.ImageModel` so that its ``r`` is:

* ``linear``: the model's own, ``port - reference`` per water pixel and RGB channel (linear
  RGB): the squared error. Glints dominate it, and a glint a pixel off costs twice a glint
  removed, so it prefers a blur to sharp glints slightly misplaced.
* ``log``: ``f(port) - f(reference)``, ``f(x) = log(max(x, 0) + LOG_EPS)`` (``LOG_EPS = 0.02
#: a loss fitted from the solution of another (the first stage of its fit)
STARTS_FROM = {"flip": "linear"}``,
  linear RGB): a relative error above ~0.02; ``J_f = f'(port) J``.
* ``flip``: per water pixel ``p``, ``sqrt(FLIP_p) d_p / |d_p|`` (``flip_jax.flip_residual``),
  ``FLIP_p`` the LDR-FLIP map (``study.fit.flip_jax``: the algorithm of ``flip-evaluator`` that
  the report gives) of the port's image (the reference's outside the water) against the
  reference, ``d_p`` the pixel's difference in FLIP's Hunt-adjusted CIELab. So ``0.5*||r||^2``
  is half the sum of the map over the water pixels: the fit minimises the mean FLIP. Two
  choices make it a fit's loss rather than the metric: the map is seen at :func:`fit_ppd`
  (a fit pixel covers the visual angle of the scored pixels it stands for), and below a HyAB
  distance of ``FLIP_KNEE`` (about a just noticeable difference) the colour term is quadratic
  (``flip_map(knee=...)``), so the loss has no cusp where an error crosses zero and
  Levenberg-Marquardt converges. The Jacobian is JAX's forward mode of the residual in the
  image (one pass per column) applied to the model's ``J``. FLIP compares CSF-filtered colour
  and edge and point features, so a sharp glint near its place costs less than a blur.
* ``transport``: ``linear``'s residual times ``sqrt(TRANSPORT_LINEAR_SHARE)`` (1/4) stacked on
  the matched values times ``sqrt(1 - TRANSPORT_LINEAR_SHARE)``: in each ``TILE`` x ``TILE``
  tile of the fit image (8 x 8, ``residual_tiles``) and each channel, the port's water values
  in increasing order minus the reference's in increasing order, the one-dimensional optimal
  transport between the tile's two histograms (the assignment of the port's values to the
  reference's that minimises the squared error). So ``0.5*||r||^2`` is never above
  ``linear``'s; a glint moved within its tile costs a quarter of ``linear``'s charge (half a
  glint removed), a glint removed, dimmed or widened costs its values, and the tiles and the
  linear share keep where on the image each value is. The matched part's Jacobian is the
  model's ``J`` with its rows in the same order (the order is constant between ties).

``flip`` is fitted from the squared error's solution (:data:`STARTS_FROM`,
``study.calibration.fitting.fit_frames``): from the shader's start constants FLIP's
colour term, which flattens where colours differ much, stalls or drives the water's colour to
a bound on three of the six shipped experiments (docs/user-shader.md), while from the squared
error's solution it lowers FLIP on every one.

Every wrapper is a :class:`~study.fit.protocol.CalibrationModel` (the model's parameters,
ranges, start constants and renders). ``reference_stderr`` is carried through ``log`` to first
order; ``flip`` and ``transport`` have none (a residual mixes a neighbourhood of pixels), so
under them the basin scan reports other minima without a noise test and never restarts from
one. Only
``linear`` has ``loss_ad`` (Adam's reverse mode); the others are refused by Adam in one line.
"""

from __future__ import annotations

import numpy as np

from .flip_jax import PPD, flip_residual
from .jax_residual import enable_x64
from .model import TILE

LOG_EPS = 0.02
#: a loss fitted from the solution of another (the first stage of its fit)
STARTS_FROM = {"flip": "linear"}
#: HyAB distance below which the fit's FLIP is quadratic (``study.fit.flip_jax.flip_map``)
FLIP_KNEE = 1.0
#: the squared error's share of the transport loss: a glint moved within its tile costs this
#: share of what the squared error charges, a glint removed the whole of it
TRANSPORT_LINEAR_SHARE = 0.25

_PASSED = ("label", "defines", "parameter_names", "bounds", "start_constants", "render",
           "reference", "inputs", "variant", "user_shader", "n_renders", "n_jacobians",
           "resolution", "texture_size", "shader", "mask", "residual_tiles")  # fmt: skip


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
    """The FLIP residual over the water pixels (see the module docstring)."""

    loss_name = "flip"
    reference_stderr = None

    def __init__(self, model, ppd: float | None = None):
        super().__init__(model)
        enable_x64()
        self.ppd = PPD if ppd is None else float(ppd)
        self._image = np.asarray(model.reference, np.float64)
        self._ref = self._image[model.mask].ravel()

    def _composite(self, port: np.ndarray) -> np.ndarray:
        """(H, W, 3): the reference with its water pixels replaced by ``port`` (3n,)."""
        img = self._image.copy()
        img[self.base.mask] = port.reshape(-1, 3)
        return img

    def _of(self, img):
        return flip_residual(self._image, img, self.ppd, FLIP_KNEE)

    def residual(self, constants) -> np.ndarray:
        port = self.base.residual(constants) + self._ref
        return np.asarray(self._of(self._composite(port)))[self.base.mask].ravel()

    def residual_and_jacobian(self, constants, names):
        import jax

        r_lin, J = self.base.residual_and_jacobian(constants, names)
        mask, k = self.base.mask, J.shape[1]
        r, lin = jax.linearize(self._of, self._composite(r_lin + self._ref))
        tangents = np.zeros((k, *self._image.shape))
        tangents[:, mask] = J.T.reshape(k, -1, 3)
        dr = np.asarray(jax.vmap(lin)(tangents))[:, mask].reshape(k, -1).T  # (3n, k)
        return np.asarray(r)[mask].ravel(), dr


class TransportResidual(_Wrapped):
    """The squared error's residual weighted by ``sqrt(share)`` above the port's water values
    matched to the reference's within tiles, weighted by ``sqrt(1 - share)`` (see the module
    docstring); ``size``: the tile's side in fit pixels."""

    loss_name = "transport"
    reference_stderr = None

    def __init__(self, model, size: int = TILE, share: float = TRANSPORT_LINEAR_SHARE):
        super().__init__(model)
        self.size = int(size)
        self._w = np.sqrt([share, 1.0 - share])
        self._tiles = np.asarray(model.residual_tiles(self.size))
        self._group = self._tiles * 3 + np.tile(np.arange(3), len(self._tiles) // 3)
        self._ref = model.reference[model.mask].astype(np.float64).ravel()
        self._ref_sorted = self._ref[np.lexsort((self._ref, self._group))]

    def _matched(self, r: np.ndarray):
        """(the stacked residual, the order of the matched part's rows) of the model's ``r``."""
        port = r + self._ref
        order = np.lexsort((port, self._group))  # by (tile, channel), then by value
        return np.concatenate(
            [self._w[0] * r, self._w[1] * (port[order] - self._ref_sorted)]
        ), order

    def residual(self, constants) -> np.ndarray:
        return self._matched(self.base.residual(constants))[0]

    def residual_and_jacobian(self, constants, names):
        r, J = self.base.residual_and_jacobian(constants, names)
        stacked, order = self._matched(r)
        return stacked, np.concatenate([self._w[0] * J, self._w[1] * J[order]])

    def residual_tiles(self, size: int = TILE) -> np.ndarray:
        """(6n,) int: each entry's tile of ``self.size`` fit pixels (a matched value's is the
        tile it is matched in, whatever ``size``)."""
        return np.concatenate([self._tiles, np.sort(self._group) // 3])


LOSSES = {cls.loss_name: cls for cls in (Linear, LogResidual, FlipResidual, TransportResidual)}


def transformed(model, loss: str = "linear", ppd: float | None = None):
    """``model`` with the residual of ``loss`` (a key of :data:`LOSSES`); ValueError naming
    the choices for any other. ``ppd``: the pixels per degree at which ``flip`` sees the
    model's image (None: ``flip-evaluator``'s default; see :func:`fit_ppd`)."""
    if loss not in LOSSES:
        raise ValueError(f"unknown fit.loss {loss!r}; choose one of {', '.join(LOSSES)}")
    return FlipResidual(model, ppd) if loss == "flip" else LOSSES[loss](model)


def fit_ppd(fit_width: int, scored_width: int) -> float:
    """The pixels per degree at which a fit image ``fit_width`` pixels wide shows the scene as
    the scored image, ``scored_width`` wide, is seen at ``flip-evaluator``'s default: each fit
    pixel covers ``scored_width / fit_width`` scored pixels, so the FLIP the fit minimises
    filters the same visual angle as the FLIP the report gives."""
    return PPD * fit_width / scored_width
