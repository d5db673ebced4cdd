"""Analytic scene content in NumPy, shared by the Mitsuba reference and the shader inputs.

World units throughout, ``+y`` up, water plane at ``y = 0``. Colours are linear RGB.

* the pool floor height ``y = floor_height(x, z)`` (``study.config.floor``, where the
  experiment's floor keys are checked);
* the waves: one tiling height field ``h0(u, v)`` (a sum of sines with distinct integer
  wave vectors on the unit torus, drawn from [-4, 4]^2, or a larger grid beyond its 40
  directions: :func:`wave_vector_bound`) sampled at four offsets ``wave1..wave4``, exactly as the
  shader samples its normal map four times. The physical surface is
  ``H(x, z) = amplitude / 4 * sum_k h0((x, z) / normal_tile + wave_k)``; the normal map
  stores the normal of ``slope_scale * amplitude * h0``, so the shader's averaged normal
  approximates the normal of ``slope_scale * H`` and the ideal ``BumptexMult`` is
  ``slope_scale`` (the approximation is that four normalised normals are averaged
  instead of four slopes);
* the sky: a zenith-to-horizon gradient, a constant ground below the horizon, and a sun
  disc of given angular radius and radiance.
"""

from __future__ import annotations

import math

import numpy as np

MAX_COMPONENTS = 64


def wave_vector_bound(components: int) -> int:
    """Bound K of the integer wave-vector grid [-K, K]^2 the components are drawn from: 4 (as
    always) while its 40 directions up to sign suffice, else the smallest K whose
    ((2K + 1)^2 - 1) / 2 directions hold ``components`` distinct ones (5 for 41..60, 6 for
    61..84)."""
    k = 4
    while ((2 * k + 1) ** 2 - 1) // 2 < components:
        k += 1
    return k


class Waves:
    """The wave height field of an experiment (see module docstring)."""

    def __init__(
        self,
        amplitude: float,
        normal_tile: float,
        components: int,
        seed: int,
        offsets,
        slope_scale: float = 1.0,
    ):
        rng = np.random.default_rng(seed)
        self.amplitude, self.tile, self.slope_scale = (
            float(amplitude),
            float(normal_tile),
            float(slope_scale),
        )
        self.offsets = np.asarray(offsets, dtype=np.float64).reshape(4, 2)
        if not 1 <= components <= MAX_COMPONENTS:
            raise ValueError(f"waves.components = {components}: expected 1 to {MAX_COMPONENTS}")
        kmax = wave_vector_bound(components)
        k = []
        while len(k) < components:  # ends: the grid holds >= components directions
            kv = rng.integers(-kmax, kmax + 1, size=2)
            if kv.any() and not any((kv == q).all() or (kv == -q).all() for q in k):
                k.append(kv)
        self.k = np.array(k, dtype=np.float64)  # (M, 2) integer wave vectors
        self.phase = rng.uniform(0, 2 * np.pi, size=components)
        a = 1.0 / np.linalg.norm(self.k, axis=1)
        self.a = a / a.sum()  # |h0| <= 1

    def _h0(self, u, v):
        arg = 2 * np.pi * (u[..., None] * self.k[:, 0] + v[..., None] * self.k[:, 1]) + self.phase
        h = (self.a * np.sin(arg)).sum(-1)
        dh = 2 * np.pi * self.a * np.cos(arg)
        return h, (dh * self.k[:, 0]).sum(-1), (dh * self.k[:, 1]).sum(-1)

    def height_and_gradient(self, x, z):
        """Surface height H and its gradient (dH/dx, dH/dz) at world (x, z); arrays of x's shape."""
        x, z = np.asarray(x, np.float64), np.asarray(z, np.float64)
        h = np.zeros_like(x)
        gx = np.zeros_like(x)
        gz = np.zeros_like(x)
        for ou, ov in self.offsets:
            hk, hu, hv = self._h0(x / self.tile + ou, z / self.tile + ov)
            h += hk
            gx += hu / self.tile
            gz += hv / self.tile
        s = self.amplitude / 4.0
        return s * h, s * gx, s * gz

    def normal_map(self, size: int) -> np.ndarray:
        """(size, size, 3) float32 encoded normals (0.5 n + 0.5) of slope_scale * amplitude * h0,
        rows indexed by v (GL order), columns by u."""
        c = (np.arange(size) + 0.5) / size
        u, v = np.meshgrid(c, c)
        _, hu, hv = self._h0(u, v)
        s = self.slope_scale * self.amplitude / self.tile
        n = np.stack([-s * hu, np.ones_like(hu), -s * hv], -1)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        return (0.5 * n + 0.5).astype(np.float32)


def sun_direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """Unit vector towards the sun."""
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    return np.array([math.cos(e) * math.cos(a), math.sin(e), math.cos(e) * math.sin(a)])


def sky_radiance(
    d: np.ndarray,
    zenith,
    horizon,
    ground,
    sun_dir=None,
    sun_radius_deg=0.0,
    sun_radiance=(0.0, 0.0, 0.0),
) -> np.ndarray:
    """Sky radiance (..., 3) in unit directions d (..., 3); the sun disc is included when sun_dir is
    given."""
    d = np.asarray(d, np.float64)
    y = d[..., 1:2]
    t = np.sqrt(np.clip(y, 0, 1))
    sky = np.where(
        y >= 0, (1 - t) * np.asarray(horizon) + t * np.asarray(zenith), np.asarray(ground)
    )
    if sun_dir is not None:
        inside = (d @ np.asarray(sun_dir)) >= math.cos(math.radians(sun_radius_deg))
        sky = sky + inside[..., None] * np.asarray(sun_radiance)
    return sky


def envmap_image(height: int, **sky) -> np.ndarray:
    """(height, 2 * height, 3) float32 lat-long image in Mitsuba's envmap convention:
    u = atan2(x, -z) / 2pi, v = acos(y) / pi, row 0 at the zenith."""
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(2 * height) + 0.5) / (2 * height)
    th, ph = np.meshgrid(v * np.pi, u * 2 * np.pi, indexing="ij")
    d = np.stack([np.sin(th) * np.sin(ph), np.cos(th), -np.sin(th) * np.cos(ph)], -1)
    return sky_radiance(d, **sky).astype(np.float32)


# GL cube-map faces +X, -X, +Y, -Y, +Z, -Z: direction for face coordinates (sc, tc) in [-1, 1]
_CUBE_FACES = (
    lambda s, t: (np.ones_like(s), -t, -s),
    lambda s, t: (-np.ones_like(s), -t, s),
    lambda s, t: (s, np.ones_like(s), t),
    lambda s, t: (s, -np.ones_like(s), -t),
    lambda s, t: (s, -t, np.ones_like(s)),
    lambda s, t: (-s, -t, -np.ones_like(s)),
)


def cubemap_directions(size: int) -> np.ndarray:
    """(6, size, size, 3) unit directions of the texel centres of a GL cube map
    (row index = t, column index = s)."""
    c = 2 * (np.arange(size) + 0.5) / size - 1
    s, t = np.meshgrid(c, c)
    out = np.stack([np.stack(f(s, t), -1) for f in _CUBE_FACES])
    return out / np.linalg.norm(out, axis=-1, keepdims=True)
