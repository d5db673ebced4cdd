"""The maps a raycast shader derives from the study's normal map: its LEAN maps (Olano and
Baker, "LEAN Mapping", 2010), what ``LEAN_NORMALS`` reads as ``slopeMoments``, and its heights,
what ``PARALLAX_OFFSET`` reads as ``heightMap``.

``slopeMoments``: each texel holds the slope ``(dh/dx, dh/dz)`` of its normal and the squares
of its two components: ``(sx, sz, sx^2, sz^2)`` (RGBA32F, float32, no encoding), ``s = -n.xz
/ max(n.y, SLOPE_MIN_Y)`` of the decoded normal ``n = 2 texel - 1`` (the slope
``SLOPE_NORMALS`` takes from one texel). The texture is mipmapped (box-filtered levels,
``pipeline.texture.box_mip_chain``, what ``glGenerateMipmap`` makes of it on llvmpipe) and
sampled trilinearly with the implicit level of detail, repeat: a lookup returns the means of
the slopes and of their squares over the pixel's footprint, and ``E[s^2] - E[s]^2`` is the
variance of the slopes the pixel does not resolve (0 where one texel covers the pixel).

The hand ports take the level of detail as llvmpipe does (``spirv.quads``: once per 2x2 quad,
from the quad's origin pixel, ``pipeline.texture.lod_from_gradients``):
:func:`texcoord_gradients` gives each covered pixel its quad's ``(ds/dx, dt/dx, ds/dy,
dt/dy)`` of each layer's coordinates, :func:`with_lean` the levels of detail made of them.

``heightMap`` (:func:`height_map`): R32F, the height of the surface whose slopes the normal
map's texels hold (``s = -n.xz / max(n.y, SLOPE_MIN_Y)``), integrated over the periodic tile
(least squares by FFT: the spectral solution of ``grad h = s``, mean 0), in texture units (tile
lengths; world units divided by ``normal_tile``), so that a shader shifts its texture
coordinates by it without knowing the tile; bilinear, repeat, no mipmaps. The mean of the
layers' heights is the reference's surface over the water plane (``study.scene.geometry.Waves``
builds the normal map from that surface's slopes).
"""

from __future__ import annotations

import dataclasses
from collections import OrderedDict

import drjit as dr
import numpy as np

from .interpolate import plane_points
from .texture import LINEAR, REPEAT, Texture2D, lod_from_gradients

#: a texel's normal y is held at this or more for its slope (tipped past 87 degrees)
SLOPE_MIN_Y = 0.05


def _slopes(normal_map: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(sx, sz) float64: the slopes ``-n.xz / max(n.y, SLOPE_MIN_Y)`` of ``normal_map``'s
    texels ((H, W, 3) encoded ``0.5 n + 0.5``)."""
    n = 2.0 * np.asarray(normal_map, np.float64) - 1.0
    if n.ndim != 3 or n.shape[2] != 3:
        raise ValueError(f"normal_map must be (H, W, 3), got {n.shape}")
    y = np.maximum(n[..., 1], SLOPE_MIN_Y)
    return -n[..., 0] / y, -n[..., 2] / y


def slope_moments(normal_map: np.ndarray) -> np.ndarray:
    """(S, S, 4) float32 ``(sx, sz, sx^2, sz^2)`` of ``normal_map`` ((S, S, 3) encoded
    ``0.5 n + 0.5``, world x, y up, z), the level 0 of ``slopeMoments``."""
    sx, sz = _slopes(normal_map)
    return np.stack([sx, sz, sx * sx, sz * sz], -1).astype(np.float32)


def height_map(normal_map: np.ndarray) -> np.ndarray:
    """(S, S) float32 ``heightMap`` of ``normal_map`` ((S, S, 3) encoded ``0.5 n + 0.5``): the
    height whose gradient is nearest the texels' slopes, in tile lengths, mean 0 (module doc).
    Rows are v (world z), columns u (world x), as the normal map's."""
    sx, sz = _slopes(normal_map)  # dh/du, dh/dv in tile lengths per tile length
    h, w = sx.shape
    kv = 2.0 * np.pi * np.fft.fftfreq(h, d=1.0 / h)[:, None]  # radians per tile length
    ku = 2.0 * np.pi * np.fft.fftfreq(w, d=1.0 / w)[None, :]
    k2 = ku * ku + kv * kv
    k2[0, 0] = 1.0
    spectrum = -1j * (ku * np.fft.fft2(sx) + kv * np.fft.fft2(sz)) / k2
    spectrum[0, 0] = 0.0
    return np.real(np.fft.ifft2(spectrum)).astype(np.float32)


def moments_texture(m, normal_map: np.ndarray) -> Texture2D:
    """``slopeMoments`` for the Dr.Jit type module ``m``: :func:`slope_moments` mipmapped,
    bilinear within and linear between levels, repeat."""
    a = slope_moments(normal_map)
    return Texture2D.from_numpy(m, a, LINEAR, REPEAT).with_mipmaps(m, LINEAR, a)


def texcoord_gradients(inputs, raster) -> np.ndarray:
    """(4, N, 4) float32: per layer ``k``, ``(ds/dx, dt/dx, ds/dy, dt/dy)`` of its coordinates
    at the covered pixels of ``raster`` (``pipeline.raster.Raster`` of ``inputs``), as llvmpipe
    takes an implicit level of detail (``spirv.quads``): float32 differences from each pixel's
    2x2 quad origin ``(x0, y0)`` (even window coordinates, window y up) to ``(x0 + 1, y0)`` and
    ``(x0, y0 + 1)``, of the coordinates those pixels have (``raster.texcoord`` where the water
    covers them, else, as a helper pixel, those of the plane point seen through its centre),
    in texture units per pixel."""
    W, H = raster.width, raster.height
    col, row = raster.index % W, raster.index // W
    x0, y0 = col & ~1, (H - 1 - row) & ~1
    where = np.full(W * H + 1, -1, np.int64)  # flat pixel -> lane (-1: not covered)
    where[raster.index] = np.arange(raster.index.size)
    waves = np.asarray(inputs.waves, np.float64)[:4, None, :]

    def coords(x, y):
        inside = (x >= 0) & (x < W) & (y >= 0) & (y < H)
        lane = where[np.where(inside, (H - 1 - y) * W + x, W * H)]
        out = raster.texcoord[:, np.maximum(lane, 0)].copy()
        helper = np.flatnonzero(lane < 0)
        if helper.size:
            p, _ = plane_points(inputs.view_proj, W, H, x[helper], H - 1 - y[helper])
            base = p[:, [0, 2]] / inputs.normal_tile
            out[:, helper] = (base[None] + waves).astype(np.float32)
        return out

    origin = coords(x0, y0)
    dx, dy = coords(x0 + 1, y0) - origin, coords(x0, y0 + 1) - origin
    return np.concatenate([dx, dy], -1)


def frame_moments(m, P) -> Texture2D:
    """:func:`moments_texture` of the prepared frame ``P``'s normal map (cached per upload)."""
    key = ("moments", P.upload, m.__name__)
    if key not in _CACHE:
        _remember(key, moments_texture(m, P.inputs.normal_map))
    return _CACHE[key]


def frame_heights(m, P) -> Texture2D:
    """``heightMap`` of the prepared frame ``P``'s normal map (bilinear, repeat; cached per
    upload)."""
    key = ("heights", P.upload, m.__name__)
    if key not in _CACHE:
        _remember(key, Texture2D.from_numpy(m, height_map(P.inputs.normal_map), LINEAR, REPEAT))
    return _CACHE[key]


#: the maps derived from the normal map, by the sampler a shader reads each as: its level 0 of
#: the normal map's texels ((S, S, 3) encoded -> float32 texels), and its texture for a prepared
#: frame ``(m, P) -> Texture2D`` (``slopeMoments`` mipmapped)
DERIVED_MAPS = {"slopeMoments": slope_moments, "heightMap": height_map}
FRAME_MAPS = {"slopeMoments": frame_moments, "heightMap": frame_heights}


def with_maps(m, P, lean: bool = False, heights: bool = False):
    """``P`` with what ``LEAN_NORMALS`` (``lean``: :func:`with_lean`) and ``PARALLAX_OFFSET``
    (``heights``: ``heightMap``, :func:`frame_heights`) read."""
    if lean:
        P = with_lean(m, P)
    if heights and P.heightMap is None:
        key = ("with heights", P.upload, m.__name__, lean)
        if key not in _CACHE:
            _remember(key, dataclasses.replace(P, heightMap=frame_heights(m, P)))
        P = _CACHE[key]
    return P


def with_lean(m, P):
    """The prepared frame ``P`` (``pipeline.raster.Prepared``) with what ``LEAN_NORMALS`` reads:
    ``slopeMoments`` (:func:`frame_moments`) and ``slopeLod``, each layer's level of detail
    (Float per lane) from :func:`texcoord_gradients` by ``pipeline.texture.lod_from_gradients``
    (evaluated). Cached per upload of ``P``: the same object for the same frame, so a frozen
    shade sees the same inputs."""
    if P.slopeMoments is not None:
        return P
    key = ("lean", P.upload, m.__name__)
    if key not in _CACHE:
        tex, g = frame_moments(m, P), texcoord_gradients(P.inputs, P.raster)
        lod = tuple(
            lod_from_gradients(m, tex, *(m.Float(np.ascontiguousarray(gk[:, i])) for i in range(4)))
            for gk in g
        )
        dr.eval(lod)
        _remember(key, dataclasses.replace(P, slopeMoments=tex, slopeLod=lod))
    return _CACHE[key]


# (what, upload, type module) -> value, the last few (as many frames as
# pipeline.raster.prepare keeps, both kinds)
_CACHE: OrderedDict = OrderedDict()


def _remember(key, value) -> None:
    _CACHE[key] = value
    while len(_CACHE) > 16:
        _CACHE.popitem(last=False)
