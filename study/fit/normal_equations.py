"""A least-squares fit's normal equations, formed where the shader runs.

A Gauss-Newton or Levenberg-Marquardt step, the gradient and the loss read the residual ``r``
(M,) and its Jacobian ``J`` (M, k) only through ``A = J^T J`` (k, k), ``g = J^T r`` (k,) and
``rr = r^T r``. M is three times the water pixels (about 6 million at 1920x1080), k the fitted
constants (7-30). :class:`NormalEquations` holds these; :func:`from_residual` forms them on the
host from ``(r, J)``; :class:`LaneReduction` forms them in Dr.Jit from the shader's lanes (the
ports' ``lanes`` hook, ``shaders_port.pipeline.frame.jacobian_passes``), so neither the image
nor the Jacobian is read back: on a GPU the host receives (k + 1)^2 numbers per evaluation in
place of 4 M (k + 1) bytes, and the solver works on k + 1 rows in place of M.

:meth:`NormalEquations.compressed` is the system the solver then sees: ``r~`` (k + 1,) and
``J~`` (k + 1, k) with ``J~^T J~ = A``, ``J~^T r~ = g`` and ``|r~|^2 = rr`` exactly (``A = V W
V^T``; ``J~ = [W^1/2 V^T; 0]``, ``r~ = [W^-1/2 V^T g; sqrt(rr - |W^-1/2 V^T g|^2)]``,
eigenvalues below ``1e-14`` of the largest dropped: ``g`` has no part along them; where the
rounding of an ill-conditioned ``A`` puts ``|W^-1/2 V^T g|^2`` above ``rr``, that part is scaled
onto ``rr``, so the loss stays exact and ``g`` holds to that rounding). Every solver
here reads a least-squares problem through those three quantities, so its steps are the steps on
the full residual up to rounding (``tests/test_normal_equations.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import numpy as np

# eigenvalues of A below this fraction of the largest are taken as 0 (a constant no scored pixel
# depends on: its column of J is 0)
RANK_RTOL = 1e-14


@dataclass(frozen=True)
class NormalEquations:
    """``A`` (k, k) float64 = J^T J, ``g`` (k,) float64 = J^T r, ``rr`` = r^T r, ``m`` the
    residuals they stand for, ``nonfinite`` the scored pixels whose colour was NaN or infinite
    (0 where formed from a finite residual)."""

    A: np.ndarray
    g: np.ndarray
    rr: float
    m: int
    nonfinite: int = 0

    @property
    def loss(self) -> float:
        """``0.5 * r^T r``, the solvers' loss."""
        return 0.5 * self.rr

    def scaled(self, d) -> "NormalEquations":
        """The equations of ``J D`` (``D = diag(d)``, d (k,)): a change of variables."""
        d = np.asarray(d, np.float64)
        return NormalEquations(self.A * d[:, None] * d[None, :], self.g * d, self.rr, self.m,
                               self.nonfinite)  # fmt: skip

    def __add__(self, other: "NormalEquations") -> "NormalEquations":
        """The equations of the two residuals stacked."""
        return NormalEquations(self.A + other.A, self.g + other.g, self.rr + other.rr,
                               self.m + other.m, self.nonfinite + other.nonfinite)  # fmt: skip

    def weighted(self, w: float) -> "NormalEquations":
        """The equations of ``w r`` (and ``w J``)."""
        w2 = float(w) ** 2
        return NormalEquations(self.A * w2, self.g * w2, self.rr * w2, self.m, self.nonfinite)

    def compressed(self) -> tuple[np.ndarray, np.ndarray]:
        """``(r~ (k + 1,), J~ (k + 1, k))`` float64, the system of k + 1 rows with these normal
        equations and this loss (module docstring)."""
        k = len(self.g)
        w, V = np.linalg.eigh(0.5 * (self.A + self.A.T))
        keep = w > RANK_RTOL * max(float(w.max(initial=0.0)), 0.0)
        J = np.zeros((k + 1, k))
        r = np.zeros(k + 1)
        root = np.sqrt(w[keep])
        J[: keep.sum()] = root[:, None] * V[:, keep].T
        z = (V[:, keep].T @ self.g) / root
        zz = float(z @ z)
        if zz > self.rr > 0.0:
            # |z|^2 = g^T A^+ g <= rr exactly; above it only by the rounding of an
            # ill-conditioned A (relative eps * cond(A)): z scaled onto rr keeps the loss exact,
            # moving J~^T r~ off g by that same relative rounding
            z *= np.sqrt(self.rr / zz)
        r[: keep.sum()] = z
        r[k] = np.sqrt(max(self.rr - float(z @ z), 0.0))
        return r, J


def forms_normal_equations(model) -> bool:
    """Whether ``model`` (or each scene of a joint model) forms its normal equations where it
    shades: a model of ``fit.loss = "linear"``; a loss that transforms each residual on the
    host does not."""
    return all(hasattr(m, "normal_equations") for m in getattr(model, "models", [model]))


def from_residual(r, J) -> NormalEquations:
    """The normal equations of ``r`` (M,) and ``J`` (M, k), formed on the host in float64."""
    r = np.asarray(r, np.float64).reshape(-1)
    J = np.asarray(J, np.float64)
    return NormalEquations(J.T @ J, J.T @ r, float(r @ r), len(r))


class LaneReduction:
    """Forms a model's :class:`NormalEquations` from the shader's lanes in Dr.Jit.

    ``mask``: (H, W) bool, the scored fit pixels; ``reference``: (H, W, 3) float32 linear RGB;
    ``supersample`` s: the lanes are pixels of the (s H, s W) shading grid, a fit pixel the
    mean of its s x s samples (``study.fit.model.ReferenceModel.fold``). Called as the ports'
    ``lanes`` hook: ``(m, raster, colour, nonfinite, grads) -> NormalEquations``. The residual
    (fold - reference) and each column of J are scattered into one float64 (3 P, k + 1) tensor
    of the P scored pixels, whose Gram matrix (``dr.matmul``) holds A, g and rr; it and the
    count of non-finite scored lanes are all that is read back. With s > 1 the scatter adds the
    samples of a pixel in no fixed order (the sums agree to rounding from run to run)."""

    def __init__(self, mask: np.ndarray, reference: np.ndarray, supersample: int = 1):
        self.mask = np.asarray(mask, bool)
        self.reference = np.asarray(reference, np.float32)
        self.s = int(supersample)
        self._index = None  # the raster's lane index the device arrays below were built for
        self._device = None

    def _lanes_of(self, m, raster):
        """Device arrays for the lanes of ``raster``: (scored pixel of each lane UInt32, lane in
        a scored pixel Bool, reference of the scored pixels per channel Float64, P)."""
        index = np.asarray(raster.index)
        if self._index is not None and (self._index is index or np.array_equal(self._index, index)):
            return self._device
        h, w = self.mask.shape
        s = self.s
        if (raster.width, raster.height) != (w * s, h * s):
            raise ValueError(
                f"the lanes are of a {raster.width}x{raster.height} frame; the fit's pixels are "
                f"{w}x{h} with {s}x{s} samples each"
            )
        y, x = np.divmod(index, raster.width)
        pixel = (y // s) * w + x // s
        flat = self.mask.ravel()
        rank = np.cumsum(flat) - 1
        scored = flat[pixel]
        P = int(flat.sum())
        ref = self.reference.reshape(-1, 3)[flat].astype(np.float64)
        self._device = (
            m.UInt32(np.where(scored, rank[pixel], 0).astype(np.uint32)),
            m.Bool(scored),
            [m.Float64(ref[:, c]) for c in range(3)],
            P,
        )
        self._index = index
        return self._device

    def __call__(self, m, raster, colour, nonfinite, grads) -> NormalEquations:
        if dr.width(colour) != len(raster.index):
            raise ValueError(
                f"{dr.width(colour)} lanes for {len(raster.index)} covered pixels: the shader's "
                "helper lanes must be dropped before the normal equations"
            )
        pixel, scored, ref, P = self._lanes_of(m, raster)
        k = len(grads)
        K = k + 1
        table = dr.zeros(m.Float64, 3 * P * K)
        inv = 1.0 / (self.s * self.s)
        every = dr.arange(m.UInt32, P)
        for c in range(3):
            row = (c * P + pixel) * K
            for j, g in enumerate(grads):
                dr.scatter_reduce(dr.ReduceOp.Add, table, m.Float64(g[c]) * inv, row + j, scored)
            dr.scatter_reduce(dr.ReduceOp.Add, table, m.Float64(colour[c]) * inv, row + k, scored)
            dr.scatter_reduce(dr.ReduceOp.Add, table, -ref[c], (c * P + every) * K + k)
        T = m.TensorXf64(table, shape=(3 * P, K))
        gram = dr.matmul(T, T, At=True)
        bad = dr.sum(m.Float64(dr.select(nonfinite & scored, 1.0, 0.0)))
        dr.eval(gram, bad)
        G = np.asarray(gram.numpy(), np.float64).reshape(K, K)
        return NormalEquations(G[:k, :k].copy(), G[:k, k].copy(), float(G[k, k]), 3 * P,
                               int(round(float(bad[0]))))  # fmt: skip
