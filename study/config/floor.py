"""The pool floor the experiment's ``floor.*`` keys describe, for the scene and for the checks of
an experiment (a ledge must clear the floor under it): the height of a built-in floor shape
(``floor_height``) or of the user's heightmap (``heightmap_floor``) in world units (``+y`` up,
water plane at ``y = 0``), and the user's albedo image over the pool (``albedo_over_pool``)."""

from __future__ import annotations

import numpy as np

from .files import albedo_image, floor_extent, heightmap
from .image_maths import sample_rect

__all__ = ["albedo_over_pool", "floor_height", "heightmap_floor"]


def floor_height(
    shape: str, depth: float, relief: float, steps: int, seed: int, half_extent, x, z
) -> np.ndarray:
    """World y of the pool floor at (x, z); mean depth ``depth`` below the water plane."""
    x, z = np.asarray(x, np.float64), np.asarray(z, np.float64)
    hx, hz = half_extent
    if shape == "flat":
        return np.full_like(x, -depth)
    if shape == "slope":
        return -depth + 0.5 * relief * np.clip(x / hx, -1, 1)
    if shape == "steps":
        t = np.clip((x + hx) / (2 * hx), 0, 1 - 1e-9)
        k = np.floor(t * steps)
        return -depth + relief * (k / max(steps - 1, 1) - 0.5)
    if shape == "terrain":
        rng = np.random.default_rng(seed)
        y = np.zeros_like(x)
        for _ in range(6):
            kx, kz = rng.uniform(0.3, 1.2, 2) * rng.choice([-1, 1], 2)
            y += np.sin(kx * x + kz * z + rng.uniform(0, 2 * np.pi)) / 6
        return -depth + 0.5 * relief * y
    raise ValueError(f"unknown floor shape {shape!r}")


def heightmap_floor(values: dict, x, z) -> np.ndarray:
    """World y of a heightmap floor at (x, z)."""
    hm = heightmap(values)[..., None]
    return (
        -values["floor.depth"]
        + values["floor.height_scale"] * sample_rect(hm, floor_extent(values), x, z)[..., 0]
    )


def albedo_over_pool(values: dict, max_size: int = 2048) -> np.ndarray:
    """(N, M, 3) float32 floor albedo over the pool rectangle (row = z, column = x), resampled
    from ``floor.albedo_image`` at (at most) its own texel density."""
    img = albedo_image(values)
    x0, z0, x1, z1 = floor_extent(values)
    hx, hz = values["pool.half_extent"]
    nx = int(np.clip(round(img.shape[1] * 2 * hx / (x1 - x0)), 8, max_size))
    nz = int(np.clip(round(img.shape[0] * 2 * hz / (z1 - z0)), 8, max_size))
    x = -hx + (np.arange(nx) + 0.5) / nx * 2 * hx
    z = -hz + (np.arange(nz) + 0.5) / nz * 2 * hz
    X, Z = np.meshgrid(x, z)
    return sample_rect(img, (x0, z0, x1, z1), X, Z).astype(np.float32)
