"""The port's side of the GL check's explanations on a GPU's own OpenGL
(``shaders_port.gl.compare``): how near each nearest-filtered lookup of the refraction's
raymarch and of the Fresnel LUT comes to a texel edge, and the highlight's slope in the Phong
cosine. Extra outputs of a render with ``diagnose=True``; nothing here is in the GLSL."""

from __future__ import annotations

import drjit as dr

from ..pipeline.texture import texmat_xy
from .highlight import fresnel_texel_edge, highlight_slope


@dr.syntax
def raymarch_texel_edge(m, P, R, iterations):
    """Least distance, in texels, of block [4]'s nearest-filtered depth lookups (the start and
    each of the ``iterations`` steps, positions accumulated as :func:`raycast_ground` does) to a
    texel edge of ``worldYComponent`` (detached Float). Where it is under a GPU's sub-texel
    addressing precision (``shaders_port.gl.compare.GPU_TEXEL_EDGE``) the GPU may read the
    neighbouring depth texel: the ray then crosses at another step, or the crossing
    interpolates another depth, and the colour jumps (a diagnostic of the GL check: not in
    the GLSL)."""
    R = dr.detach(R)
    p = m.Array3f(dr.detach(P.varyingVecWorldPosition))
    s, t = texmat_xy(P.tex_matrix0, p)
    edge = m.Float(P.worldYComponent.texel_edge(m, s, t))
    k = m.UInt32(0)
    n = m.UInt32(iterations)
    while k < n:
        p += R
        s, t = texmat_xy(P.tex_matrix0, p)
        edge = dr.minimum(edge, P.worldYComponent.texel_edge(m, s, t))
        k += 1
    return edge


def gl_check_diagnostics(m, P, C, f, reflection: bool, lobe: str) -> dict:
    """The port's side of the GL check's explanations for a GPU (``shaders_port.gl.compare``):
    ``raymarch_texel_edge`` (:func:`raymarch_texel_edge`), and with the reflection block
    ``fresnel_texel_edge`` and ``highlight_slope`` (``ports.highlight``). ``f``: the
    refraction's blocks (``ports.water_refraction.Refracted``). Extra outputs only."""
    out = {"raymarch_texel_edge": raymarch_texel_edge(m, P, f.R, f.loop_iterations)}
    if reflection:
        out["fresnel_texel_edge"] = fresnel_texel_edge(m, P, f.vEye, f.vBumpTex)
        out["highlight_slope"] = highlight_slope(m, P, f.vBumpTex, f.vEye, f.vLight, C, lobe)
    return out
