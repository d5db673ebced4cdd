"""Dr.Jit port of the seed's reflection-and-refraction water shader (``water_reflection``).

Seed 000, section 3: blocks [1]-[6], [8] and [9] are those of ``water_refraction`` (the
same functions, imported from it); block [7] raycasts the reflection ray against the
bottom-up textures ``worldYComponentReflection`` / ``reflectionBottom`` (texture matrix
``gl_TextureMatrix[1]``) and falls back to the cube map when nothing is hit. Fixes as in
``water_refraction`` plus ``reflectionTop`` -> ``reflectionBottom`` (the declared sampler)
and the duplicated ``cpy`` -> ``cpoy``. Kept quirks: the bounds test on ``texcoord`` breaks
*before* the depth fetch, ``olddepth`` is updated after that test, the height cut
``current_position.y > REFL_HEIGHT_CUT`` ends the loop without a hit, ``noHit`` selects the
cube map (looked up with the step-scaled ``R``, renormalised, ``y`` flipped).

Discontinuities of the derivatives (forward mode gives the a.e. derivative): everything
listed in ``water_refraction``; in addition the reflection step schedule
``REFL_STEPS_STEEP`` / ``REFL_STEPS_GRAZING`` decides the hit step, and hit / no-hit
(``diagnostics['refl_hit']``) switches between ``reflectionBottom`` and the cube map with
a jump in colour; ``REFL_HEIGHT_CUT`` and the texture bounds end rays discontinuously.
"""

from __future__ import annotations

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
from ..pipeline.texture import backend_types, mix, texmat_xy
from .normals import normal_fetches, with_maps_of
from .water_refraction import DEFINES as _REFRACTION_DEFINES
from .water_refraction import (
    Options,
    cubemap_reflection,
    fresnel_combine,
    gl_check_diagnostics,
    loop_positions,
    loop_R,
    options_of,
    outside_unit_square,
    reflect,
    refraction_blocks,
    refraction_failure_diagnostics,
    specular_highlight,
)

# the GL check (shaders_port.gl.compare) renders with diagnose=True: its GPU explanations
# (raymarch_texel_edge, fresnel_texel_edge, highlight_slope) come with the failure diagnostics
GL_CHECK_DIAGNOSE = True

# the one table from the GLSL file's #define names to the port's options (see ports.switches): those
# of water_refraction's blocks [2]-[6] and [8]; NOREFLECTION (block [7] skipped) is the
# water_refraction_noreflection variant of the other shader, not a switch of this port, and the
# mirror, the local cube map and the screen-space reflection replace block [7] there
DEFINES = {
    k: v
    for k, v in _REFRACTION_DEFINES.items()
    if k not in ("NOREFLECTION", "PLANAR_REFLECTION", "BOX_REFLECTION", "SSR_REFLECTION")
}

__all__ = ["render", "render_with_jacobian", "ShaderOutput"]


@dr.syntax
def raycast_reflection(m, P, R, C):
    """Block [7]'s loop. Returns the loop state after the last iteration."""
    current_position = m.Array3f(P.varyingVecWorldPosition)
    current_position_old = m.Array3f(current_position)
    olddepth = m.Float(0.0)
    s, t = texmat_xy(P.tex_matrix1, current_position)
    depthtex = P.worldYComponentReflection.sample(m, s, t)
    depth = m.Float(depthtex[0])
    noHit = m.Bool(True)  # width 1, widened by the loop (no width literal in a recording)
    done = m.Bool(False)
    i = m.UInt32(0)
    loop_fetches = m.UInt32(0)
    # plain locals: loop-condition variables become loop state (keep constants' AD out of it)
    REFL_LOOP_CAP = C.refl_loop_cap
    REFL_HEIGHT_CUT = dr.detach(C.refl_height_cut)  # only compared: no derivative
    while (i < REFL_LOOP_CAP) & ~done:
        current_position_old = m.Array3f(current_position)
        current_position += R
        texcoord_x, texcoord_y = texmat_xy(P.tex_matrix1, current_position)
        outside = (texcoord_x < 0) | (texcoord_x > 1) | (texcoord_y < 0) | (texcoord_y > 1)
        inside = ~outside
        depthtex = P.worldYComponentReflection.sample(m, texcoord_x, texcoord_y, inside)
        olddepth = dr.select(inside, depth, olddepth)
        depth = dr.select(inside, depthtex[0], depth)
        loop_fetches += dr.select(inside, m.UInt32(1), m.UInt32(0))
        hit = inside & (depth > current_position.y)
        noHit &= ~hit
        too_high = inside & ~hit & (current_position.y > REFL_HEIGHT_CUT)
        done = outside | hit | too_high
        i += 1
    return current_position, current_position_old, depth, olddepth, noHit, i, loop_fetches


# ---- failure diagnostics (not in the GLSL: extra outputs, the colour is unchanged) --------

REFL_EXIT_HIT, REFL_EXIT_OUTSIDE, REFL_EXIT_HEIGHT_CUT, REFL_EXIT_LOOP_CAP = 0.0, 1.0, 2.0, 3.0


def reflection_exit(m, P, C, loop_position, noHit):
    """How block [7]'s loop ended, per lane (``m.Float``): ``REFL_EXIT_HIT`` (0, a hit),
    ``REFL_EXIT_OUTSIDE`` (1, the ray left the reflection textures' [0, 1]^2: cube map),
    ``REFL_EXIT_HEIGHT_CUT`` (2, above ``REFL_HEIGHT_CUT``: cube map) or ``REFL_EXIT_LOOP_CAP``
    (3, ``REFL_LOOP_CAP`` steps without any of these: cube map). ``loop_position`` is the
    loop's last ``current_position`` (where the breaking test was made)."""
    p = dr.detach(loop_position)
    s, t = texmat_xy(P.tex_matrix1, p)
    outside = outside_unit_square(s, t)
    too_high = p.y > dr.detach(C.refl_height_cut)
    code = dr.select(
        outside, REFL_EXIT_OUTSIDE, dr.select(too_high, REFL_EXIT_HEIGHT_CUT, REFL_EXIT_LOOP_CAP)
    )
    return m.Float(dr.select(noHit, code, REFL_EXIT_HIT))


def _shade(m, P, C, diagnose: bool = False, opts: Options = Options()):
    # ---- [1]-[6]: as in water_refraction ----
    f = refraction_blocks(m, P, C, opts)
    vEye, vLight, vBumpTex, vBumpTexMore = f.vEye, f.vLight, f.vBumpTex, f.vBumpTexMore
    vRefraction, iterations, crossed, denominator = (
        f.vRefraction,
        f.iterations,
        f.crossed,
        f.denominator,
    )
    refraction_R, refracted_position = f.R, f.current_position

    # ---- [7] Reflection ----
    R = dr.normalize(reflect(m, -vEye, vBumpTexMore))
    R.y = dr.maximum(R.y, 0.001)
    R = dr.normalize(R)
    refl_dir = R  # kept for the diagnostics
    numsteps = mix(C.refl_steps_steep, C.refl_steps_grazing, 1.0 - R.y)
    stepsize = 1.0 / numsteps
    R *= stepsize
    (
        current_position,
        current_position_old,
        depth,
        olddepth,
        noHit,
        refl_iterations,
        refl_fetches,
    ) = raycast_reflection(m, P, loop_R(C, R), C)
    refl_loop_position = current_position  # kept for the diagnostics
    current_position, current_position_old = loop_positions(
        m, C, R, current_position, current_position_old, refl_iterations
    )
    # if (!noHit): interpolate, one step of zero-approximation
    cpoy = current_position_old.y
    cpy = current_position.y
    current_position = mix(
        current_position_old, current_position, (cpoy - olddepth) / (cpoy - cpy + depth - olddepth)
    )
    s, t = texmat_xy(P.tex_matrix1, current_position)
    hit_active = ~noHit
    vReflection_hit = (
        m.Array4f(*P.reflectionBottom.sample(m, s, t, hit_active), 1.0) * C.reflectColor
    )
    # else: no hit with reflection surface -> fetch colour from the cube map
    vReflection_sky = cubemap_reflection(m, P, R) * C.reflectColor
    vReflection = dr.select(noHit, vReflection_sky, vReflection_hit)

    vReflection = specular_highlight(
        m, P, vReflection, vBumpTex, vEye, vLight, C, opts.specular, f.slope_variance
    )
    gl_FragColor = fresnel_combine(m, P, vReflection, vRefraction, vEye, vBumpTex)
    fetches = normal_fetches(opts) + 1 + iterations + 1 + 1 + refl_fetches + 1 + 1
    bad = nonfinite_any(
        vEye,
        vLight,
        vBumpTex,
        vBumpTexMore,
        refraction_R,
        refracted_position,
        R,
        dr.select(noHit, refracted_position, current_position),
    )
    diagnostics = {
        "iterations": m.Float(iterations),
        "fetches": m.Float(fetches),
        "crossed": dr.select(crossed, 1.0, 0.0),
        "denominator": dr.abs(denominator),
        "refl_iterations": m.Float(refl_iterations),
        "refl_hit": dr.select(noHit, 0.0, 1.0),
        "nonfinite": dr.select(bad, 1.0, 0.0),
    }
    if f.refine_path is not None:
        diagnostics["refine_path"], diagnostics["refine_texel_edge"] = f.refine_path
    if diagnose:
        diagnostics.update(refraction_failure_diagnostics(m, P, C, f))
        diagnostics.update(gl_check_diagnostics(m, P, C, f, True, opts.specular))
        diagnostics["refl_exit"] = reflection_exit(m, P, C, refl_loop_position, noHit)
        d = dr.detach(refl_dir)
        diagnostics.update(
            {"refl_dir_x": m.Float(d.x), "refl_dir_y": m.Float(d.y), "refl_dir_z": m.Float(d.z)}
        )
    return gl_FragColor, diagnostics


def _frozen_shade(m, P, C, diagnose, opts):
    return _frame.call_frozen(
        ("water_reflection", diagnose, opts) + _frame.python_config(C),
        lambda m, P, C: _shade(m, P, C, diagnose, opts),
        m,
        P,
        C,
    )


def render(
    inputs: ShaderInputs,
    constants: Constants | None = None,
    *,
    backend: str | None = None,
    loop_ad: str = "replay",
    diagnose: bool = False,
    defines: tuple = (),
) -> ShaderOutput:
    """Render ``water_reflection`` compiled with ``defines`` (``#define`` names of
    :data:`DEFINES`: the switches of blocks [2], [5], [6] and [8]).

    Returns a :class:`ShaderOutput` as ``water_refraction.render`` does, with two more
    diagnostics: ``refl_iterations`` (reflection loop iterations) and ``refl_hit`` (1 where
    the reflection ray hit the geometry above the water, 0 where the cube map was used).
    ``fetches`` counts every texture2D/textureCube call: 4 normal map, 1 + ``iterations``
    depth, 1 refraction colour, 1 + (in-bounds reflection iterations) reflection depth, 1
    reflection colour (bottom texture or cube map), 1 Fresnel LUT. ``diagnose=True`` adds the
    failure diagnostics of ``water_refraction.refraction_failure_diagnostics``, ``refl_exit``
    (:func:`reflection_exit`) and ``refl_dir_x/y/z`` (the unit reflection direction after the
    clamp of ``R.y``, before the step scaling); extra outputs only, the colour is bit-identical.
    """
    opts = options_of(defines, "water_reflection", DEFINES)
    m = backend_types(backend)
    P = with_maps_of(m, prepare(inputs, m), opts)
    C = resolve_constants(m, constants if constants is not None else Constants(), loop_ad)
    with evaluated_loops_if(C.differentiable and loop_ad == "evaluated"):
        if _frame.USE_FROZEN and not C.differentiable:
            color, diag = _frozen_shade(m, P.shading_state(), C, diagnose, opts)
        else:
            color, diag = _shade(m, P, C, diagnose, opts)
        return finish_output(m, P, color, diag, "water_reflection")


def _frozen_tangents(m, P, C, params, opts):
    return _frame.call_frozen(
        ("water_reflection.tangents", opts) + _frame.python_config(C),
        lambda m, P, C, params: tangents(m, *_shade(m, P, C, False, opts), params),
        m,
        P,
        C,
        params,
    )


def render_with_jacobian(
    inputs: ShaderInputs,
    constants: Constants | None,
    names: list[str],
    *,
    backend: str | None = None,
    loop_ad: str = "replay",
    defines: tuple = (),
    lanes=None,
):
    """``(ShaderOutput, J)`` with ``J`` float32 (H, W, 3, len(names)): forward-mode derivatives
    of the linear-RGB colour w.r.t. the named scalars (see ``water_refraction``)."""
    opts = options_of(defines, "water_reflection", DEFINES)

    def shade_tangents(m, P, C, params, frozen):
        if frozen:
            return _frozen_tangents(m, P, C, params, opts)
        return tangents(m, *_shade(m, P, C, False, opts), params)

    return jacobian_passes(
        shade_tangents,
        "water_reflection",
        inputs,
        constants if constants is not None else Constants(),
        names,
        backend,
        loop_ad,
        lanes=lanes,
        maps=lambda m, P: with_maps_of(m, P, opts),
    )
