"""Block [2] of the raycast shaders (``water_refraction``, ``water_reflection``): the normal map's
layers made one normal, and the bump scaling. The layers' texels are averaged as normals (the
original, 000), or, with ``SLOPE_NORMALS`` (the ``normals = "slopes"`` choice of the shader
space), blended as slopes: partial-derivative blending (Barre-Brisebois and Hill, "Blending in
Detail", 2012), the normal of the layers' mean height, which is the reference's surface
(``study.scene.geometry.Waves``: the mean of the four layers' heights).

``P.normalMap`` samples (..., 3) encoded normals ``0.5 n + 0.5`` (``y`` up); ``P.texcoord[k]``
the layer ``k``'s texture coordinate; returns unit Array3f (world space).
"""

from __future__ import annotations

import drjit as dr

#: a texel's normal y is held at this or more in ``layerSlope`` (tipped past 87 degrees)
SLOPE_MIN_Y = 0.05


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


def _taps(m, P, layers: int) -> list:
    return [
        m.Array3f(P.normalMap.sample(m, P.texcoord[k][0], P.texcoord[k][1])) for k in range(layers)
    ]


def normal_map_block(m, P, BumptexMult, layers: int = 4, slopes: bool = False):
    """(vBumpTex, vBumpTexMore): the layers' normal (``layers`` of 4, 2 or 1: the original,
    ``TWO_NORMAL_LAYERS``, ``ONE_NORMAL_LAYER``; ``slopes``: ``SLOPE_NORMALS``) and that normal
    with its y scaled by ``BumptexMult`` and renormalised."""
    # ---- [2] Normal map: average four layers, bump scaling ----
    taps = _taps(m, P, layers)
    if layers == 1:  # ONE_NORMAL_LAYER
        vBumpTex = dr.normalize(2.0 * taps[0] - 1.0)
    elif slopes:  # SLOPE_NORMALS
        vBumpTex = slope_blend(m, taps)
    elif layers == 2:  # TWO_NORMAL_LAYERS
        vBumpTex = dr.normalize(2.0 * (taps[0] + taps[1]) - 2.0)
    else:
        vBumpTex = dr.normalize(2.0 * (taps[0] + taps[1] + taps[2] + taps[3]) - 4.0)
    vBumpTexMore = dr.normalize(vBumpTex * m.Array3f(1.0, BumptexMult, 1.0))
    return vBumpTex, vBumpTexMore
