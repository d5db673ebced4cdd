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
(``dr.freeze``; set ``USE_FROZEN = False`` to trace every call). Constants enter the
kernels as opaque float32 values, so traced and replayed renders are bit-identical.
"""
from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass

import drjit as dr
import numpy as np

from ._inputs import CONSTANT_SPECS, Constants, ShaderInputs
from ._raster import prepare
from ._texture import backend_types, clamp, gl_pow, mix, texmat_xy

__all__ = ["render", "render_with_jacobian", "ShaderOutput"]


# ---- blocks shared with water_reflection -----------------------------------------------

def eye_and_light(m, P):
    # ---- [1] Eye and light vectors ----
    vEye = dr.normalize(P.varyingVecEye)
    vLight = dr.normalize(P.varyingVecLight)
    return vEye, vLight


def normal_map_block(m, P, BumptexMult):
    # ---- [2] Normal map: average four layers, bump scaling ----
    vBumpTexA = m.Array3f(P.normalMap.sample(m, P.texcoord[0][0], P.texcoord[0][1]))
    vBumpTexB = m.Array3f(P.normalMap.sample(m, P.texcoord[1][0], P.texcoord[1][1]))
    vBumpTexC = m.Array3f(P.normalMap.sample(m, P.texcoord[2][0], P.texcoord[2][1]))
    vBumpTexD = m.Array3f(P.normalMap.sample(m, P.texcoord[3][0], P.texcoord[3][1]))
    vBumpTex = dr.normalize(2.0 * (vBumpTexA + vBumpTexB + vBumpTexC + vBumpTexD) - 4.0)
    vBumpTexMore = dr.normalize(vBumpTex * m.Array3f(1.0, BumptexMult, 1.0))
    return vBumpTex, vBumpTexMore


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
    crossed = dr.zeros(m.Bool, dr.width(depth))
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


def interpolate_crossing(m, P, current_position, current_position_old, depth, olddepth):
    # ---- [5] Interpolate the crossing ----
    cpoy = current_position_old.y
    cpy = current_position.y
    denominator = cpoy - cpy + depth - olddepth
    current_position = mix(current_position_old, current_position, (cpoy - olddepth) / denominator)
    s, t = texmat_xy(P.tex_matrix0, current_position)
    vRefraction = m.Array4f(*P.refractionTexture.sample(m, s, t), 1.0)
    return current_position, vRefraction, denominator


def attenuation(m, P, current_position, vRefraction, C):
    # ---- [6] Attenuation ----
    travelLength = dr.norm(current_position - P.varyingVecWorldPosition)
    travelLength = clamp(travelLength / C.attenuation_distance, 0.0, 1.0)
    vRefraction = mix(vRefraction, C.waterColor, travelLength)
    return vRefraction


def cubemap_reflection(m, P, R):
    """``textureCube(reflectionTexture, normalize(R) * vec3(1, -1, 1))`` as a vec4."""
    d = dr.normalize(R) * m.Array3f(1.0, -1.0, 1.0)
    return m.Array4f(*P.reflectionTexture.sample(m, d.x, d.y, d.z), 1.0)


def specular_highlight(m, P, vReflection, vBumpTex, vEye, vLight, C):
    # ---- [8] Specular highlight ----
    rLight = dr.dot(2.0 * vBumpTex, vLight) * vBumpTex - vLight
    spec = gl_pow(clamp(dr.dot(rLight, vEye), 0.0, 1.0), C.specular_exponent)
    specular = m.Array4f(spec * P.lightcolor[0], spec * P.lightcolor[1], spec * P.lightcolor[2], 1.0)
    vReflection += specular * C.specular_strength
    return vReflection


def fresnel_combine(m, P, vReflection, vRefraction, vEye, vBumpTex):
    # ---- [9] Fresnel combine ----
    NdotV = clamp(dr.dot(vEye, vBumpTex), 0.0, 1.0)
    FresnelCoeffs = P.fresnelLookup.sample(m, NdotV, m.Float(0.5))
    return vReflection * FresnelCoeffs[1] + vRefraction * FresnelCoeffs[0]


# ---- output, constants, loop mode, Jacobian ----------------------------------------------

@dataclass
class ShaderOutput:
    """One rendered frame.

    Attributes:
        color: TensorXf (H, W, 3) linear RGB (float32); 0 off the water and where the shader
            produced a non-finite value (see ``diagnostics['nonfinite']``).
        mask: TensorXf (H, W), 1.0 on water pixels else 0.0.
        diagnostics: dict name -> TensorXf (H, W), 0 off the water.
    """

    color: object
    mask: object
    diagnostics: dict
    lanes: object = dataclasses.field(default=None, repr=False)  # Array3f colour of the water
    # pixels in raster order (differentiable; used by render_with_jacobian)

    def numpy(self) -> dict:
        """``{'color': (H, W, 3), 'mask': (H, W), <diagnostic>: (H, W)}`` float32 NumPy arrays."""
        out = {"color": np.asarray(self.color.numpy(), dtype=np.float32),
               "mask": np.asarray(self.mask.numpy(), dtype=np.float32)}
        out.update({k: np.asarray(v.numpy(), dtype=np.float32) for k, v in self.diagnostics.items()})
        return out


@dataclass
class _Resolved:
    differentiable: bool
    values: dict

    def __getattr__(self, name):
        try:
            return self.__dict__["values"][name]
        except KeyError:
            raise AttributeError(name) from None


def resolve_constants(m, constants: Constants, loop_ad: str = "replay") -> _Resolved:
    """Validate ``constants`` and return them as Python floats / size-1 ``m.Float`` (names as in
    ``Constants`` plus ``waterColor`` / ``reflectColor`` as ``m.Array4f``)."""
    if not isinstance(constants, Constants):
        raise TypeError(f"expected Constants, got {type(constants).__name__}")
    constants.validate()
    vals, diff = {}, False

    def conv(name, x):
        nonlocal diff
        if isinstance(x, dr.ArrayBase):
            if dr.width(x) != 1:
                raise ValueError(f"constant {name}: a Dr.Jit value must have size 1, got {dr.width(x)}")
            v = float(np.asarray(dr.detach(x).numpy()).ravel()[0])
            lo, hi = CONSTANT_SPECS[name][3]
            if not (np.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"constant {name} = {v!r} is not finite or outside [{lo}, {hi}]")
            diff = diff or dr.grad_enabled(x)
            return x if type(x) is m.Float else m.Float(x)
        # float32 arithmetic, as a GLSL uniform / const; opaque so that a traced and a frozen
        # render compute the same (no literal folding) and new values reuse compiled kernels
        return dr.opaque(m.Float, float(np.float32(x)))

    for name, (glsl, kind, _, _) in CONSTANT_SPECS.items():
        v = getattr(constants, name)
        if kind.endswith("int"):
            if isinstance(v, dr.ArrayBase):
                raise TypeError(f"constant {name} ({glsl}) is an integer loop cap; pass a Python int")
            vals[name] = int(v)
        elif kind.endswith("vec4"):
            vals[name] = tuple(conv(name, x) for x in v)
        else:
            vals[name] = conv(name, v)
    if loop_ad not in ("replay", "evaluated"):
        raise ValueError(f"loop_ad must be 'replay' or 'evaluated', got {loop_ad!r}")
    vals["loop_ad"] = loop_ad
    vals["waterColor"] = m.Array4f(*vals["water_color"])
    vals["reflectColor"] = m.Array4f(*vals["reflect_color"])
    return _Resolved(diff, vals)


class evaluated_loops_if:
    """Context manager: turn ``JitFlag.SymbolicLoops`` off while active if ``cond`` (restored after)."""

    def __init__(self, cond: bool):
        self.cond = cond

    def __enter__(self):
        self.old = dr.flag(dr.JitFlag.SymbolicLoops)
        if self.cond:
            dr.set_flag(dr.JitFlag.SymbolicLoops, False)
        return self

    def __exit__(self, *exc):
        dr.set_flag(dr.JitFlag.SymbolicLoops, self.old)
        return False


def finish_output(m, P, color, diag: dict, shader: str) -> ShaderOutput:
    """Flag non-finite lanes, scatter lanes into (H, W) images, warn if any pixel was non-finite."""
    r = P.raster
    n = r.width * r.height
    nonfinite = ~(dr.isfinite(color.x) & dr.isfinite(color.y) & dr.isfinite(color.z))
    if "nonfinite" in diag:  # intermediate vectors whose NaN a clamp or a lookup can hide
        nonfinite |= diag["nonfinite"] > 0
    dr.eval(color, nonfinite, {k: v for k, v in diag.items() if k != "nonfinite"})  # one kernel
    idx = m.UInt32(r.index.astype(np.uint32))
    flat = dr.zeros(m.Float, 3 * n)
    lanes = m.Array3f(*(dr.select(nonfinite, 0.0, color[c]) for c in range(3)))
    for c in range(3):
        dr.scatter(flat, lanes[c], 3 * idx + c)
    diag = dict(diag)
    diag["nonfinite"] = dr.select(nonfinite, 1.0, 0.0)
    images = {}
    for k, v in diag.items():
        img = dr.zeros(m.Float, n)
        dr.scatter(img, m.Float(dr.detach(v)), idx)
        images[k] = m.TensorXf(img, shape=(r.height, r.width))
    count = int(dr.sum(diag["nonfinite"])[0]) if dr.width(diag["nonfinite"]) else 0
    if count:
        warnings.warn(f"{shader}: {count} water pixel(s) were non-finite (NaN/inf) and set to 0; "
                      "see diagnostics['nonfinite'] (e.g. a degenerate normal from bumptex_mult "
                      "or a zero-length vector)", RuntimeWarning, stacklevel=3)
    mask = m.TensorXf(m.Float(r.mask.ravel().astype(np.float32)), shape=(r.height, r.width))
    return ShaderOutput(m.TensorXf(flat, shape=(r.height, r.width, 3)), mask, images, lanes)


def _parse_name(name: str):
    if name.endswith("]") and "[" in name:
        base, idx = name[:-1].split("[", 1)
        if base in ("water_color", "reflect_color") and idx in ("0", "1", "2", "3"):
            return base, int(idx)
    elif name in CONSTANT_SPECS and not CONSTANT_SPECS[name][1].endswith(("int", "vec4")):
        return name, None
    raise ValueError(f"cannot differentiate with respect to {name!r}: use a float key of "
                     "CONSTANT_SPECS or 'water_color[i]' / 'reflect_color[i]' (i = 0..3)")


def tangents(m, color, diag: dict, params: list):
    """Forward-mode passes of one shaded frame: ``(colour lanes Array3f, diag, grads)``, where
    ``grads[j]`` is the Array3f derivative of the colour lanes w.r.t. ``params[j]``. The graph is
    kept between passes and the gradients cleared; non-finite lanes get colour and derivative 0."""
    bad = ~(dr.isfinite(color.x) & dr.isfinite(color.y) & dr.isfinite(color.z))
    bad |= diag["nonfinite"] > 0
    lanes = m.Array3f(*(dr.select(bad, 0.0, color[c]) for c in range(3)))
    keep = dr.ADFlag.ClearInterior | dr.ADFlag.ClearInput
    grads = []
    for p in params:
        for q in params:
            dr.clear_grad(q)
        dr.clear_grad(lanes)
        dr.set_grad(p, 1.0)
        grads.append(m.Array3f(dr.forward_to(lanes, flags=keep)))
    return color, {k: dr.detach(v) for k, v in diag.items()}, grads


def jacobian_passes(shade_tangents, shader: str, inputs: ShaderInputs, constants: Constants,
                    names: list[str], backend: str, loop_ad: str):
    """Shared driver of ``render_with_jacobian``: every named scalar becomes a gradient-enabled
    size-1 Float; ``shade_tangents(m, P, C, params, frozen)`` shades once and runs one
    forward-mode pass per name (see :func:`tangents`), replayed from recorded kernels
    (``dr.freeze``) in ``loop_ad='replay'`` mode. Returns ``(ShaderOutput, J (H, W, 3, k))``."""
    m = backend_types(backend)
    if not names:
        raise ValueError("names is empty: give at least one constant to differentiate")
    changes, params = {}, []
    for name in names:
        base, idx = _parse_name(name)
        cur = changes.get(base, getattr(constants, base))
        if idx is None:
            p = m.Float(float(dr.detach(cur)[0]) if isinstance(cur, dr.ArrayBase) else float(cur))
            changes[base] = p
        else:
            comps = list(cur)
            x = comps[idx]
            p = m.Float(float(dr.detach(x)[0]) if isinstance(x, dr.ArrayBase) else float(x))
            comps[idx] = p
            changes[base] = tuple(comps)
        dr.enable_grad(p)
        params.append(p)
    P = prepare(inputs, m)
    C = resolve_constants(m, constants.replace(**changes), loop_ad)
    try:
        with evaluated_loops_if(loop_ad == "evaluated"):
            frozen = USE_FROZEN and loop_ad == "replay"
            color, diag, grads = shade_tangents(m, P.shading_state() if frozen else P, C, params, frozen)
            dr.eval(color, diag, grads)  # primal and all tangents together
    finally:
        for p in params:
            dr.disable_grad(p)
    out = finish_output(m, P, dr.detach(color), diag, shader)
    r = P.raster
    J = np.zeros((r.width * r.height, 3, len(names)), dtype=np.float32)
    for j, g in enumerate(grads):
        J[r.index, :, j] = np.asarray(g.numpy(), dtype=np.float32).T
    return out, J.reshape(r.height, r.width, 3, len(names))


def _raster_index(out: ShaderOutput) -> np.ndarray:
    """Flat pixel indices of the lanes of ``out`` (water pixels in raster order)."""
    return np.flatnonzero(np.asarray(out.mask.numpy()).ravel() > 0.5)


def nonfinite_any(*vectors):
    """Bool per lane: some component of some Array3f in ``vectors`` is NaN or infinite."""
    bad = None
    for v in vectors:
        b = ~(dr.isfinite(v.x) & dr.isfinite(v.y) & dr.isfinite(v.z))
        bad = b if bad is None else bad | b
    return bad


# ---- the shader ---------------------------------------------------------------------------

@dataclass
class Refracted:
    """What blocks [1]-[6] hand to the rest of either shader (names as in the GLSL)."""

    vEye: object
    vLight: object
    vBumpTex: object
    vBumpTexMore: object
    R: object                  # the scaled refraction step vector
    current_position: object   # the interpolated crossing
    vRefraction: object        # attenuated refraction colour (vec4)
    iterations: object
    crossed: object
    denominator: object


def refraction_blocks(m, P, C) -> Refracted:
    """Blocks [1]-[6], shared by ``water_refraction`` and ``water_reflection`` (the seed's
    section 3: "very similar to the previous one")."""
    vEye, vLight = eye_and_light(m, P)
    vBumpTex, vBumpTexMore = normal_map_block(m, P, C.bumptex_mult)
    R = refraction_vector(m, vEye, vBumpTexMore, C)
    current_position, current_position_old, depth, olddepth, iterations, crossed = \
        raycast_ground(m, P, loop_R(C, R), C.loop_cap)
    current_position, current_position_old = loop_positions(
        m, C, R, current_position, current_position_old, iterations)
    current_position, vRefraction, denominator = interpolate_crossing(
        m, P, current_position, current_position_old, depth, olddepth)
    vRefraction = attenuation(m, P, current_position, vRefraction, C)
    return Refracted(vEye, vLight, vBumpTex, vBumpTexMore, R, current_position, vRefraction,
                     iterations, crossed, denominator)


def _shade(m, P, C, reflection: bool):
    f = refraction_blocks(m, P, C)
    vEye, vLight, vBumpTex, vBumpTexMore = f.vEye, f.vLight, f.vBumpTex, f.vBumpTexMore
    R, current_position, vRefraction = f.R, f.current_position, f.vRefraction
    iterations, crossed, denominator = f.iterations, f.crossed, f.denominator
    fetches = 4 + 1 + iterations + 1
    bad = nonfinite_any(vEye, vBumpTex, vBumpTexMore, R, current_position)
    if reflection:
        # ---- [7] Reflection ----
        R = dr.normalize(reflect(m, -vEye, vBumpTexMore))
        R.y = dr.maximum(R.y, 0.001)
        vReflection = cubemap_reflection(m, P, R) * C.reflectColor
        vReflection = specular_highlight(m, P, vReflection, vBumpTex, vEye, vLight, C)
        gl_FragColor = fresnel_combine(m, P, vReflection, vRefraction, vEye, vBumpTex)
        fetches = fetches + 2
        bad |= nonfinite_any(R, vLight)
    else:
        gl_FragColor = vRefraction
    diagnostics = {"iterations": m.Float(iterations), "fetches": m.Float(fetches),
                   "crossed": dr.select(crossed, 1.0, 0.0), "denominator": dr.abs(denominator),
                   "nonfinite": dr.select(bad, 1.0, 0.0)}
    return gl_FragColor, diagnostics


# Plain (non-differentiable) renders replay recorded kernels instead of re-tracing the shader
# (``dr.freeze``); a change of loop caps, shader variant or input sizes records anew.
USE_FROZEN = True
_frozen_shade = dr.freeze(lambda m, P, C, reflection: _shade(m, P, C, reflection))


def render(inputs: ShaderInputs, constants: Constants | None = None, *, reflection: bool = True,
           backend: str = "llvm", loop_ad: str = "replay") -> ShaderOutput:
    """Render ``water_refraction`` (``reflection=False``: the ``NOREFLECTION`` variant).

    Returns a :class:`ShaderOutput`: ``color`` TensorXf (H, W, 3) linear RGB, 0 off the
    water; ``mask`` TensorXf (H, W); ``diagnostics`` TensorXf (H, W) each: ``iterations``
    (raycast loop iterations), ``fetches`` (texture2D/textureCube calls of the shader),
    ``crossed`` (1 if the floor was crossed within ``LOOP_CAP``), ``denominator``
    (``|cpoy - cpy + depth - olddepth|``), ``nonfinite`` (1 where the colour or an intermediate
    vector -- vEye, vBumpTex, vBumpTexMore, R, the interpolated position, and with reflection
    vLight -- was non-finite: GLSL's clamp and texture lookups can turn a NaN into a finite
    colour). ``loop_ad`` matters only for gradient-enabled constants (see the module doc).
    """
    m = backend_types(backend)
    P = prepare(inputs, m)
    C = resolve_constants(m, constants if constants is not None else Constants(), loop_ad)
    with evaluated_loops_if(C.differentiable and loop_ad == "evaluated"):
        if USE_FROZEN and not C.differentiable:
            color, diag = _frozen_shade(m, P.shading_state(), C, reflection)
        else:
            color, diag = _shade(m, P, C, reflection)
        return finish_output(m, P, color, diag, "water_refraction")


_frozen_tangents = dr.freeze(lambda m, P, C, params, reflection:
                             tangents(m, *_shade(m, P, C, reflection), params))


def render_with_jacobian(inputs: ShaderInputs, constants: Constants | None, names: list[str], *,
                         reflection: bool = True, backend: str = "llvm", loop_ad: str = "replay"):
    """Render and return ``(ShaderOutput, J)``, ``J`` float32 (H, W, 3, len(names)).

    ``J[..., j]`` is the forward-mode derivative of the linear-RGB colour with respect to
    the scalar ``names[j]`` (a scalar key of ``CONSTANT_SPECS`` or ``"water_color[i]"`` /
    ``"reflect_color[i]"``), one AD pass per name; zero off the water and on non-finite
    pixels. ``loop_ad``: 'replay' (default; symbolic loops, loop positions differentiated as
    ``start + i R``) or 'evaluated' (AD through the unrolled loop in evaluated mode).
    """
    def shade_tangents(m, P, C, params, frozen):
        if frozen:
            return _frozen_tangents(m, P, C, params, reflection)
        return tangents(m, *_shade(m, P, C, reflection), params)
    return jacobian_passes(shade_tangents, "water_refraction", inputs,
                           constants if constants is not None else Constants(), names, backend, loop_ad)
