"""Dr.Jit port of the baseline game water shader (``water_baseline``), whole image at once.

Line by line ``glsl/water_baseline.frag``: seeds 001-004 composed as a game builds them
(planar refraction of the depth-buffer point (001) applied backwards on the screen-space
scene texture, normal-map distortion with chromatic dispersion (003), planar reflection from
the mirrored camera by projective texturing (004) offset by the projected flattened wave
normal (002)), with seed 000's depth tint, Phong highlight and Fresnel LUT. Variants (GLSL
defines, ``defines=`` here): ``FLAT_WATER`` (no normal map and no distortion: 001 + 004, the
flat-water limit), ``NO_PLANAR_REFRACTION`` (no 001), ``NO_REFRACTION`` (no refracted light: the
water colour, as 002 and 004 alone) and ``CUBE_REFLECTION`` (seed 000's sky cube map in place of
004's mirrored camera).

GLSL semantics as in ``water_refraction``: ``refract`` returns 0 on total internal reflection,
``normalize(0)`` is NaN (seed 002's ``normalize(eyeNormal.xy)`` is guarded: no offset where the
projected flattened normal is 0, as on calm water), ``mix``/``clamp``/``pow`` as specified.
``gl_FragCoord`` is the pixel centre ``(c + 0.5, H - r - 0.5)``. Non-finite pixels are set to 0,
flagged in ``diagnostics['nonfinite']`` and warned about.

Inputs: :class:`ShaderInputs` with the optional fields ``scene_color``, ``scene_depth``,
``reflection_color`` and ``reflection_view_proj`` (see ``study.scene.baseline_inputs``);
:class:`Constants` (this shader reads ``refraction_index``, ``refraction_strength``,
``chromatic_dispersion``, ``reflect_distortion``, ``attenuation_distance``, ``water_color``,
``reflect_color``, ``specular_strength``, ``specular_exponent``; see :data:`READS`).

Derivatives: no loop; forward-mode AD through every block. Discontinuous where: the
nearest-filtered depth (constant per texel, no derivative), the depth-tint clamp at 1, the
clamps of ``NdotV`` and of the specular cosine, the nearest-filtered Fresnel LUT, texel
edges of the clamped bilinear lookups (kinks only), and the direction ``normalize(eyeNormal.xy)``
near a flat normal (its offset goes to 0 there, continuously, but its direction jumps).

Diagnostics: ``fetches`` (texture reads per pixel: this shader's, plus :data:`PASS_FETCHES`
for the mirrored camera's extra pass, none with ``CUBE_REFLECTION``), ``iterations`` (0: no
loop), ``nonfinite``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import drjit as dr
import numpy as np

from ..glsl_text import constants_read, read_source, with_define
from ..inputs import Constants, ShaderInputs, normal_matrix
from ..pipeline import frame as _frame
from ..pipeline.frame import (
    ShaderOutput,
    finish_output,
    jacobian_passes,
    nonfinite_any,
    resolve_constants,
    tangents,
)
from ..pipeline.raster import prepare
from ..pipeline.texture import CLAMP, LINEAR, NEAREST, Texture2D, backend_types, clamp, gl_pow, mix
from .planar import MIRROR_NORMAL, mat4_vec4, planar_reflection
from .planar import mat_tuple as _mat
from .switches import decode
from .water_refraction import cubemap_reflection, eye_and_light, reflect, refract

__all__ = ["render", "render_with_jacobian", "ShaderOutput", "READS", "DEFINES", "PASS_FETCHES"]

# the one table from the GLSL file's #define names to the port's options (see ports.switches)
DEFINES = {
    "FLAT_WATER": {"flat": True},
    "NO_PLANAR_REFRACTION": {"planar": False},
    "NO_REFRACTION": {"refraction": False},
    "CUBE_REFLECTION": {"cube": True},
}
# texture reads per pixel attributed to the shader for the mirrored camera's pass (one surface
# texture read per pixel of the reflection render; none with the cube map); the scene
# colour/depth pass is the frame the game renders anyway and is not counted
PASS_FETCHES = 1


class Options(NamedTuple):
    """The port's switches (see :data:`DEFINES`): no normal map (``flat``), 001's planar
    refraction (``planar``), refracted light at all (``refraction``), the sky cube map in place of
    the planar reflection (``cube``)."""

    flat: bool = False
    planar: bool = True
    refraction: bool = True
    cube: bool = False


# the constants the GLSL declares; FLAT_WATER reads neither REFLECT_DISTORTION nor the 003 pair
# (see reads_with)
READS = (
    "attenuation_distance",
    "specular_strength",
    "specular_exponent",
    "reflect_distortion",
    "refraction_index",
    "refraction_strength",
    "chromatic_dispersion",
    "water_color",
    "reflect_color",
)


@dataclass
class Screen:
    """What the baseline reads beyond the seed-000 inputs (freeze-traversable)."""

    bumpUV: tuple  # (s, t) Float: gl_FragCoord.xy / screenSize per lane
    sceneColor: object
    sceneDepth: object
    reflection_sampler: object
    mvp: tuple  # gl_ModelViewProjectionMatrix (= view_proj), nested float32 tuples
    mvp_inverse: tuple  # gl_ModelViewProjectionMatrixInverse
    normal_matrix: tuple  # gl_NormalMatrix (3, 3)
    o2v_projection_reflection: tuple
    viewpos: tuple


def screen_state(m, P, inputs: ShaderInputs, o: Options = Options()) -> Screen:
    """Upload the screen-space buffers the variant reads (the others are None) and the per-lane
    window coordinate."""
    need = ("scene_color", "scene_depth") if o.refraction else ()
    need += () if o.cube else ("reflection_color", "reflection_view_proj")
    inputs.require(need, "water_baseline", "study.scene.baseline_inputs.with_baseline_inputs")
    r = P.raster
    col = (r.index % r.width).astype(np.float32)
    row = (r.index // r.width).astype(np.float32)
    fx, fy = col + np.float32(0.5), np.float32(r.height) - row - np.float32(0.5)
    s = fx / np.float32(inputs.width)  # gl_FragCoord.x / screenSize.x in float32
    t = fy / np.float32(inputs.height)
    return Screen(
        bumpUV=(m.Float(s), m.Float(t)),
        sceneColor=_texture(m, inputs.scene_color, LINEAR, o.refraction),
        sceneDepth=_texture(m, inputs.scene_depth, NEAREST, o.refraction),
        reflection_sampler=_texture(m, inputs.reflection_color, LINEAR, not o.cube),
        mvp=_mat(inputs.view_proj),
        mvp_inverse=_mat(np.linalg.inv(inputs.view_proj.astype(np.float64))),
        normal_matrix=_mat(normal_matrix(inputs.view_proj)),
        o2v_projection_reflection=None if o.cube else _mat(inputs.reflection_view_proj),
        viewpos=tuple(float(v) for v in inputs.viewpos),
    )


def _texture(m, image, filt, read: bool):
    return Texture2D.from_numpy(m, image, filt, CLAMP) if read else None


# ---- seed 001 ----------------------------------------------------------------------------


def Refract(m, S, position, surface, refractionIndex):
    """Seed 001: the perceived position of ``position`` seen through the plane ``surface``."""
    # ray origin is the camera position
    viewerPosition = m.Array3f(*S.viewpos)
    # ray end is the vertex's undistorted position
    vertexPosition = position
    # get the vector from the camera to the vertex
    worldRay = vertexPosition - viewerPosition
    # normalize it for direction
    worldRayDir = dr.normalize(worldRay)
    # surface is a vector4 that defines a plane
    worldPlaneNormal = m.Array3f(*surface[:3])
    # define a known position on the plane
    worldPlaneOrigin = worldPlaneNormal * surface[3]
    # get the vector result of the worldRay entering the water
    refraction = refract(m, worldRayDir, dr.normalize(worldPlaneNormal), refractionIndex)
    # raycast from the vertex, backwards along the refraction vector
    denom = dr.dot(-worldPlaneNormal, -refraction)
    p010 = worldPlaneOrigin - vertexPosition
    t = dr.dot(p010, -worldPlaneNormal) / denom
    intersection = vertexPosition + refraction * -t
    # get the vector from the camera to the intersection, this is the perceived position
    originToIntersection = intersection - viewerPosition
    # starting from the camera, move along the perceived position vector by the original ray length
    return viewerPosition + dr.normalize(originToIntersection) * dr.norm(worldRay)


WATER_PLANE = (0.0, 1.0, 0.0, 0.0)


# ---- the shader ---------------------------------------------------------------------------


def _shade(m, P, S, C, o: Options):
    # ---- [1] Eye and light vectors ----
    vEye, vLight = eye_and_light(m, P)

    # ---- [2] Normal map: average four layers ----
    fetches = 0
    mirrorNormal = m.Array3f(*MIRROR_NORMAL)
    if not o.flat:
        vBumpTexA = m.Array3f(P.normalMap.sample(m, P.texcoord[0][0], P.texcoord[0][1]))
        vBumpTexB = m.Array3f(P.normalMap.sample(m, P.texcoord[1][0], P.texcoord[1][1]))
        vBumpTexC = m.Array3f(P.normalMap.sample(m, P.texcoord[2][0], P.texcoord[2][1]))
        vBumpTexD = m.Array3f(P.normalMap.sample(m, P.texcoord[3][0], P.texcoord[3][1]))
        vBumpTex = dr.normalize(2.0 * (vBumpTexA + vBumpTexB + vBumpTexC + vBumpTexD) - 4.0)
        fetches += 4
    else:
        vBumpTex = m.Array3f(mirrorNormal)
    bad = nonfinite_any(vEye, vLight, vBumpTex)

    if o.refraction:
        # ---- [3] Planar refraction (seed 001) ----
        groundPosition, refractedUV = planar_refraction(m, S, C, o.planar)
        fetches += 1

        # ---- [4] Normal-map distortion and chromatic dispersion (seed 003) ----
        vRefraction = distorted_refraction(m, S, C, vBumpTex, refractedUV, o.flat)
        fetches += 1 if o.flat else 3

        # ---- [5] Depth tint ----
        travelLength = dr.norm(groundPosition - P.varyingVecWorldPosition)
        travelLength = clamp(travelLength / C.attenuation_distance, 0.0, 1.0)
        vRefraction = mix(vRefraction, C.waterColor, travelLength)
        bad |= nonfinite_any(groundPosition)
        if o.planar:
            bad |= ~(dr.isfinite(refractedUV[0]) & dr.isfinite(refractedUV[1]))
    else:
        # no refracted light: the water's own colour (the depth tint's limit)
        vRefraction = m.Array4f(C.waterColor)

    if o.cube:
        # ---- [6] Sky cube-map reflection (seed 000) ----
        R = dr.normalize(reflect(m, -vEye, vBumpTex))
        R.y = dr.maximum(R.y, 0.001)
        vReflection = cubemap_reflection(m, P, R) * C.reflectColor
        bad |= nonfinite_any(R)
    else:
        # ---- [6] Planar reflection (seed 004), distorted by the wave normal (seed 002) ----
        vReflection, vTextureReflection = planar_reflection(
            m, P, S, C, vBumpTex, mirrorNormal, o.flat
        )
        if not o.flat:
            bad |= ~(dr.isfinite(vTextureReflection[0]) & dr.isfinite(vTextureReflection[1]))
    fetches += 1

    # ---- [7] Specular highlight ----
    rLight = dr.dot(2.0 * vBumpTex, vLight) * vBumpTex - vLight
    spec = gl_pow(clamp(dr.dot(rLight, vEye), 0.0, 1.0), C.specular_exponent)
    specular = m.Array4f(
        spec * P.lightcolor[0], spec * P.lightcolor[1], spec * P.lightcolor[2], 1.0
    )
    vReflection += specular * C.specular_strength

    # ---- [8] Fresnel combine ----
    NdotV = clamp(dr.dot(vEye, vBumpTex), 0.0, 1.0)
    FresnelCoeffs = P.fresnelLookup.sample(m, NdotV, m.Float(0.5))
    fetches += 1
    gl_FragColor = vReflection * FresnelCoeffs[1] + vRefraction * FresnelCoeffs[0]

    # the count below matches the code above
    assert fetches + (0 if o.cube else PASS_FETCHES) == fetch_count(o)
    diagnostics = {"nonfinite": dr.select(bad, 1.0, 0.0)}
    return gl_FragColor, diagnostics


def planar_refraction(m, S, C, planar: bool):
    """Block [3] (source 001): the depth-buffer point under the pixel and the screen coordinate
    it is seen at through the flat water, applied backwards. Returns ``(groundPosition``
    Array3f world, ``refractedUV`` pair of Float screen coordinates in [0, 1]); 1 fetch."""
    bumpUV = S.bumpUV
    sceneZ = S.sceneDepth.sample(m, bumpUV[0], bumpUV[1])[0]
    groundClip = mat4_vec4(
        m, S.mvp_inverse, 2.0 * bumpUV[0] - 1.0, 2.0 * bumpUV[1] - 1.0, 2.0 * sceneZ - 1.0, 1.0
    )
    groundPosition = m.Array3f(groundClip.x, groundClip.y, groundClip.z) / groundClip.w
    if planar:
        a = Refract(m, S, groundPosition, WATER_PLANE, C.refraction_index)
        apparentClip = mat4_vec4(m, S.mvp, a.x, a.y, a.z, 1.0)
        apparentUV = (
            0.5 + 0.5 * apparentClip.x / apparentClip.w,
            0.5 + 0.5 * apparentClip.y / apparentClip.w,
        )
        refractedUV = (
            bumpUV[0] - (apparentUV[0] - bumpUV[0]),
            bumpUV[1] - (apparentUV[1] - bumpUV[1]),
        )
    else:
        refractedUV = bumpUV
    return groundPosition, refractedUV


def distorted_refraction(m, S, C, vBumpTex, refractedUV, flat: bool):
    """Block [4] (source 003): the scene colour at ``refractedUV`` moved by the normal map, each
    channel at its own offset (chromatic dispersion). Returns ``vRefraction`` Array4f linear
    RGB, alpha 1; 3 fetches (1 if ``flat``: no distortion)."""
    if not flat:
        bump = (vBumpTex.x, vBumpTex.z)
        newUV = (
            refractedUV[0] + bump[0] * C.refraction_strength,
            refractedUV[1] + bump[1] * C.refraction_strength,
        )
        red = S.sceneColor.sample(
            m, newUV[0] - C.chromatic_dispersion, newUV[1] - C.chromatic_dispersion
        )
        green = S.sceneColor.sample(m, newUV[0], newUV[1])
        blue = S.sceneColor.sample(
            m, newUV[0] - C.chromatic_dispersion, newUV[1] - C.chromatic_dispersion
        )
        refractionColor = m.Array3f(red[0], green[1], blue[2])
    else:
        refractionColor = m.Array3f(S.sceneColor.sample(m, refractedUV[0], refractedUV[1]))
    vRefraction = m.Array4f(refractionColor.x, refractionColor.y, refractionColor.z, 1.0)
    return vRefraction


def fetch_count(o: Options = Options()) -> int:
    """Texture reads per pixel of the variant: [2] 4 normal-map layers (none if flat), [3] 1 depth,
    [4] 3 scene reads (1 if flat; [3] and [4] none without refraction), [6] 1 reflection, [8] 1
    Fresnel LUT, plus ``PASS_FETCHES`` for the mirrored camera (none with the cube map)."""
    refraction = (1 + (1 if o.flat else 3)) if o.refraction else 0
    passes = 0 if o.cube else PASS_FETCHES
    return (0 if o.flat else 4) + refraction + 1 + 1 + passes


def with_static_diagnostics(m, diag: dict, o: Options) -> dict:
    """``diag`` plus ``fetches`` and ``iterations`` (0): the same on every lane, so they are made
    here, outside the recorded kernels (a width baked into a frozen recording would be replayed
    at the wrong size)."""
    n = dr.width(diag["nonfinite"])
    return {
        "iterations": dr.zeros(m.Float, n),
        "fetches": dr.full(m.Float, float(fetch_count(o)), n),
        **diag,
    }


def reads_with(defines=()) -> tuple[str, ...]:
    """The constants the GLSL reads when compiled with ``defines`` (see
    ``glsl_text.constants_read``)."""
    src = read_source("water_baseline", "frag", "core")
    for d in defines:
        src = with_define(src, d)
    return tuple(constants_read(src))


def _options(defines) -> Options:
    """The port's :class:`Options` for ``defines`` (see :data:`DEFINES`)."""
    return Options(**decode("water_baseline", DEFINES, defines))


def _frozen_shade(m, P, S, C, o: Options):
    # one frozen function per Python-level configuration (see pipeline.frame.frozen)
    return _frame.call_frozen(
        ("water_baseline", *o) + _frame.python_config(C),
        lambda m, P, S, C: _shade(m, P, S, C, o),
        m,
        P,
        S,
        C,
    )


def render(
    inputs: ShaderInputs,
    constants: Constants | None = None,
    *,
    defines: tuple = (),
    backend: str | None = None,
    loop_ad: str = "replay",
    diagnose: bool = False,
) -> ShaderOutput:
    """Render ``water_baseline`` compiled with ``defines`` (a subset of :data:`DEFINES`).

    Returns a :class:`ShaderOutput`: ``color`` TensorXf (H, W, 3) linear RGB, 0 off the water;
    ``mask``; ``diagnostics`` (H, W): ``fetches``, ``iterations`` (0), ``nonfinite``.
    ``loop_ad`` is accepted for the common port interface (this shader has no loop).
    ``diagnose=True`` (the raycast ports' failure diagnostics) is refused: this shader has none.
    """
    if diagnose:
        raise ValueError(
            "water_baseline has no failure diagnostics (they classify raycast failures); "
            "study failures applies to the raycast variants only"
        )
    o = _options(defines)
    m = backend_types(backend)
    P = prepare(inputs, m)
    S = screen_state(m, P, inputs, o)
    C = resolve_constants(m, constants if constants is not None else Constants(), loop_ad)
    if _frame.USE_FROZEN and not C.differentiable:
        color, diag = _frozen_shade(m, P.shading_state(), S, C, o)
    else:
        color, diag = _shade(m, P, S, C, o)
    return finish_output(m, P, color, with_static_diagnostics(m, diag, o), "water_baseline")


def _frozen_tangents(m, P, S, C, params, o: Options):
    return _frame.call_frozen(
        ("water_baseline.tangents", *o) + _frame.python_config(C),
        lambda m, P, S, C, params: tangents(m, *_shade(m, P, S, C, o), params),
        m,
        P,
        S,
        C,
        params,
    )


def render_with_jacobian(
    inputs: ShaderInputs,
    constants: Constants | None,
    names: list[str],
    *,
    defines: tuple = (),
    backend: str | None = None,
    loop_ad: str = "replay",
    lanes=None,
):
    """Render and return ``(ShaderOutput, J)``, ``J`` float32 (H, W, 3, len(names)): the
    forward-mode derivative of the linear-RGB colour with respect to each named scalar
    constant (``"water_color[i]"`` for colour components); zero off the water."""
    o = _options(defines)
    reads = reads_with(defines)
    unread = [n for n in names if n.split("[")[0] not in reads]
    if unread:
        raise ValueError(
            f"water_baseline{''.join(' ' + d for d in defines)} does not read {unread}: "
            f"no derivative with respect to them; it reads: {', '.join(reads)}"
        )

    def shade_tangents(m, P, C, params, frozen):
        S = screen_state(m, prepare(inputs, m), inputs, o)
        if frozen:
            color, diag, grads = _frozen_tangents(m, P, S, C, params, o)
        else:
            color, diag, grads = tangents(m, *_shade(m, P, S, C, o), params)
        return color, with_static_diagnostics(m, diag, o), grads

    return jacobian_passes(
        shade_tangents,
        "water_baseline",
        inputs,
        constants if constants is not None else Constants(),
        names,
        backend,
        loop_ad,
        lanes=lanes,
    )
