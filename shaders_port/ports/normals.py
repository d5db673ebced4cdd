"""Block [2] of the raycast shaders (``water_refraction``, ``water_reflection``): the normal map's
layers made one normal, and the bump scaling. The layers' texels are averaged as normals (the
original, 000), or, with ``SLOPE_NORMALS`` (the ``normals = "slopes"`` choice of the shader
space), blended as slopes: partial-derivative blending (Barre-Brisebois and Hill, "Blending in
Detail", 2012), the normal of the layers' mean height, which is the reference's surface
(``study.scene.geometry.Waves``: the mean of the four layers' heights). With ``LEAN_NORMALS``
(``normals = "lean"``: Olano and Baker's LEAN mapping) the layers' slopes and their squares are
read from the mipmapped ``slopeMoments`` (``pipeline.normal_maps``) at the pixel's footprint: the
normal of the layers' mean slope over the footprint, and the variance of the slopes the pixel
does not resolve, which widens the highlight (``ports.highlight``). With ``PARALLAX_OFFSET``
(``parallax = "offset"``: parallax offset mapping, Kaneko et al. 2001) the layers are read
where the eye ray meets the waves rather than at the water plane's point: the layers' mean
height ``H`` (``heightMap``, ``pipeline.normal_maps``, in tile lengths) shifts every layer's
coordinate by ``H / max(vEye.y, PARALLAX_MIN_Y) * vEye.xz`` (one step).

``P.normalMap`` samples (..., 3) encoded normals ``0.5 n + 0.5`` (``y`` up); ``P.texcoord[k]``
the layer ``k``'s texture coordinate; returns unit Array3f (world space).
"""

from __future__ import annotations

import drjit as dr

from ..pipeline.normal_maps import SLOPE_MIN_Y, with_maps

NORMALS = ("average", "slopes", "lean")
#: ``vEye.y`` is held at this or more in the parallax shift (the eye 3 degrees over the water)
PARALLAX_MIN_Y = 0.05


def slope_blend(m, texels):
    """SLOPE_NORMALS: the normal of the layers' mean height, ``normalize(-mean slope, 1)``,
    each layer's slope ``(dh/dx, dh/dz) = -n.xz / max(n.y, SLOPE_MIN_Y)`` (``layerSlope``)."""
    sx, sz = None, None
    for t in texels:
        n = 2.0 * t - 1.0
        y = dr.maximum(n.y, SLOPE_MIN_Y)
        sx = -n.x / y if sx is None else sx + (-n.x / y)
        sz = -n.z / y if sz is None else sz + (-n.z / y)
    k = 1.0 / len(texels)
    return dr.normalize(m.Array3f(-(k * sx), 1.0, -(k * sz)))


def _taps(m, P, layers: int, coords) -> list:
    return [m.Array3f(P.normalMap.sample(m, coords[k][0], coords[k][1])) for k in range(layers)]


def parallax_coords(m, P, layers: int, vEye) -> list:
    """PARALLAX_OFFSET: the layers' coordinates shifted to where the eye ray meets the waves:
    ``layers`` lookups of ``P.heightMap`` at the layers' coordinates, their mean ``H`` (tile
    lengths), every coordinate plus ``H / max(vEye.y, PARALLAX_MIN_Y) * vEye.xz``."""
    if P.heightMap is None:
        raise ValueError("PARALLAX_OFFSET reads heightMap: prepare the frame with with_maps")
    H = None
    for k in range(layers):
        h = P.heightMap.sample(m, P.texcoord[k][0], P.texcoord[k][1])[0]
        H = h if H is None else H + h
    d = (1.0 / layers) * H / dr.maximum(vEye.y, PARALLAX_MIN_Y)
    return [(s + d * vEye.x, t + d * vEye.z) for s, t in P.texcoord]


def lean_blend(m, P, layers: int):
    """LEAN_NORMALS: ``(normal, variance)``: the normal of the layers' mean slope over the
    pixel's footprint and the per-axis variance (Float, slope units squared) of the mean slope
    the pixel does not resolve, ``(1 / layers^2) * sum_k 0.5 * (var_x + var_z)`` of the layers'
    ``E[s^2] - E[s]^2`` (independent layers; each clamped at 0). Each layer is one trilinear
    lookup of ``P.slopeMoments`` at llvmpipe's level of detail of its coordinates
    (``P.slopeLod``, ``pipeline.normal_maps.with_lean``)."""
    tex = P.slopeMoments
    if tex is None:
        raise ValueError("LEAN_NORMALS reads slopeMoments: prepare the frame with with_lean")
    sx = sz = var = None
    for k in range(layers):
        a = tex.sample_lod(m, P.texcoord[k][0], P.texcoord[k][1], P.slopeLod[k])
        v = 0.5 * (dr.maximum(a[2] - a[0] * a[0], 0.0) + dr.maximum(a[3] - a[1] * a[1], 0.0))
        sx, sz = (a[0], a[1]) if sx is None else (sx + a[0], sz + a[1])
        var = v if var is None else var + v
    k = 1.0 / layers
    return dr.normalize(m.Array3f(-(k * sx), 1.0, -(k * sz))), (k * k) * var


def normal_map_block(
    m, P, BumptexMult, layers: int = 4, normals: str = "average", parallax: bool = False, vEye=None
):
    """(vBumpTex, vBumpTexMore, slopeVariance): the layers' normal (``layers`` of 4, 2 or 1:
    the original, ``TWO_NORMAL_LAYERS``, ``ONE_NORMAL_LAYER``; ``normals`` one of
    :data:`NORMALS`: the original, ``SLOPE_NORMALS``, ``LEAN_NORMALS``; ``parallax``:
    ``PARALLAX_OFFSET``, read where the eye ray ``vEye`` meets the waves), that normal with its
    y scaled by ``BumptexMult`` and renormalised, and with ``LEAN_NORMALS`` the unresolved
    slopes' variance (:func:`lean_blend`; None otherwise)."""
    if normals not in NORMALS:
        raise ValueError(f"normals = {normals!r}; the choices: {', '.join(NORMALS)}")
    if parallax and normals == "lean":
        raise ValueError("PARALLAX_OFFSET with LEAN_NORMALS: LEAN reads at the plane's point")
    # ---- [2] Normal map: average four layers, bump scaling ----
    coords = parallax_coords(m, P, layers, vEye) if parallax else P.texcoord
    variance = None
    if normals == "lean":  # LEAN_NORMALS
        vBumpTex, variance = lean_blend(m, P, layers)
    elif layers == 1:  # ONE_NORMAL_LAYER
        vBumpTex = dr.normalize(2.0 * _taps(m, P, 1, coords)[0] - 1.0)
    elif normals == "slopes":  # SLOPE_NORMALS
        vBumpTex = slope_blend(m, _taps(m, P, layers, coords))
    elif layers == 2:  # TWO_NORMAL_LAYERS
        taps = _taps(m, P, 2, coords)
        vBumpTex = dr.normalize(2.0 * (taps[0] + taps[1]) - 2.0)
    else:
        taps = _taps(m, P, 4, coords)
        vBumpTex = dr.normalize(2.0 * (taps[0] + taps[1] + taps[2] + taps[3]) - 4.0)
    vBumpTexMore = dr.normalize(vBumpTex * m.Array3f(1.0, BumptexMult, 1.0))
    return vBumpTex, vBumpTexMore, variance


def normal_fetches(opts) -> int:
    """Block [2]'s texture reads for a raycast port's ``Options``: one per layer, twice with
    ``PARALLAX_OFFSET``."""
    return opts.normal_layers * (2 if opts.parallax else 1)


def with_maps_of(m, P, opts):
    """``P`` with the normal map's derived maps a raycast port's ``Options`` read
    (``pipeline.normal_maps.with_maps``)."""
    return with_maps(m, P, opts.normals == "lean", opts.parallax)
