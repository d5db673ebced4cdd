"""Maths on the images a scene reads: lat-long sky maps and images laid over a world rectangle.

* Lat-long maps (H, 2H, C), in Mitsuba's ``envmap`` convention (u = atan2(x, -z) / 2pi,
  v = acos(y) / pi, row 0 at the zenith): the directions and solid angles of their texels,
  a bilinear lookup by direction, a turn about +y, the sun (the brightest region) and the
  sky with that region filled in.
* An image (H, W, C) over the world rectangle ``(x0, z0, x1, z1)`` (columns along x, rows
  along z, texel centres at the cell centres): a bilinear lookup at world (x, z), clamped.
* sRGB-encoded texels decoded to linear.

NumPy arrays in, arrays out: reading the files and checking them is ``files``'s.
"""

from __future__ import annotations

import math

import numpy as np

SUN_THRESHOLD = 0.1  # the sun region: texels brighter than this fraction of the brightest one
SUN_CONTRAST = 20.0  # ... whose brightest texel is this many times the median, or no sun


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """Linear values of sRGB-encoded ones in [0, 1] (the sRGB transfer function inverted)."""
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def turn_latlong(img: np.ndarray, degrees: float) -> np.ndarray:
    """A lat-long map (H, W, C) turned about +y by ``degrees`` (from +x towards +z):
    u -> u + degrees / 360, interpolated linearly along u, which wraps."""
    w = img.shape[1]
    shift = (degrees / 360.0) * w
    src = (np.arange(w) - shift) % w
    i0 = np.floor(src).astype(int)
    f = (src - i0)[None, :, None]
    return (1 - f) * img[:, i0] + f * img[:, (i0 + 1) % w]


def latlong_directions(h: int) -> tuple[np.ndarray, np.ndarray]:
    """(h, 2h, 3) unit directions of the texel centres of a lat-long map (Mitsuba's envmap
    convention) and (h, 2h) their solid angles (steradians)."""
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(2 * h) + 0.5) / (2 * h)
    th, ph = np.meshgrid(v * np.pi, u * 2 * np.pi, indexing="ij")
    d = np.stack([np.sin(th) * np.sin(ph), np.cos(th), -np.sin(th) * np.cos(ph)], -1)
    edges = np.arange(h + 1) / h * np.pi
    band = (np.cos(edges[:-1]) - np.cos(edges[1:])) * (2 * np.pi / (2 * h))
    return d, np.repeat(band[:, None], 2 * h, 1)


def latlong_lookup(img: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Bilinear lookup of a lat-long image (H, 2H, C) in unit directions d (..., 3)."""
    h, w = img.shape[:2]
    u = (np.arctan2(d[..., 0], -d[..., 2]) / (2 * np.pi)) % 1.0
    v = np.arccos(np.clip(d[..., 1], -1, 1)) / np.pi
    x, y = u * w - 0.5, np.clip(v * h - 0.5, 0, h - 1)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    y1 = np.minimum(y0 + 1, h - 1)
    x0w, x1w = x0 % w, (x0 + 1) % w
    return (1 - fy) * ((1 - fx) * img[y0, x0w] + fx * img[y0, x1w]) + fy * (
        (1 - fx) * img[y1, x0w] + fx * img[y1, x1w]
    )


def find_sun(img: np.ndarray) -> dict:
    """The brightest region of a lat-long radiance map (H, 2H, 3): the texels brighter than
    ``SUN_THRESHOLD`` x the brightest one and connected to it (wrapping in u). Returns
    ``direction`` (3,) (radiance-weighted mean), ``solid_angle`` (sr), ``radiance`` (3,)
    (mean over the region, linear RGB), ``radius_deg`` (of the disc of that solid angle),
    ``mask`` (H, 2H) bool. Raises ValueError when no texel stands out (the brightest is less
    than ``SUN_CONTRAST`` x the median)."""
    from scipy import ndimage

    h, w = img.shape[:2]
    lum = img @ np.array([0.2126, 0.7152, 0.0722])
    peak = float(lum.max())
    med = float(np.median(lum))
    if peak <= 0 or peak < SUN_CONTRAST * med:
        raise ValueError(
            f"no sun in the map: its brightest texel is {peak / max(med, 1e-30):.3g} x the "
            f"median (at least {SUN_CONTRAST:g} x needed)"
        )
    r, c = np.unravel_index(int(np.argmax(lum)), lum.shape)
    shift = w // 2 - c  # centre the peak so the region does not wrap
    rolled = np.roll(lum, shift, axis=1)
    labels, _ = ndimage.label(rolled >= SUN_THRESHOLD * peak)
    mask = np.roll(labels == labels[r, w // 2], -shift, axis=1)
    d, omega = latlong_directions(h)
    wgt = omega[mask] * lum[mask]
    direction = (d[mask] * wgt[:, None]).sum(0)
    direction /= np.linalg.norm(direction)
    solid = float(omega[mask].sum())
    radiance = (img[mask] * omega[mask][:, None]).sum(0) / solid
    radius = math.degrees(math.acos(max(-1.0, 1 - solid / (2 * np.pi))))
    return {
        "direction": direction,
        "solid_angle": solid,
        "radiance": radiance,
        "radius_deg": radius,
        "mask": mask,
    }


def fill_region(img: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``img`` with the texels of ``mask`` (grown by one texel) set to the mean of the ring of
    texels around them: the sky without its sun."""
    from scipy import ndimage

    grown = ndimage.binary_dilation(mask, iterations=1)
    ring = ndimage.binary_dilation(grown, iterations=2) & ~grown
    out = img.copy()
    out[grown] = img[ring].mean(0) if ring.any() else 0.0
    return out


def sample_rect(img: np.ndarray, extent, x, z) -> np.ndarray:
    """Bilinear lookup (clamped) of an image (H, W, C) covering ``extent`` at world (x, z)."""
    x0, z0, x1, z1 = extent
    h, w = img.shape[:2]
    fx = np.clip((np.asarray(x, np.float64) - x0) / (x1 - x0) * w - 0.5, 0, w - 1)
    fz = np.clip((np.asarray(z, np.float64) - z0) / (z1 - z0) * h - 0.5, 0, h - 1)
    i0, j0 = np.floor(fx).astype(int), np.floor(fz).astype(int)
    i1, j1 = np.minimum(i0 + 1, w - 1), np.minimum(j0 + 1, h - 1)
    ax, az = (fx - i0)[..., None], (fz - j0)[..., None]
    return (1 - az) * ((1 - ax) * img[j0, i0] + ax * img[j0, i1]) + az * (
        (1 - ax) * img[j1, i0] + ax * img[j1, i1]
    )
