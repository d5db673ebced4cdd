"""Blocks [8] and [9] of the raycast shaders (``water_refraction``, ``water_reflection``): the
specular highlight added to the reflection, one of the ``specular`` choices of the shader space
(Phong on the averaged normal, GGX with Smith masking, the sun's disc seen in the mirror of the
normal), and the Fresnel combine of reflection and refraction through the LUT.

``vBumpTex``, ``vEye``, ``vLight``: unit Array3f (world space); colours Array4f linear RGBA;
``C``: the resolved constants (``pipeline.frame.resolve_constants``); ``P``: the prepared
inputs (``lightcolor``, ``fresnelLookup``).
"""

from __future__ import annotations

import drjit as dr

from ..pipeline.texture import clamp, gl_pow, radians, smoothstep


#: (180 / pi)^2: a variance in radians squared to degrees squared
DEG2_PER_RAD2 = 3282.8064


def specular_highlight(
    m, P, vReflection, vBumpTex, vEye, vLight, C, lobe: str = "phong", variance=None
):
    """Block [8]: ``vReflection`` (Array4f) with the highlight of ``lobe`` added. ``variance``
    (``LEAN_NORMALS``: the per-axis variance of the slopes the pixel does not resolve, Float,
    ``ports.normals.lean_blend``; None: no widening) widens the lobe by it. A normal tilted by
    slope ``s`` turns the mirrored light by ``2 s`` radians (small slopes), so the lobe is
    convolved with a spread of per-axis variance ``4 variance``; each lobe is replaced by the one
    of the same second moment, its energy kept:

    * Phong, ``cos^n`` (per-axis variance ``1/n``): ``n' = n / (1 + 4 variance n)``, the
      strength times ``n' / n``;
    * GGX: ``alpha^2 + 2 variance`` (Beckmann's ``alpha^2 = 2 variance``; GGX's distribution
      is normalised);
    * the sun's disc (per-axis variance ``radius^2 / 4``): ``radius'^2 = radius^2 + 16
      variance`` (radians), the radiance times ``(radius / radius')^2``."""
    # ---- [8] Specular highlight ----
    if lobe == "none":  # NO_SPECULAR
        return vReflection
    if lobe == "ggx":  # GGX_SPECULAR
        vHalf = dr.normalize(vLight + vEye)
        NdotH = clamp(dr.dot(vBumpTex, vHalf), 0.0, 1.0)
        NdotL = clamp(dr.dot(vBumpTex, vLight), 0.0, 1.0)
        NdotE = clamp(dr.dot(vBumpTex, vEye), 0.0, 1.0)
        alpha2 = C.specular_roughness * C.specular_roughness
        if variance is not None:  # LEAN_NORMALS
            alpha2 = alpha2 + 2.0 * variance
        ggxDenominator = NdotH * NdotH * (alpha2 - 1.0) + 1.0
        ggxD = alpha2 / (3.14159265 * ggxDenominator * ggxDenominator)
        smithVis = 1.0 / (
            (NdotL + dr.sqrt(alpha2 + (1.0 - alpha2) * NdotL * NdotL))
            * (NdotE + dr.sqrt(alpha2 + (1.0 - alpha2) * NdotE * NdotE))
        )
        spec = ggxD * smithVis * NdotL
        specular = m.Array4f(
            spec * P.lightcolor[0], spec * P.lightcolor[1], spec * P.lightcolor[2], 1.0
        )
        vReflection += specular * C.specular_strength
        return vReflection
    rLight = dr.dot(2.0 * vBumpTex, vLight) * vBumpTex - vLight
    if lobe == "disc":  # SUN_DISC_SPECULAR
        radius, strength = C.sun_disc_radius, C.sun_disc_radiance
        if variance is not None:  # LEAN_NORMALS
            wide = dr.sqrt(radius * radius + (16.0 * DEG2_PER_RAD2) * variance)
            strength = strength * (radius * radius) / (wide * wide)
            radius = wide
        outerCos = dr.cos(radians(radius * (1.0 + C.sun_disc_softness)))
        innerCos = dr.cos(radians(radius * (1.0 - C.sun_disc_softness)))
        spec = smoothstep(outerCos, innerCos, dr.dot(rLight, vEye))
    else:
        exponent, strength = C.specular_exponent, C.specular_strength
        if variance is not None:  # LEAN_NORMALS
            widen = 1.0 + 4.0 * variance * exponent
            exponent, strength = exponent / widen, strength / widen
        spec = gl_pow(clamp(dr.dot(rLight, vEye), 0.0, 1.0), exponent)
    specular = m.Array4f(
        spec * P.lightcolor[0], spec * P.lightcolor[1], spec * P.lightcolor[2], 1.0
    )
    vReflection += specular * strength
    return vReflection


def fresnel_combine(m, P, vReflection, vRefraction, vEye, vBumpTex):
    # ---- [9] Fresnel combine ----
    NdotV = clamp(dr.dot(vEye, vBumpTex), 0.0, 1.0)
    FresnelCoeffs = P.fresnelLookup.sample(m, NdotV, m.Float(0.5))
    return vReflection * FresnelCoeffs[1] + vRefraction * FresnelCoeffs[0]


# ---- diagnostics for the GL check (not in the GLSL: extra outputs, the colour is unchanged) ----


def fresnel_texel_edge(m, P, vEye, vBumpTex):
    """Distance, in texels, of block [9]'s nearest-filtered Fresnel LUT lookup to a texel edge
    (detached Float): where it is under a GPU's sub-texel addressing precision, the GPU may
    read the neighbouring LUT entry (``shaders_port.gl.compare``)."""
    NdotV = clamp(dr.dot(dr.detach(vEye), dr.detach(vBumpTex)), 0.0, 1.0)
    return m.Float(P.fresnelLookup.texel_edge(m, NdotV, m.Float(0.5)))


def highlight_slope(m, P, vBumpTex, vEye, vLight, C, lobe: str = "phong"):
    """|d colour / d cos| of block [8]'s Phong highlight as block [9] weighs it (detached Float):
    ``R * SPECULAR_STRENGTH * SPECULAR_EXPONENT * cos^(SPECULAR_EXPONENT - 1) * max(lightcolor)``,
    ``cos = clamp(dot(rLight, vEye), 0, 1)`` and ``R`` the Fresnel LUT's reflection weight.
    How far the colour moves when the cosine moves by a little (a GPU's normal map filtered at
    its own sub-texel precision moves it by ~1e-5 to 1e-4 where the normal map is steep): with a
    large exponent and strength this reaches 1e-2 per 1e-4. 0 for the other lobes (None, GGX,
    the sun's disc), which the GL check does not explain this way."""
    if lobe != "phong":
        return m.Float(dr.zeros(m.Float, dr.width(vEye)))
    N, E, L = dr.detach(vBumpTex), dr.detach(vEye), dr.detach(vLight)
    rLight = dr.dot(2.0 * N, L) * N - L
    c = clamp(dr.dot(rLight, E), 0.0, 1.0)
    e = dr.detach(C.specular_exponent)
    slope = dr.detach(C.specular_strength) * e * gl_pow(c, dr.maximum(e - 1.0, 0.0))
    NdotV = clamp(dr.dot(E, N), 0.0, 1.0)
    reflectance = P.fresnelLookup.sample(m, NdotV, m.Float(0.5))[1]
    lc = dr.maximum(dr.maximum(P.lightcolor[0], P.lightcolor[1]), P.lightcolor[2])
    return m.Float(dr.abs(slope * reflectance * lc))
