"""Seed 004's planar reflection offset by the wave normal (seed 002), shared by the shaders
that read the mirrored camera's texture (``water_baseline`` and ``water_refraction`` compiled
with ``PLANAR_REFLECTION``).

The state a shader needs for it is any object with the attributes ``reflection_sampler``
(``Texture2D`` of the mirrored camera's colour, linear RGB, bilinear, clamped),
``o2v_projection_reflection`` (the mirrored camera's projection * view, nested float32 tuples,
row-major) and ``normal_matrix`` (``gl_NormalMatrix``, (3, 3) nested tuples): :class:`Mirror`
is one, :func:`mirror_state` makes it.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import numpy as np

from ..inputs import ShaderInputs, normal_matrix
from ..pipeline.texture import CLAMP, LINEAR, Texture2D

MIRROR_NORMAL = (0.0, 1.0, 0.0)  # the undeformed mirror's normal (seed 002)


@dataclass
class Mirror:
    """The mirrored camera's texture and matrices (freeze-traversable)."""

    reflection_sampler: object
    o2v_projection_reflection: tuple
    normal_matrix: tuple


def mat_tuple(M) -> tuple:
    """A matrix as nested float32-valued Python float tuples (row-major)."""
    return tuple(tuple(float(v) for v in row) for row in np.asarray(M, np.float32))


def mirror_state(m, inputs: ShaderInputs, shader: str) -> Mirror:
    """Upload the mirrored camera's buffer; a ValueError names what ``inputs`` lacks."""
    inputs.require(
        ("reflection_color", "reflection_view_proj"),
        shader,
        "study.scene.baseline_inputs.with_baseline_inputs",
    )
    return Mirror(
        reflection_sampler=Texture2D.from_numpy(m, inputs.reflection_color, LINEAR, CLAMP),
        o2v_projection_reflection=mat_tuple(inputs.reflection_view_proj),
        normal_matrix=mat_tuple(normal_matrix(inputs.view_proj)),
    )


def mat4_vec4(m, M, x, y, z, w):
    """``M * vec4(x, y, z, w)`` -> Array4f (M: nested float tuples, row-major)."""
    return m.Array4f(*(M[i][0] * x + M[i][1] * y + M[i][2] * z + M[i][3] * w for i in range(4)))


def planar_reflection(m, P, S, C, vBumpTex, mirrorNormal, flat: bool):
    """The planar reflection (sources 004 and 002; block [6] of water_baseline, [7] of
    water_refraction): the mirrored camera's texture at the surface point's
    projective coordinate, offset by the projected flattened wave normal. Returns
    ``(vReflection`` Array4f linear RGB times ``reflectColor``, ``vTextureReflection`` pair of
    Float texture coordinates); 1 fetch."""
    wp = P.varyingVecWorldPosition
    vClipReflection = mat4_vec4(m, S.o2v_projection_reflection, wp.x, 0.0, wp.z, 1.0)
    vDeviceReflection = (
        vClipReflection.x / vClipReflection.w,
        vClipReflection.y / vClipReflection.w,
    )
    vTextureReflection = (0.5 + 0.5 * vDeviceReflection[0], 0.5 + 0.5 * vDeviceReflection[1])
    if not flat:
        flatNormal = vBumpTex - dr.dot(vBumpTex, mirrorNormal) * mirrorNormal
        N = S.normal_matrix
        eyeNormal = m.Array3f(
            *(
                N[i][0] * flatNormal.x + N[i][1] * flatNormal.y + N[i][2] * flatNormal.z
                for i in range(3)
            )
        )
        exy = m.Array2f(eyeNormal.x, eyeNormal.y)
        # a flat normal must not deform the image: no offset where eyeNormal.xy is 0
        reflectOffset = dr.select(
            dr.norm(exy) > 0.0,
            dr.normalize(exy) * dr.norm(flatNormal) * C.reflect_distortion,
            m.Array2f(0.0, 0.0),
        )
        # 004's mirrored camera is flipped in y (t = 1 - gl_FragCoord.y / height): 002's
        # offset is in window coordinates, so its vertical part enters with the opposite sign
        vTextureReflection = (
            vTextureReflection[0] + reflectOffset.x,
            vTextureReflection[1] - reflectOffset.y,
        )
    reflectionTextureColor = S.reflection_sampler.sample(
        m, vTextureReflection[0], vTextureReflection[1]
    )
    vReflection = m.Array4f(*reflectionTextureColor, 1.0) * C.reflectColor
    return vReflection, vTextureReflection
