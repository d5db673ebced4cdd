"""Whether the camera sees the water: a check before anything is rendered.

The shader draws the flat water rectangle (``pool.half_extent``) at ``y = 0`` and shades
the pixels whose centres it covers; with none, there is nothing to compare or fit. This
casts the camera ray of every pixel centre at the experiment's and the fit's resolutions
onto the plane (NumPy, exact for the flat quad the shader rasterises).
"""

from __future__ import annotations

import numpy as np

from ..config.errors import ExperimentError
from ..config.experiment import Experiment
from .mitsuba_scene import camera_view_proj


def water_pixel_count(exp: Experiment, width: int, height: int) -> int:
    """Pixel centres of a (width, height) image whose camera ray meets the water rectangle."""
    inv = np.linalg.inv(camera_view_proj(exp, width, height).astype(np.float64))
    j, i = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    x = (i.ravel() + 0.5) / width * 2 - 1
    y = 1 - (j.ravel() + 0.5) / height * 2  # row 0 at the top
    one = np.ones_like(x)

    def unproject(zn):
        p = inv @ np.stack([x, y, zn * one, one])
        return (p[:3] / p[3]).T

    near, far = unproject(-1.0), unproject(1.0)
    d = far - near
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -near[:, 1] / d[:, 1]
        p = near + t[:, None] * d
    hx, hz = exp.pool.half_extent
    hit = (t > 0) & np.isfinite(t) & (np.abs(p[:, 0]) <= hx) & (np.abs(p[:, 2]) <= hz)
    return int(hit.sum())


def check_water_in_view(exp: Experiment) -> None:
    """Raise ExperimentError naming the keys when the water covers no pixel centre at the
    experiment's resolution or at the fit's."""
    for key in ("resolution", "fit.resolution"):
        w, h = exp[key]
        if water_pixel_count(exp, w, h) == 0:
            raise ExperimentError(
                f"no water in view at {key} = [{w}, {h}]: the water rectangle (pool.half_extent = "
                f"{exp.pool.half_extent}) covers no pixel centre of the "
                "camera (camera.position, "
                "camera.target, camera.fov_y); aim the camera at the water or enlarge it"
            )
