"""The pool floor the experiment's ``floor.*`` keys describe: its height ``y = floor_height(x,
z)`` in world units (``+y`` up, water plane at ``y = 0``), for the scene and for the checks of
an experiment (a ledge must clear the floor under it)."""

from __future__ import annotations

import numpy as np

__all__ = ["floor_height"]


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
