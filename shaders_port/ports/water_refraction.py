"""Dr.Jit port of the seed's refraction water shader (``water_refraction``), whole image at once.

Line by line the GLSL of seed 000, section 2 (fixes: names that did not compile, the
duplicated ``cpy`` declaration, ``cpy-cpy`` -> ``cpoy-cpy`` in the interpolation denominator,
``texture2D(fresnelLookup, vec2(NdotV, 0.5))``). Kept quirks: the cube-map ``y`` flip, no hit
test before the interpolation (a ray that never crosses the floor within ``LOOP_CAP`` steps
is still interpolated), ``R.y`` clamped to 0.001, ``olddepth = 0`` before the loop,
``NdotV`` from ``vBumpTex`` (not ``vBumpTexMore``), the specular term adding to alpha.

GLSL semantics: ``refract`` returns 0 on total internal reflection, ``normalize(0)`` is NaN,
``mix(x, y, a) = x (1 - a) + y a``, ``clamp(x, a, b) = min(max(x, a), b)``,
``pow(x, y) = exp2(y log2 x)`` (0 for x = 0). Non-finite output pixels are set to 0,
flagged in ``diagnostics['nonfinite']`` and reported with a ``RuntimeWarning``.

Inputs: :class:`ShaderInputs` and :class:`Constants`; scalars may be Python numbers or
size-1 Dr.Jit ``Float`` with gradients enabled. Output: :class:`ShaderOutput` (linear RGB).

Where derivatives are discontinuous (forward-mode AD gives the derivative of the branch
taken, i.e. the a.e. derivative, and misses the jumps):

* the step schedule: ``STEPS_GRAZING`` / ``STEPS_STEEP`` (and anything moving ``R``) decide
  at which step the ray crosses the floor; the colour jumps where the crossing step index
  changes and the derivative is continuous only between these jumps. ``LOOP_CAP`` is an
  integer (no derivative);
* the loop ``break`` (a crossing test on a nearest-filtered depth texture: piecewise
  constant in position, so the depth values carry zero derivative);
* the attenuation clamp at 1 (``travelLength / ATTENUATION_DISTANCE >= 1`` gives zero
  derivative with respect to the distance) and the clamps of ``NdotV`` and of the specular
  cosine; the nearest-filtered Fresnel LUT (piecewise constant in ``NdotV``).

Loops and derivatives. The raycast loops are ``@dr.syntax`` while loops with a per-lane
``break`` (active mask), run in Dr.Jit's symbolic mode. Derivatives (``loop_ad``):

* ``'replay'`` (default): the loops run on a detached step vector ``R`` and carry no AD
  state; afterwards the positions get their derivatives from ``current_position = start +
  i R`` (``i`` = iterations), which is exactly what AD through the unrolled loop yields
  (depths are nearest-filtered, so constant between jumps). Values are bit-identical to a
  plain render; checked against ``'evaluated'`` and against central differences in tests.
* ``'evaluated'``: AD through the loop in evaluated mode (``JitFlag.SymbolicLoops`` off
  while rendering, restored afterwards); symbolic-mode forward AD through such a loop is
  not trusted. Slower (one kernel per iteration).

Plain renders (no gradient) and ``'replay'`` Jacobians replay recorded kernels
(``dr.freeze``; ``STUDY_FREEZE=0`` or ``shaders_port.pipeline.frame.USE_FROZEN = False``
traces every call; see ``pipeline.frame.call_frozen``). Constants enter the kernels as opaque
float32 values, so traced and replayed renders are bit-identical.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import drjit as dr

from ..inputs import Constants, ShaderInputs
from ..pipeline import frame as _frame
from ..pipeline.frame import (
    ShaderOutput,
    evaluated_loops_if,
    finish_output,
    jacobian_passes,
    nonfinite_any,
    resolve_constants,
    tangents,
)
from ..pipeline.raster import prepare
from ..pipeline.texture import backend_types, clamp, mix, texmat_xy
from .box import box_reflection, box_state
from .gl_diagnostics import gl_check_diagnostics
from .highlight import fresnel_combine, specular_highlight
from .normals import normal_fetches, normal_map_block, with_maps_of
from .planar import MIRROR_NORMAL, mirror_state, planar_reflection
from .ssr import ssr_reflection, ssr_state
from .switches import decode

__all__ = ["render", "render_with_jacobian", "ShaderOutput", "Options", "DEFINES"]


class Options(NamedTuple):
    """The port's side of the GLSL variant switches; the defaults are the original shader's code
    path. Made from ``#define`` names by :data:`DEFINES` only (:func:`options_of`).

    reflection: True (original) or False (``NOREFLECTION``: block [7] skipped, the refraction
        colour alone -- no sky reflection and so no highlight).
    normal_layers: 4 (original), 2 (``TWO_NORMAL_LAYERS``) or 1 (``ONE_NORMAL_LAYER``).
    normals: 'average' (original: the layers' normals averaged), 'slopes' (``SLOPE_NORMALS``:
        the layers' slopes averaged, the normal of their mean height; one layer is the same
        either way) or 'lean' (``LEAN_NORMALS``: the layers' mean slope and the variance of the
        slopes the pixel does not resolve, from the mipmapped ``slopeMoments``; the variance
        widens the highlight: ``ports.normals``, ``ports.highlight``).
    parallax: False (original) or True (``PARALLAX_OFFSET``: the layers read where the eye ray
        meets the waves, their coordinates shifted by the layers' mean height from
        ``heightMap``; one more fetch per layer: ``ports.normals``).
    refine: None (original), 'binary' (``BINARY_REFINE``) or 'secant' (``SECANT_REFINE``): that
        many (``REFINE_STEPS``) bracket refinements after the linear search.
    attenuation: 'linear' (original: clamped mix over ``ATTENUATION_DISTANCE``) or 'beer'
        (``BEER_ATTENUATION``: ``exp(-ABSORPTION_RGB * travelLength)`` towards ``waterColor``).
    specular: 'phong' (original), 'ggx' (``GGX_SPECULAR``), 'disc' (``SUN_DISC_SPECULAR``: the
        sun's disc mirrored by the normal: a smoothstep from ``SUN_DISC_RADIUS`` times
        ``1 +- SUN_DISC_SOFTNESS`` degrees, times ``SUN_DISC_RADIANCE``) or 'none'
        (``NO_SPECULAR``).
    wall_faces: False (original) or True (``WALL_FACES``: a crossing into geometry that rises
        above the water plane, e.g. a pool wall, hit that geometry's vertical face under the
        water, which the top-down textures do not hold; it is shaded as ``waterColor``).
    reflection_map: what block [7] reads: 'cube' (original: the sky cube map), 'mirror'
        (``PLANAR_REFLECTION``: seed 004's mirrored camera at the surface point, offset by the
        projected flattened wave normal times ``REFLECT_DISTORTION`` (seed 002); needs
        ``ShaderInputs.reflection_color`` and ``reflection_view_proj``), 'box'
        (``BOX_REFLECTION``: the local cube map of the pool, box-projected (``ports.box``);
        needs ``ShaderInputs.box_cubemap``, ``box_min``, ``box_max`` and ``box_capture``) or
        'ssr' (``SSR_REFLECTION``: the screen-space reflection over the camera's buffers of the
        dry scene, the sky cube map where it finds nothing (``ports.ssr``); needs
        ``ShaderInputs.scene_color`` and ``scene_depth``).
    """

    reflection: bool = True
    normal_layers: int = 4
    normals: str = "average"
    parallax: bool = False
    refine: str | None = None
    attenuation: str = "linear"
    specular: str = "phong"
    wall_faces: bool = False
    reflection_map: str = "cube"


# the GL check (shaders_port.gl.compare) renders with diagnose=True: its GPU explanations
# (raymarch_texel_edge, fresnel_texel_edge, highlight_slope) come with the failure diagnostics
GL_CHECK_DIAGNOSE = True

# the one table from the GLSL file's #define names to the port's options (see ports.switches)
DEFINES = {
    "NOREFLECTION": {"reflection": False},
    "TWO_NORMAL_LAYERS": {"normal_layers": 2},
    "ONE_NORMAL_LAYER": {"normal_layers": 1},
    "SLOPE_NORMALS": {"normals": "slopes"},
    "LEAN_NORMALS": {"normals": "lean"},
    "PARALLAX_OFFSET": {"parallax": True},
    "BINARY_REFINE": {"refine": "binary"},
    "SECANT_REFINE": {"refine": "secant"},
    "BEER_ATTENUATION": {"attenuation": "beer"},
    "GGX_SPECULAR": {"specular": "ggx"},
    "NO_SPECULAR": {"specular": "none"},
    "SUN_DISC_SPECULAR": {"specular": "disc"},
    "WALL_FACES": {"wall_faces": True},
    "PLANAR_REFLECTION": {"reflection_map": "mirror"},
    "BOX_REFLECTION": {"reflection_map": "box"},
    "SSR_REFLECTION": {"reflection_map": "ssr"},
}
# texture reads per pixel attributed to PLANAR_REFLECTION for the mirrored camera's pass (as
# water_baseline.PASS_FETCHES)
PASS_FETCHES = 1


def options_of(defines, shader: str = "water_refraction", table: dict = DEFINES) -> Options:
    """``Options`` of ``shader`` compiled with the ``#define`` names ``defines`` (a tuple)."""
    return Options(**decode(shader, table, defines))


# ---- blocks shared with water_reflection -----------------------------------------------


def eye_and_light(m, P):
    # ---- [1] Eye and light vectors ----
    vEye = dr.normalize(P.varyingVecEye)
    vLight = dr.normalize(P.varyingVecLight)
    return vEye, vLight


def refract(m, I, N, eta):
    """GLSL ``refract``: 0 when ``k < 0`` (total internal reflection)."""
    d = dr.dot(N, I)
    k = 1.0 - eta * eta * (1.0 - d * d)
    out = eta * I - (eta * d + dr.sqrt(dr.maximum(k, 0.0))) * N
    return dr.select(k < 0.0, m.Array3f(0.0), out)


def reflect(m, I, N):
    """GLSL ``reflect``: ``I - 2 dot(N, I) N``."""
    return I - 2.0 * dr.dot(N, I) * N


def refraction_vector(m, vEye, vBumpTexMore, C):
    # ---- [3] Refraction vector and step schedule ----
    R = dr.normalize(refract(m, -vEye, vBumpTexMore, C.refr_coeff))
    numsteps = mix(C.steps_grazing, C.steps_steep, -R.y)
    stepsize = 1.0 / numsteps
    R *= stepsize
    return R


@dr.syntax
def raycast_ground(m, P, R, LOOP_CAP):
    # ---- [4] Raycast the ground ----
    current_position = m.Array3f(P.varyingVecWorldPosition)
    current_position_old = m.Array3f(current_position)
    olddepth = m.Float(0.0)
    s, t = texmat_xy(P.tex_matrix0, current_position)
    depthtex = P.worldYComponent.sample(m, s, t)
    depth = m.Float(depthtex[0])
    i = m.UInt32(0)
    crossed = m.Bool(False)  # width 1, widened by the loop (no width literal in a recording)
    while (i < LOOP_CAP) & ~crossed:
        current_position_old = m.Array3f(current_position)
        current_position += R
        olddepth = m.Float(depth)
        s, t = texmat_xy(P.tex_matrix0, current_position)
        depthtex = P.worldYComponent.sample(m, s, t)
        depth = m.Float(depthtex[0])
        crossed = depth > current_position.y
        i += 1
    return current_position, current_position_old, depth, olddepth, i, crossed


def loop_positions(m, C, R, current_position, current_position_old, i):
    """Attach derivatives to the positions a raycast loop ran with a detached ``R`` (mode
    ``loop_ad='replay'``): after ``i`` steps ``current_position = start + i R`` and
    ``current_position_old = start + (i - 1) R``, so their derivatives are ``i dR`` and
    ``(i - 1) dR`` -- exactly what AD through the unrolled loop gives (the ``break`` is not
    differentiable, the nearest-filtered depths carry no derivative). Values are unchanged."""
    if C.loop_ad != "replay" or not dr.grad_enabled(R):
        return current_position, current_position_old
    dR = R - dr.detach(R)
    n = m.Float(i)
    return current_position + n * dR, current_position_old + (n - 1.0) * dR


def loop_R(C, R):
    """The step vector handed to a raycast loop: detached in ``loop_ad='replay'`` mode."""
    return dr.detach(R) if C.loop_ad == "replay" else R


def refine_crossing(m, P, current_position, current_position_old, depth, olddepth, C, refine):
    """Variants ``BINARY_REFINE`` (``refine='binary'``, relief mapping) and ``SECANT_REFINE``
    (``'secant'``, parallax occlusion mapping): shrink the bracket ``REFINE_STEPS`` times at its
    middle or at its secant crossing (one depth fetch each). Unrolled (``REFINE_STEPS`` is a
    compile-time integer), so derivatives flow through the secant fractions directly. Returns
    the bracket and depths, the path of the decisions (Float, bit ``j`` set where step ``j``
    found the middle below the ground) and the least distance, in texels, of a step's depth
    lookup (nearest-filtered) to a texel edge: where float rounding flips a decision or a
    lookup's texel, the crossing jumps."""
    path = m.Float(0.0)
    edge = m.Float(1.0)
    for j in range(C.refine_steps):
        if refine == "binary":
            middle_position = 0.5 * (current_position_old + current_position)
        else:
            middle_position = mix(
                current_position_old,
                current_position,
                (current_position_old.y - olddepth)
                / (current_position_old.y - current_position.y + depth - olddepth),
            )
        s, t = texmat_xy(P.tex_matrix0, middle_position)
        middle_depth = m.Float(P.worldYComponent.sample(m, s, t)[0])
        edge = dr.minimum(edge, dr.detach(P.worldYComponent.texel_edge(m, s, t)))
        below = middle_depth > middle_position.y
        path = path + dr.select(below, float(2**j), 0.0)
        current_position = dr.select(below, middle_position, current_position)
        depth = dr.select(below, middle_depth, depth)
        current_position_old = dr.select(below, current_position_old, middle_position)
        olddepth = dr.select(below, olddepth, middle_depth)
    return current_position, current_position_old, depth, olddepth, (path, edge)


def interpolate_crossing(m, P, current_position, current_position_old, depth, olddepth):
    # ---- [5] Interpolate the crossing ----
    cpoy = current_position_old.y
    cpy = current_position.y
    denominator = cpoy - cpy + depth - olddepth
    current_position = mix(current_position_old, current_position, (cpoy - olddepth) / denominator)
    s, t = texmat_xy(P.tex_matrix0, current_position)
    vRefraction = m.Array4f(*P.refractionTexture.sample(m, s, t), 1.0)
    return current_position, vRefraction, denominator


def attenuation(
    m, P, current_position, vRefraction, depth, C, model: str = "linear", wall_faces: bool = False
):
    # ---- [6] Attenuation ----
    travelLength = dr.norm(current_position - P.varyingVecWorldPosition)
    if model == "beer":  # BEER_ATTENUATION
        transmittance = dr.exp(
            -m.Array3f(C.absorption_r, C.absorption_g, C.absorption_b) * travelLength
        )
        vRefraction = mix(C.waterColor, vRefraction, m.Array4f(*transmittance, 1.0))
    else:
        travelLength = clamp(travelLength / C.attenuation_distance, 0.0, 1.0)
        vRefraction = mix(vRefraction, C.waterColor, travelLength)
    if wall_faces:  # WALL_FACES
        vRefraction = dr.select(depth > P.varyingVecWorldPosition.y, C.waterColor, vRefraction)
    return vRefraction


def cubemap_reflection(m, P, R):
    """``textureCube(reflectionTexture, normalize(R) * vec3(1, -1, 1))`` as a vec4."""
    d = dr.normalize(R) * m.Array3f(1.0, -1.0, 1.0)
    return m.Array4f(*P.reflectionTexture.sample(m, d.x, d.y, d.z), 1.0)


# ---- failure diagnostics (not in the GLSL: extra outputs, the colour is unchanged) --------


def outside_unit_square(s, t):
    """Bool per lane: texture coordinate (s, t) outside [0, 1]^2 (clamp-to-edge substitutes
    the border texel there)."""
    return (s < 0.0) | (s > 1.0) | (t < 0.0) | (t > 1.0)


def refraction_failure_diagnostics(m, P, C, f: "Refracted") -> dict:
    """Per-lane quantities that say where the method of blocks [3]-[5] leaves its domain
    (read by ``study.studies.failures``); every value is a detached ``m.Float``:

    * ``refract_k``: GLSL refract's ``k = 1 - eta^2 (1 - dot(N, I)^2)`` (< 0: total internal
      reflection, ``R = 0``; cannot happen for ``refrCoeff <= 1``, kept as a check);
    * ``cos_eye_normal``: ``dot(vEye, vBumpTexMore)`` (<= 0: the bumped normal faces away from
      the eye, refract is applied from the back of the facet);
    * ``refr_dir_x/y/z``: the unit refraction direction ``normalize(R)`` (before the step scaling);
    * ``interp_weight``: ``(cpoy - olddepth) / denominator`` of block [5] (in [0, 1] when the
      floor was crossed; anything when the loop ran out and the crossing is extrapolated);
    * ``lookup_outside``: 1 where a ``worldYComponent`` fetch (the start, every step: the
      points lie on one segment, so checking its ends suffices, the texture square being
      convex) or the ``refractionTexture`` fetch at the interpolated point falls outside the
      top-down textures' [0, 1]^2.
    """
    vEye, N = dr.detach(f.vEye), dr.detach(f.vBumpTexMore)
    d = dr.dot(N, -vEye)
    eta = dr.detach(C.refr_coeff)
    k = 1.0 - eta * eta * (1.0 - d * d)
    Rn = dr.normalize(dr.detach(f.R))
    cpoy = dr.detach(f.loop_position_old.y)
    weight = (cpoy - dr.detach(f.olddepth)) / dr.detach(f.denominator)
    outside = m.Bool(False)
    for p in (P.varyingVecWorldPosition, f.loop_position, f.current_position):
        s, t = texmat_xy(P.tex_matrix0, dr.detach(p))
        outside |= outside_unit_square(s, t)
    return {
        "refract_k": m.Float(k),
        "cos_eye_normal": m.Float(-d),
        "refr_dir_x": m.Float(Rn.x),
        "refr_dir_y": m.Float(Rn.y),
        "refr_dir_z": m.Float(Rn.z),
        "interp_weight": m.Float(weight),
        "lookup_outside": dr.select(outside, 1.0, 0.0),
    }


# ---- the shader ---------------------------------------------------------------------------


@dataclass
class Refracted:
    """What blocks [1]-[6] hand to the rest of either shader (names as in the GLSL)."""

    vEye: object
    vLight: object
    vBumpTex: object
    vBumpTexMore: object
    R: object  # the scaled refraction step vector
    current_position: object  # the interpolated crossing
    vRefraction: object  # attenuated refraction colour (vec4)
    iterations: object
    crossed: object
    denominator: object
    # the loop's last state (before the interpolation), for the failure diagnostics only
    loop_position: object = None  # current_position after the last step
    loop_position_old: object = None  # current_position_old
    olddepth: object = None
    # the refinement's decisions and least texel-edge distance (refine_crossing), or None
    refine_path: object = None
    loop_iterations: object = None  # the linear search's steps (before any refinement)
    slope_variance: object = None  # LEAN_NORMALS: the unresolved slopes' variance, else None


def refraction_blocks(m, P, C, opts: Options = Options()) -> Refracted:
    """Blocks [1]-[6], shared by ``water_refraction`` and ``water_reflection`` (the seed's
    section 3: "very similar to the previous one")."""
    vEye, vLight = eye_and_light(m, P)
    vBumpTex, vBumpTexMore, slope_variance = normal_map_block(
        m, P, C.bumptex_mult, opts.normal_layers, opts.normals, opts.parallax, vEye
    )
    R = refraction_vector(m, vEye, vBumpTexMore, C)
    current_position, current_position_old, depth, olddepth, iterations, crossed = raycast_ground(
        m, P, loop_R(C, R), C.loop_cap
    )
    current_position, current_position_old = loop_positions(
        m, C, R, current_position, current_position_old, iterations
    )
    path = None
    loop_iterations = iterations
    if opts.refine is not None:
        current_position, current_position_old, depth, olddepth, path = refine_crossing(
            m, P, current_position, current_position_old, depth, olddepth, C, opts.refine
        )
        iterations = iterations + C.refine_steps
    loop_end = (current_position, current_position_old)  # kept for the diagnostics
    current_position, vRefraction, denominator = interpolate_crossing(
        m, P, current_position, current_position_old, depth, olddepth
    )
    loop_position, loop_position_old = loop_end
    vRefraction = attenuation(
        m, P, current_position, vRefraction, depth, C, opts.attenuation, opts.wall_faces
    )
    return Refracted(
        vEye,
        vLight,
        vBumpTex,
        vBumpTexMore,
        R,
        current_position,
        vRefraction,
        iterations,
        crossed,
        denominator,
        loop_position,
        loop_position_old,
        olddepth,
        path,
        loop_iterations,
        slope_variance,
    )


def reflection_block(m, P, C, opts: Options, Mi, f: Refracted):
    """Blocks [7]-[9] with the reflection ``opts.reflection_map`` reads (``Mi``: its state,
    ``ports.planar.Mirror``, ``ports.box.BoxProbe`` or ``ports.ssr.ScreenProbe``, None for the
    sky cube map). Returns ``(gl_FragColor`` Array4f, texture fetches it adds, Bool of
    non-finite intermediates, diagnostics of the reflection's decisions: with ``ssr``,
    ``refl_hit`` (1 where the march found the scene) and ``refl_iterations`` (its depth
    samples), as ``water_reflection`` reports its raycast's)."""
    vEye, vLight, vBumpTex = f.vEye, f.vLight, f.vBumpTex
    decisions = {}
    if opts.reflection_map == "mirror":
        # ---- [7] Reflection (PLANAR_REFLECTION: sources 004 and 002) ----
        vReflection, uv = planar_reflection(m, P, Mi, C, vBumpTex, m.Array3f(*MIRROR_NORMAL), False)
        fetches = 2 + PASS_FETCHES
        bad = nonfinite_any(vLight) | ~(dr.isfinite(uv[0]) & dr.isfinite(uv[1]))
    else:
        # ---- [7] Reflection ----
        R = dr.normalize(reflect(m, -vEye, f.vBumpTexMore))
        R.y = dr.maximum(R.y, 0.001)
        fetches = 2
        if opts.reflection_map == "box":  # BOX_REFLECTION
            vReflection = box_reflection(m, P, Mi, C, R)
        elif opts.reflection_map == "ssr":  # SSR_REFLECTION: its depth samples besides
            vReflection, taken, found = ssr_reflection(m, P, Mi, C, R, cubemap_reflection(m, P, R))
            fetches = fetches + taken
            decisions = {"refl_hit": dr.select(found, 1.0, 0.0), "refl_iterations": m.Float(taken)}
        else:
            vReflection = cubemap_reflection(m, P, R) * C.reflectColor
        bad = nonfinite_any(R, vLight)
    vReflection = specular_highlight(
        m, P, vReflection, vBumpTex, vEye, vLight, C, opts.specular, f.slope_variance
    )
    gl_FragColor = fresnel_combine(m, P, vReflection, f.vRefraction, vEye, vBumpTex)
    return gl_FragColor, fetches, bad, decisions


def _shade(m, P, C, diagnose: bool = False, opts: Options = Options(), Mi=None):
    f = refraction_blocks(m, P, C, opts)
    iterations, crossed, denominator = f.iterations, f.crossed, f.denominator
    # iterations include the refinement steps; PARALLAX_OFFSET reads the heights of each layer
    fetches = normal_fetches(opts) + 1 + iterations + 1
    bad = nonfinite_any(f.vEye, f.vBumpTex, f.vBumpTexMore, f.R, f.current_position)
    decisions = {}
    if opts.reflection:
        gl_FragColor, more, worse, decisions = reflection_block(m, P, C, opts, Mi, f)
        fetches = fetches + more
        bad |= worse
    else:
        gl_FragColor = f.vRefraction
    diagnostics = {
        "iterations": m.Float(iterations),
        "fetches": m.Float(fetches),
        "crossed": dr.select(crossed, 1.0, 0.0),
        "denominator": dr.abs(denominator),
        "nonfinite": dr.select(bad, 1.0, 0.0),
        **decisions,
    }
    if f.refine_path is not None:
        diagnostics["refine_path"], diagnostics["refine_texel_edge"] = f.refine_path
    if diagnose:
        diagnostics.update(refraction_failure_diagnostics(m, P, C, f))
        diagnostics.update(gl_check_diagnostics(m, P, C, f, opts.reflection, opts.specular))
    return gl_FragColor, diagnostics


def _frozen_shade(m, P, C, diagnose, opts, Mi):
    return _frame.call_frozen(
        ("water_refraction", diagnose, opts) + _frame.python_config(C),
        lambda m, P, C, Mi: _shade(m, P, C, diagnose, opts, Mi),
        m,
        P,
        C,
        Mi,
    )


def _reflection_state(m, inputs, opts: Options):
    """The state of the reflection ``opts`` reads beyond the study's inputs: the mirrored
    camera's (``ports.planar.Mirror``), the local cube map's (``ports.box.BoxProbe``), the
    camera's buffers (``ports.ssr.ScreenProbe``) or None."""
    if opts.reflection and opts.reflection_map == "mirror":
        return mirror_state(m, inputs, "water_refraction with PLANAR_REFLECTION")
    if opts.reflection and opts.reflection_map == "box":
        return box_state(m, inputs, "water_refraction with BOX_REFLECTION")
    if opts.reflection and opts.reflection_map == "ssr":
        return ssr_state(m, inputs, "water_refraction with SSR_REFLECTION")
    return None


def render(
    inputs: ShaderInputs,
    constants: Constants | None = None,
    *,
    defines: tuple = (),
    backend: str | None = None,
    loop_ad: str = "replay",
    diagnose: bool = False,
) -> ShaderOutput:
    """Render ``water_refraction`` compiled with ``defines`` (``#define`` names of
    :data:`DEFINES`, e.g. ``("NOREFLECTION",)``).

    Returns a :class:`ShaderOutput`: ``color`` TensorXf (H, W, 3) linear RGB, 0 off the
    water; ``mask`` TensorXf (H, W); ``diagnostics`` TensorXf (H, W) each: ``iterations``
    (raycast loop iterations), ``fetches`` (texture2D/textureCube calls of the shader),
    ``crossed`` (1 if the floor was crossed within ``LOOP_CAP``), ``denominator``
    (``|cpoy - cpy + depth - olddepth|``), ``nonfinite`` (1 where the colour or an intermediate
    vector -- vEye, vBumpTex, vBumpTexMore, R, the interpolated position, and with reflection
    vLight -- was non-finite: GLSL's clamp and texture lookups can turn a NaN into a finite
    colour); with ``SSR_REFLECTION`` also ``refl_hit`` and ``refl_iterations`` (the march's
    decisions, :func:`reflection_block`), with a refinement ``refine_path`` and
    ``refine_texel_edge`` (its decisions, its lookups' distance to a texel edge:
    :func:`refine_crossing`). ``loop_ad`` matters only for gradient-enabled constants (see the
    module doc). ``diagnose=True`` adds the failure diagnostics of
    :func:`refraction_failure_diagnostics` (extra outputs only: the colour is bit-identical).
    """
    opts = options_of(defines)
    m = backend_types(backend)
    P = with_maps_of(m, prepare(inputs, m), opts)
    Mi = _reflection_state(m, inputs, opts)
    C = resolve_constants(m, constants if constants is not None else Constants(), loop_ad)
    with evaluated_loops_if(C.differentiable and loop_ad == "evaluated"):
        if _frame.USE_FROZEN and not C.differentiable:
            color, diag = _frozen_shade(m, P.shading_state(), C, diagnose, opts, Mi)
        else:
            color, diag = _shade(m, P, C, diagnose, opts, Mi)
        return finish_output(m, P, color, diag, "water_refraction")


def _frozen_tangents(m, P, C, params, opts, Mi):
    return _frame.call_frozen(
        ("water_refraction.tangents", opts) + _frame.python_config(C),
        lambda m, P, C, params, Mi: tangents(m, *_shade(m, P, C, False, opts, Mi), params),
        m,
        P,
        C,
        params,
        Mi,
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
    """Render and return ``(ShaderOutput, J)``, ``J`` float32 (H, W, 3, len(names)).

    ``J[..., j]`` is the forward-mode derivative of the linear-RGB colour with respect to
    the scalar ``names[j]`` (a scalar key of ``CONSTANT_SPECS`` or ``"water_color[i]"`` /
    ``"reflect_color[i]"``), one AD pass per name; zero off the water and on non-finite
    pixels. ``loop_ad``: 'replay' (default; symbolic loops, loop positions differentiated as
    ``start + i R``) or 'evaluated' (AD through the unrolled loop in evaluated mode).
    """
    opts = options_of(defines)

    def shade_tangents(m, P, C, params, frozen):
        Mi = _reflection_state(m, inputs, opts)
        if frozen:
            return _frozen_tangents(m, P, C, params, opts, Mi)
        return tangents(m, *_shade(m, P, C, False, opts, Mi), params)

    return jacobian_passes(
        shade_tangents,
        "water_refraction",
        inputs,
        constants if constants is not None else Constants(),
        names,
        backend,
        loop_ad,
        lanes=lanes,
        maps=lambda m, P: with_maps_of(m, P, opts),
    )
