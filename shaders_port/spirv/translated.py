"""A GLSL water fragment shader executed through SPIR-V on Dr.Jit types: rendered, and
differentiated in its constants, without a hand port.

A :class:`ShaderSpec` names the shader: its source in any dialect of ``spirv.dialects``
(compiled to SPIR-V by glslang there, ``#include`` files searched in its ``include_paths``),
its preprocessor names, the constants to set or differentiate and the bindings of its own
names. :func:`render` and :func:`render_with_jacobian` execute it (``spirv.execute``) on the
per-pixel inputs the hand ports get (``pipeline.raster.prepare``, the varyings the study's
``water.vert`` writes): the result is a :class:`~shaders_port.pipeline.frame.ShaderOutput`
like a port's, the Jacobian comes from the ports' forward-mode passes
(``pipeline.frame.jacobian_passes``), and both are replayed from a recording
(``pipeline.frame.call_frozen``). Its users: :class:`Translated`, a shipped variant whose
core GLSL file (:func:`builtin_spec`) runs in place of its hand port; a user's shader
(``spirv.user_shader``); a user's vertex shader's frame (``spirv.user_vertex``, which shades
its lanes with :func:`shade_lanes`).

Constants. Each is a one-line declaration ``const|uniform [precision] TYPE NAME = VALUE;``
(``float``, ``int``, ``vec2``, ``vec3``, ``vec4``) made a plain ``uniform`` before compiling,
line for line (:meth:`ShaderSpec.prepared_source`), so that the executor binds it to the
run's value; a uniform without initializer (one an engine sets), or one an ``#include``
declares, is bound as it is. The shipped shaders declare the constants of ``CONSTANT_SPECS``
(their GLSL names); a user's shader declares its own (``spirv.user_shader``).

Bindings. The shader's inputs, uniforms and samplers are bound by name: the study's GLSL
names (:data:`STUDY_INPUTS`: those of the shipped core shaders and the engines' names of
``spirv.engine_inputs``, in a Z-up world with the spec's ``engine`` option ``up = "z"``) bind
themselves; a ``ShaderSpec.bindings`` entry binds another name of the shader to one of them.
The colour is the shader's one ``vec4`` output (element 0 of an output array).

Loops. A loop whose trip count differs between lanes runs as ``spirv.loops`` says (its
passes checked against their bound); for the Jacobian it is replayed on detached values with
the derivatives attached after it when its differentiable state is affine, and otherwise
unrolled its largest trip count over the frame, found by a plain run first.

Diagnostics: ``fetches`` and ``iterations`` per pixel, counted by the executor from the
translated code (texture samples executed; loop bodies entered), ``nonfinite``, and
``discarded`` (1 where the shader ran ``discard``; such a pixel's colour is 0, the cleared
framebuffer's, and it leaves a model's scored mask) when the shader can discard.

Derivatives (``dFdx`` ...): the frame's lanes are then its covered pixels followed by the
helper pixels of their 2x2 quads (``spirv.quads``); only the covered pixels' results are kept.
"""

from __future__ import annotations

import dataclasses
import functools
import re
from dataclasses import dataclass, field

import drjit as dr
import numpy as np

from ..glsl_text import declared_constants, read_source
from ..inputs import CONSTANT_SPECS, Constants, ShaderInputs, normal_matrix
from ..pipeline import frame as _frame
from ..pipeline.frame import (
    ShaderOutput,
    finish_output,
    jacobian_passes,
    resolve_constants,
    tangents,
)
from ..pipeline.normal_maps import FRAME_MAPS
from ..pipeline.raster import prepare
from ..pipeline.texture import CLAMP, LINEAR, NEAREST, Texture2D, backend_types
from . import engine_inputs as _engine
from . import quads as _quads
from .execute import Executor
from .loops import check_passes
from .dialects import has_includes
from .module import Module, compile_fragment
from .ops import lift

__all__ = ["ShaderSpec", "STUDY_INPUTS", "builtin_spec", "render", "render_with_jacobian"]

# the study's inputs of a fragment shader, by the GLSL names of the shipped core shaders
STUDY_INPUTS = {
    "varyingVecWorldPosition": "varying vec3: world position on the water plane",
    "varyingVecEye": "varying vec3: water point -> camera (world units)",
    "varyingVecLight": "varying vec3: water point -> light (world units)",
    "vTexCoord0": "varying vec4: normal-map layer 0 coordinate ((x, z)/tile + wave1, 0, 1)",
    "vTexCoord1": "varying vec4: normal-map layer 1 coordinate",
    "vTexCoord2": "varying vec4: normal-map layer 2 coordinate",
    "vTexCoord3": "varying vec4: normal-map layer 3 coordinate",
    "gl_FragCoord": "built-in: window coordinate of the pixel centre",
    "refractionTexture": "sampler2D: top-down ground colour, linear RGB, bilinear, clamp",
    "worldYComponent": "sampler2D: top-down ground world y (.r), nearest, clamp",
    "normalMap": "sampler2D: wave normals 0.5 n + 0.5, bilinear, repeat",
    "reflectionTexture": "samplerCube: sky, linear RGB, bilinear, clamp",
    "fresnelLookup": "sampler2D: Fresnel LUT (N x 1; .r transmission, .g reflection), nearest",
    "worldYComponentReflection": "sampler2D: world y of geometry above the water, nearest",
    "reflectionBottom": "sampler2D: that geometry seen from below, bilinear, clamp",
    "sceneColor": "sampler2D: screen-space scene without the water, bilinear, clamp",
    "sceneDepth": "sampler2D: its window depth, nearest, clamp",
    "reflection_sampler": "sampler2D: mirrored-camera reflection, bilinear, clamp",
    "slopeMoments": "sampler2D: the normal map's slopes and their squares (sx, sz, sx^2, sz^2), "
    "mipmapped, trilinear, repeat (LEAN mapping, shaders_port.pipeline.normal_maps)",
    "heightMap": "sampler2D: the normal map's wave heights in tile lengths (.r), bilinear, repeat "
    "(parallax mapping, shaders_port.pipeline.normal_maps)",
    "uTextureMatrix0": "mat4: world -> (s, t) of the top-down textures",
    "uTextureMatrix1": "mat4: world -> (s, t) of the reflection textures",
    "uModelViewProjectionMatrix": "mat4: world -> clip space of the camera",
    "uModelViewProjectionMatrixInverse": "mat4: its inverse",
    "uNormalMatrix": "mat3: the camera's rotation",
    "o2v_projection_reflection": "mat4: world -> clip of the mirrored camera",
    "screenSize": "vec2: output width, height in pixels",
    "viewpos": "vec3: camera position",
    "lightpos": "vec3: light position",
    "lightcolor": "vec3: linear RGB of the highlight",
    # the inputs engines' water shaders read besides (``spirv.engine_inputs``)
    **{k: f"{t}: {what}" for k, (t, what) in _engine.ENGINE_INPUTS.items()},
}
# the study's inputs given in world space: their kind for a Z-up world (``engine_inputs.to_up``)
_WORLD = {
    "varyingVecWorldPosition": "vector",
    "varyingVecEye": "vector",
    "varyingVecLight": "vector",
    "viewpos": "vector",
    "lightpos": "vector",
    "uTextureMatrix0": "matrix",
    "uTextureMatrix1": "matrix",
    "uModelViewProjectionMatrix": "matrix",
    "o2v_projection_reflection": "matrix",
    "uModelViewProjectionMatrixInverse": "inverse",
    "uNormalMatrix": "rotation",
}
_DECL = (
    r"^(?P<head>\s*(?:const|uniform)\s+(?:(?:lowp|mediump|highp)\s+)?"
    r"(?P<type>float|int|vec2|vec3|vec4)\s+{name}\s*=\s*)"
)
_DECL_TAIL = r"(?P<value>[^;]*)(?P<tail>;.*)$"


@dataclass(frozen=True)
class ShaderSpec:
    """A fragment shader to execute: its GLSL ``source`` (a dialect of ``spirv.dialects``), a
    ``label`` (file name for messages and debug lines), the preprocessor names ``defines``,
    ``constants``: GLSL name -> ``CONSTANT_SPECS`` key or the user's name (each a declaration
    with an initializer, made a uniform, or a uniform without one), ``bindings``: shader name
    -> :data:`STUDY_INPUTS` name, ``include_paths``: folders of its ``#include`` files, and
    ``engine``: the options of ``spirv.engine_inputs`` (``up``, ``normal_map``) as pairs."""

    source: str
    label: str
    defines: tuple = ()
    constants: tuple = ()  # ((glsl name, key), ...)
    bindings: tuple = ()  # ((shader name, study name), ...)
    ints: tuple = field(default=())  # GLSL names of the integer constants
    include_paths: tuple = ()  # folders searched for its #include files
    engine: tuple = ()  # options of spirv.engine_inputs: (("up", "z"), ("normal_map", path))

    def prepared_source(self) -> str:
        """The source with every declared constant a uniform without initializer (line for
        line: the GLSL line numbers are kept)."""
        return _prepared(self.source, self.label, self.constants)


@functools.lru_cache(maxsize=64)
def _prepared(source: str, label: str, constants: tuple) -> str:
    """:meth:`ShaderSpec.prepared_source` (remembered: it is on every call's key)."""
    src = source
    for glsl, _ in constants:
        pat = re.compile(_DECL.format(name=re.escape(glsl)) + _DECL_TAIL, re.M)
        found = pat.search(src)
        bare = rf"^\s*uniform\s+(?:\w+\s+)?\w+\s+{re.escape(glsl)}\s*;"
        if found is None and re.search(bare, src, re.M):
            continue  # a uniform without initializer (the engine sets it): bound as it is
        if found is None and has_includes(src):
            continue  # declared in an #include (a uniform without initializer, checked there)
        if found is None:
            raise ValueError(
                f"{label}: no declaration `const|uniform <float|int|vec3|vec4> {glsl} "
                "= <value>;` of the constant to fit; declare it on one line"
            )
        decl = f"uniform {found['type']} {glsl}{found['tail']}"
        indent = found["head"][: len(found["head"]) - len(found["head"].lstrip())]
        src = src[: found.start()] + indent + decl + src[found.end() :]
    return src


def prepared_source(source: str, label: str, names) -> str:
    """``source`` with each constant of ``names`` (GLSL names declared on one line) a uniform
    without initializer, as :meth:`ShaderSpec.prepared_source` makes a fragment shader's."""
    return _prepared(source, label, tuple((n, n) for n in names))


_MODULES: dict = {}


def module_of(spec: ShaderSpec) -> Module:
    """The compiled, decoded module of ``spec`` (cached by source and defines)."""
    key = (spec.prepared_source(), spec.defines, spec.label, spec.include_paths)
    mod = _MODULES.get(key)
    if mod is None:
        spv = compile_fragment(key[0], spec.label, spec.defines, spec.include_paths)
        mod = Module(spv, label=spec.label)
        if len(_MODULES) > 64:
            _MODULES.clear()
        _MODULES[key] = mod
    return mod


def builtin_spec(shader: str, defines: tuple = ()) -> ShaderSpec:
    """The spec of a shipped shader (``water_refraction``, ``water_reflection``,
    ``water_baseline``): its core file and the ``CONSTANT_SPECS`` it declares."""
    src = read_source(shader, "frag", "core")
    names = declared_constants(src)
    consts = tuple((CONSTANT_SPECS[n][0], n) for n in names)
    return ShaderSpec(src, f"{shader}.frag", tuple(defines), consts)


def _columns(M) -> list:
    a = np.asarray(M, np.float32)
    return [[float(a[i, j]) for i in range(a.shape[0])] for j in range(a.shape[1])]


def study_bindings(m, P, inputs: ShaderInputs, engine: tuple = ()) -> dict:
    """The values of :data:`STUDY_INPUTS` for one prepared frame; ``engine``: the options of
    ``spirv.engine_inputs`` (with ``up`` 'z' the world-space values in a Z-up frame)."""
    b = _study_values(m, P, inputs)
    options = dict(engine)
    up = options.get("up", "y")
    if up != "y":
        for name, kind in _WORLD.items():
            if name in b and name.startswith("varying"):
                x, y, z = b[name]
                b[name] = [x, -z, y] if up == "z" else b[name]
            elif name in b:
                a = np.asarray(b[name], np.float64).T if kind != "vector" else b[name]
                v = _engine.to_up(up, a, kind)
                b[name] = _columns(v) if kind != "vector" else [float(np.float32(c)) for c in v]
    b.update(_engine.engine_values(m, inputs, options))
    for name, study in _engine.SAME_AS.items():
        if study in b:
            b[name] = b[study]
    return b


def _study_values(m, P, inputs: ShaderInputs) -> dict:
    """The values of the study's own inputs for one prepared frame, in its Y-up world."""
    r = P.raster
    b = {
        "varyingVecWorldPosition": [P.varyingVecWorldPosition[i] for i in range(3)],
        "varyingVecEye": [P.varyingVecEye[i] for i in range(3)],
        "varyingVecLight": [P.varyingVecLight[i] for i in range(3)],
        "refractionTexture": P.refractionTexture,
        "worldYComponent": P.worldYComponent,
        "normalMap": P.normalMap,
        "reflectionTexture": P.reflectionTexture,
        "fresnelLookup": P.fresnelLookup,
        "worldYComponentReflection": P.worldYComponentReflection,
        "reflectionBottom": P.reflectionBottom,
        "uTextureMatrix0": _columns(inputs.tex_matrix0),
        "uTextureMatrix1": _columns(inputs.tex_matrix1),
        "uModelViewProjectionMatrix": _columns(inputs.view_proj),
        "uModelViewProjectionMatrixInverse": _columns(
            np.linalg.inv(inputs.view_proj.astype(np.float64))
        ),
        "screenSize": [float(np.float32(inputs.width)), float(np.float32(inputs.height))],
        "viewpos": [float(v) for v in inputs.viewpos],
        "lightpos": [float(v) for v in inputs.lightpos],
        "lightcolor": [float(v) for v in inputs.lightcolor],
    }
    for k in range(4):
        s, t = P.texcoord[k]
        b[f"vTexCoord{k}"] = [s, t, 0.0, 1.0]
    col = (r.index % r.width).astype(np.float32)
    row = (r.index // r.width).astype(np.float32)
    clip = np.c_[r.world.astype(np.float64), np.ones(len(r.index))] @ inputs.view_proj.T
    b["gl_FragCoord"] = [
        m.Float(col + np.float32(0.5)),
        m.Float(np.float32(r.height) - row - np.float32(0.5)),
        m.Float((0.5 * clip[:, 2] / clip[:, 3] + 0.5).astype(np.float32)),
        m.Float((1.0 / clip[:, 3]).astype(np.float32)),
    ]
    try:
        b["uNormalMatrix"] = _columns(normal_matrix(inputs.view_proj))
    except ValueError:
        pass  # a view_proj that is no perspective times a rigid view: a shader reading it fails
    for name, field_, filt in (
        ("sceneColor", "scene_color", LINEAR),
        ("sceneDepth", "scene_depth", NEAREST),
        ("reflection_sampler", "reflection_color", LINEAR),
    ):
        if getattr(inputs, field_) is not None:
            b[name] = Texture2D.from_numpy(m, getattr(inputs, field_), filt, CLAMP)
    if inputs.reflection_view_proj is not None:
        b["o2v_projection_reflection"] = _columns(inputs.reflection_view_proj)
    return b


def constant_values(spec: ShaderSpec, C) -> dict:
    """GLSL name -> executor value of each declared constant, from resolved constants ``C``
    (``pipeline.frame.resolve_constants``, or any object with ``values`` keyed like ``spec``)."""
    out = {}
    for glsl, key in spec.constants:
        v = C.values[key]
        out[glsl] = list(v) if isinstance(v, tuple) else v
    return out


_BINDINGS: dict = {}


def frame_bindings(m, P, inputs, spec: ShaderSpec) -> dict:
    """Every value the shader may read on this frame: those of the study's inputs, and of the
    spec's bindings of other names to them (checked), that the module declares; not the
    constants. One dict per uploaded frame, module and bindings (a recorded kernel replays only
    for the same objects: measured, a new dict of equal values records again); nothing the
    module does not read (each Python number of a recording's arguments is checked on every
    replay)."""
    mod = module_of(spec)
    key = (P.upload, m.__name__, spec.bindings, spec.engine, mod.bound_names,
           _quads.uses_quads(mod, {}))  # fmt: skip
    hit = _BINDINGS.get(key)
    if hit is not None:
        return hit
    b = study_bindings(m, P, inputs, spec.engine)
    for name, frame_map in FRAME_MAPS.items():  # built only for a shader that reads them
        if name in mod.bound_names or any(s == name for _, s in spec.bindings):
            b[name] = frame_map(m, P)
    for name, study in spec.bindings:
        if study in STUDY_INPUTS and study not in b and name in mod.bound_names:
            raise ValueError(
                f"{spec.label}: {name} reads the study input {study}, which this frame has not "
                "built (a screen-space buffer or the mirrored camera: `study calibrate` renders "
                "them for a shader that reads them; else build the inputs with "
                "study.scene.baseline_inputs.with_baseline_inputs)"
            )
        if study not in b and study not in STUDY_INPUTS:
            raise ValueError(
                f"{spec.label}: the binding {name} = {study!r} names no study input the frame "
                f"has; the study's inputs: {', '.join(sorted(STUDY_INPUTS))}"
            )
        if study in b:
            b[name] = b[study]
    b = {k: v for k, v in b.items() if k in mod.bound_names}
    if _quads.uses_quads(mod, b):  # derivatives: the helper lanes of the frame's quads too
        b = _quads.study_quad_bindings(m, P, inputs, b, dict(spec.engine).get("up", "y"))
    if len(_BINDINGS) >= 8:
        _BINDINGS.pop(next(iter(_BINDINGS)))
    _BINDINGS[key] = b
    return b


def shade_lanes(m, P, b: dict, spec: ShaderSpec, C, differentiate=False, trips=None, info=None):
    """Run the shader on one frame's bindings ``b``: (colour Array3f, diagnostics dict of
    per-lane Floats, passes: loop header -> per-lane passes of each symbolic loop). Shapes are
    the frame's lanes; nothing here reads a value back, so it can be recorded (``dr.freeze``)
    unless a lane-dependent loop is unrolled without its ``trips``. ``info`` (a dict) gets
    ``unrolled``: whether a loop was unrolled for AD (it needed its trip count)."""
    b = dict(b)
    b.update(constant_values(spec, C))
    ex = Executor(module_of(spec), m, b, differentiate=differentiate, trips=trips)
    try:
        outs, counts, passes = ex.run(), dict(ex.counts), dict(ex.passes)
        discarded = ex.discarded
        counts.pop("discarded", None)
        if info is not None:
            info["unrolled"] = ex.unrolled
    finally:
        ex.release()
    color = [v for v in outs.values() if v is not None]
    if len(color) != 1:
        raise ValueError(f"{spec.label}: the shader must write exactly one vec4 output")
    color = color[0]
    if isinstance(color[0], (list, tuple)):  # an output array (`out vec4 fragData[1]`):
        color = color[0]  # its element 0, at location 0 (the one colour the study compares)
    color = m.Array3f(*(lift(m, c, "float") for c in color[:3]))
    diag = {
        "iterations": lift(m, counts["iterations"], "float"),
        "fetches": lift(m, counts["fetches"], "float"),
        "nonfinite": m.Float(0.0),
    }
    if discarded is not None:  # a discarded pixel keeps the cleared framebuffer's 0, as on GL
        color = dr.select(discarded, 0.0, color)
        diag["discarded"] = dr.select(discarded, 1.0, 0.0)
    return color, diag, passes


def _lanes(P):
    """What a recorded run gets of the prepared frame ``P``: its lanes and upload number, the
    rest left out (the shader reads its bindings; every argument of a recording is traversed
    on each replay)."""
    keep = ("varyingVecWorldPosition", "upload")
    return dataclasses.replace(
        P, **{f.name: None for f in dataclasses.fields(P) if f.name not in keep}
    )


def _key(spec: ShaderSpec, C, *extra) -> tuple:
    return ("spirv", spec.prepared_source(), spec.defines, spec.label, *extra) + (
        _frame.python_config(C)
    )


def _recorded(key: tuple, fn, m, P, *args):
    """``pipeline.frame.call_frozen``; a failure while recording (an unsupported instruction, an
    unbound name: an error of the shader) is raised as itself by tracing the call. With the
    frame's quads in the bindings (the last argument), the loops' per-lane passes are kept over
    the helper lanes too (their trip counts bound the unrolled loops that compute the helpers'
    values), so that width is an output's too."""
    quads = args[-1].get(_quads.QUADS_KEY) if args and isinstance(args[-1], dict) else None
    widths = (quads.lanes,) if quads is not None else ()
    try:
        return _frame.call_frozen(key, fn, m, P, *args, widths=widths)
    except RuntimeError as exc:
        if "frozen function" not in str(exc):
            raise
        return fn(m, P, *args)


def shade(m, P, inputs, spec: ShaderSpec, C, differentiate: bool = False, trips=None):
    """:func:`shade_lanes` on a prepared frame ``P`` (with its raster): (colour, diag)."""
    color, diag, _ = shade_lanes(m, P, frame_bindings(m, P, inputs, spec), spec, C,
                                 differentiate, trips)  # fmt: skip
    return color, diag


def trip_counts(m, P, inputs, spec: ShaderSpec, C) -> dict:
    """Loop header -> the largest number of passes through the loop's body over the frame's
    lanes, from a plain (recorded) run with constants ``C``."""

    def fn(m, P, C, b):
        return shade_lanes(m, P, b, spec, C)[2]

    b = frame_bindings(m, P, inputs, spec)
    with dr.suspend_grad():
        passes = _recorded(_key(spec, C, "passes"), fn, m, _lanes(P), C, b)
    check_passes(module_of(spec), passes, spec.label)
    return {k: int(dr.max(v)[0]) if dr.width(v) else 0 for k, v in passes.items()}


def render(
    inputs: ShaderInputs,
    constants: Constants | None = None,
    *,
    spec: ShaderSpec,
    backend: str | None = None,
    resolved=None,
) -> ShaderOutput:
    """Render ``spec`` on ``inputs`` with ``constants`` (the study's ``Constants``; or
    ``resolved``: already resolved values, e.g. a user shader's). Returns a ShaderOutput:
    ``color`` TensorXf (H, W, 3) linear RGB, ``mask``, ``diagnostics`` ``iterations``,
    ``fetches``, ``nonfinite`` (H, W). Replayed from a recording
    (``pipeline.frame.call_frozen``)."""
    m = backend_types(backend)
    P = prepare(inputs, m)
    C = resolved if resolved is not None else resolve_constants(m, constants or Constants())
    b = frame_bindings(m, P, inputs, spec)

    def fn(m, P, C, b):
        return shade_lanes(m, P, b, spec, C)

    color, diag, passes = _recorded(_key(spec, C), fn, m, _lanes(P), C, b)
    check_passes(module_of(spec), passes, spec.label)  # a loop stopped at its bound: an error
    return finish_output(m, P, color, diag, spec.label)


# configuration of a Jacobian (the constants it differentiates included) -> whether it unrolls
# a loop (then a plain run first finds the trip counts; a loop replayed on detached values
# needs none)
_NEEDS_TRIPS: dict = {}


def render_with_jacobian(
    inputs: ShaderInputs,
    constants: Constants | None,
    names: list[str],
    *,
    spec: ShaderSpec,
    backend: str | None = None,
    lanes=None,
):
    """``(ShaderOutput, J)`` with ``J`` float32 (H, W, 3, len(names)): the forward-mode
    derivatives of the colour in the ``CONSTANT_SPECS`` scalar names ``names`` (as the ports'
    ``render_with_jacobian``), through the executed SPIR-V. A lane-dependent loop whose
    differentiable state is affine (``v = v + X``, copies of such ``v``) runs on detached
    values with the derivatives attached after it (``spirv.loops``: the ports' 'replay');
    any other such loop is unrolled its largest trip count over the frame, found by a plain
    run first. Both recorded (``pipeline.frame.call_frozen``)."""
    constants = constants if constants is not None else Constants()
    m = backend_types(backend)
    P = prepare(inputs, m)
    b = frame_bindings(m, P, inputs, spec)

    def shade_tangents(m, P_, C, params, frozen):
        needs_key = _key(spec, C)
        trips = {}
        if _NEEDS_TRIPS.get(needs_key, True):
            trips = trip_counts(m, P, inputs, spec, resolve_constants(m, constants))
        config = ("trips", tuple(sorted(trips.items())))

        def fn(m, P, C, params, b):
            info: dict = {}
            color, diag, _ = shade_lanes(m, P, b, spec, C, True, trips, info)
            _NEEDS_TRIPS[needs_key] = info["unrolled"]
            return tangents(m, color, diag, params)

        if frozen:
            return _recorded(_key(spec, C, config), fn, m, _lanes(P_), C, params, b)
        return fn(m, P_, C, params, b)

    return jacobian_passes(
        shade_tangents, spec.label, inputs, constants, names, backend, "replay", lanes=lanes
    )


class Translated:
    """A shader variant (``shaders_port.variants.Variant``) whose ``render`` and
    ``render_with_jacobian`` execute its GLSL file through SPIR-V in place of its hand port;
    everything else (name, defines, constants it reads, ...) is the variant's."""

    def __init__(self, variant):
        self._variant = variant
        self._spec = builtin_spec(variant.shader, variant.defines)

    def __getattr__(self, name):
        return getattr(self._variant, name)

    def render(self, inputs, constants=None, backend: str | None = None, **kw):
        _no_port_options(kw)
        inputs = self._variant.prepare_inputs(inputs)
        return render(inputs, constants, spec=self._spec, backend=backend)

    def render_with_jacobian(
        self, inputs, constants, names, backend: str | None = None, lanes=None, **kw
    ):
        _no_port_options(kw)
        inputs = self._variant.prepare_inputs(inputs)
        return render_with_jacobian(
            inputs, constants, names, spec=self._spec, backend=backend, lanes=lanes
        )


def _no_port_options(kw: dict) -> None:
    if kw:
        raise ValueError(
            f"{', '.join(sorted(kw))}: an option of the hand ports (failure diagnostics, loop "
            "modes) that the shader executed through SPIR-V does not have"
        )
