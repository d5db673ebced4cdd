"""The screen-space reflection (engines' SSR), read by ``water_refraction`` compiled with
``SSR_REFLECTION`` (block [7]).

The camera's depth buffer of the scene without the water (``ShaderInputs.scene_depth``, the
baseline shader's buffer) holds what this camera sees above the water; a reflected ray that
meets something the camera sees can take that thing's colour from the camera's colour buffer
(``scene_color``). As engines do it (Godot, three.js ``SSRPass``, Unreal), the ray is marched on
the screen over the depth buffer; where it finds nothing, the shader falls back on the sky cube
map, as the original shader reads it.

The march. The reflected ray ``P + t R`` (``t >= 0``) is clipped to the camera's view frustum in
homogeneous clip space: its points are ``mix(ssrStart, ssrRay, u)`` for ``u`` in [0, 1]
(``ssrStart = MVP (P, 1)``, ``ssrRay = MVP (R, 0)``; ``u = 1`` is the ray's point at infinity),
and each plane ``w +- x``, ``w +- y``, ``w +- z >= 0`` is left at ``u = f0 / (f0 - min(fR, 0))``
(1 where it is never left). Between the start and that exit the window coordinates (s, t,
depth) are linear on the screen, so the march takes :data:`SSR_STEPS` equal screen steps
between them. A sample is a hit where the depth buffer there holds a surface (not the clear
value 1), the sample lies behind it, and that surface lies no more than :data:`SSR_THICKNESS`
of the previous sample's view depth in front of the previous sample (the ray passed behind it
during this step; a surface in front of the whole step, e.g. the wall nearest the camera, is
not hit). The hit is
refined, without a fetch, to where the step's depth reaches the depth found (the step's start
where that depth is nearer than the whole step), and the colour buffer is read there
(bilinear). No fade at the screen's edges: the frustum's edge ends the
march and the sky cube map takes over there.

Fetches per pixel: the depth samples taken (the march stops at a hit; :data:`SSR_STEPS` where
none) and one colour, the scene's or the sky cube map's, where the sky cube map alone reads one.

Derivatives: the hit point moves with ``R`` (through the frustum exit, the steps and the
refinement), the colour buffer is bilinear: forward-mode AD flows through them. Whether and at
which step a ray hits is decided on the nearest-filtered depth buffer (no derivative): the
colour jumps where that decision changes.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import numpy as np

from ..inputs import SSR_INPUTS, ShaderInputs
from ..pipeline.texture import CLAMP, LINEAR, NEAREST, Texture2D, clamp, mix
from .planar import mat4_vec4, mat_tuple

# the depth samples of the march (GLSL ``#define SSR_STEPS`` in water_refraction.frag)
SSR_STEPS = 4
# how far in front of the ray's previous sample a surface may lie and still be hit, a fraction
# of that sample's view depth (GLSL ``#define SSR_THICKNESS``)
SSR_THICKNESS = 0.02
# the floor of a step's depth span in the refinement (no 0 / 0 on a step of constant depth)
MIN_SPAN = 1e-30


@dataclass
class ScreenProbe:
    """The camera's buffers of the scene without the water and its matrices
    (freeze-traversable)."""

    sceneColor: object
    sceneDepth: object
    mvp: tuple  # gl_ModelViewProjectionMatrix (= view_proj), nested float32 tuples
    mvp_inverse: tuple  # gl_ModelViewProjectionMatrixInverse


def ssr_state(m, inputs: ShaderInputs, shader: str) -> ScreenProbe:
    """Upload the camera's buffers; a ValueError names what ``inputs`` lacks."""
    inputs.require(SSR_INPUTS, shader, "study.scene.baseline_inputs.with_baseline_inputs")
    return ScreenProbe(
        sceneColor=Texture2D.from_numpy(m, inputs.scene_color, LINEAR, CLAMP),
        sceneDepth=Texture2D.from_numpy(m, inputs.scene_depth, NEAREST, CLAMP),
        mvp=mat_tuple(inputs.view_proj),
        mvp_inverse=mat_tuple(np.linalg.inv(inputs.view_proj.astype(np.float64))),
    )


def frustum_segment(m, S: ScreenProbe, origin, R):
    """Window coordinates (Array3f: s, t, depth) of the ray ``origin + t R`` at its start and
    where it leaves the view frustum (``ssrFrom``, ``ssrTo``)."""
    start = mat4_vec4(m, S.mvp, origin.x, origin.y, origin.z, 1.0)
    ray = mat4_vec4(m, S.mvp, R.x, R.y, R.z, 0.0)
    sxyz, rxyz = m.Array3f(start.x, start.y, start.z), m.Array3f(ray.x, ray.y, ray.z)
    plus, minus = start.w + sxyz, start.w - sxyz
    exit_plus = plus / (plus - dr.minimum(ray.w + rxyz, 0.0))
    exit_minus = minus / (minus - dr.minimum(ray.w - rxyz, 0.0))
    exit = dr.minimum(exit_plus, exit_minus)
    end = mix(start, ray, dr.minimum(dr.minimum(exit.x, exit.y), exit.z))
    ssrFrom = 0.5 * sxyz / start.w + 0.5
    ssrTo = 0.5 * m.Array3f(end.x, end.y, end.z) / end.w + 0.5
    return ssrFrom, ssrTo


def view_depth(m, S: ScreenProbe, s, t, depth):
    """The clip-space ``w`` (view depth) of window coordinates ``(s, t, depth)``:
    ``1 / (MVP^-1 (2 (s, t, depth) - 1, 1)).w``."""
    row = S.mvp_inverse[3]
    return 1.0 / (
        row[0] * (2.0 * s - 1.0) + row[1] * (2.0 * t - 1.0) + row[2] * (2.0 * depth - 1.0) + row[3]
    )


def ssr_march(m, S: ScreenProbe, origin, R, steps: int = SSR_STEPS):
    """The march of the module doc: ``(found`` Bool, ``hit`` Array3f window coordinates of the
    refined hit, ``taken`` UInt32 depth samples read). Unrolled (``SSR_STEPS`` is a
    compile-time integer); a lane stops at its first hit as the GLSL loop breaks."""
    ssrFrom, ssrTo = frustum_segment(m, S, origin, R)
    previous = m.Array3f(ssrFrom)
    previousW = view_depth(m, S, previous.x, previous.y, previous.z)
    hit = m.Array3f(ssrFrom)
    found = m.Bool(False)
    taken = m.UInt32(0)
    for k in range(1, steps + 1):
        active = ~found
        sample = mix(ssrFrom, ssrTo, float(k) / float(steps))
        sceneZ = m.Float(S.sceneDepth.sample(m, sample.x, sample.y)[0])
        sceneW = view_depth(m, S, sample.x, sample.y, sceneZ)
        now = (
            active
            & (sceneZ < 1.0)
            & (sceneZ <= sample.z)
            & (sceneW >= previousW * (1.0 - SSR_THICKNESS))
        )
        span = dr.maximum(sample.z - previous.z, MIN_SPAN)
        along = clamp((sceneZ - previous.z) / span, 0.0, 1.0)  # 0: the surface is nearer
        hit = dr.select(now, mix(previous, sample, along), hit)
        taken = dr.select(active, taken + 1, taken)
        found = found | now
        previous = sample
        previousW = view_depth(m, S, sample.x, sample.y, sample.z)
    return found, hit, taken


def ssr_reflection(m, P, S: ScreenProbe, C, R, sky):
    """Block [7] with ``SSR_REFLECTION``: the scene's colour where the march hits, else ``sky``
    (the sky cube map's ``vec4`` along ``R``), times ``reflectColor``. ``R``: the reflected
    direction after the seed's ``R.y`` clamp. Returns ``(vReflection`` Array4f, ``taken``
    depth samples, ``found`` Bool)."""
    found, hit, taken = ssr_march(m, S, P.varyingVecWorldPosition, R)
    scene = S.sceneColor.sample(m, hit.x, hit.y)
    colour = dr.select(found, m.Array4f(*scene, 1.0), sky)
    return colour * C.reflectColor, taken, found
