"""A user's fragment shader run after the user's own vertex shader, as OpenGL draws the pair.

:class:`UserVertex` holds a :class:`~shaders_port.spirv.vertex.VertexShader` and the grid it
runs on (``cells = (nx, nz)`` cells of two triangles over the water quad). For one frame
(:meth:`UserVertex.frame`) it

1. runs the vertex shader on every grid vertex (``spirv.vertex``);
2. rasterises the triangles from its ``gl_Position`` (``pipeline.interpolate``: clipping, the
   viewport, coverage, the depth test), so a displaced vertex moves the coverage and depth as
   GL's would; the water pixels are the covered ones;
3. interpolates each vertex output the fragment shader reads, perspective-correct, ``flat``
   (provoking vertex: the triangle's last) or ``noperspective`` by the *fragment* shader's
   qualifier, matched by name, else by an explicit ``layout(location = N)`` on both sides;
4. binds ``gl_FragCoord`` (pixel centre, window depth, ``1 / w``) and ``gl_FrontFacing``, and
   every uniform and sampler as for the fragment shader alone (``spirv.translated``);
5. where the fragment shader takes a derivative or an implicit-level mipmapped lookup, adds
   the helper lanes of each triangle's 2x2 quads (``pipeline.interpolate.quad_helpers``: the
   triangle's interpolants extrapolated to the helper's centre) and their
   :class:`~shaders_port.spirv.quads.Quads`.

The vertex shader's constants to fit are uniforms of its run, at the values of each render.
Their forward-mode derivatives come from the vertex run (``VertexShader.run``), carried
through the interpolation (``pipeline.interpolate.weight_tangents``: a moved vertex moves the
plane a pixel interpolates on) onto the varyings and ``gl_FragCoord``, the coverage held fixed
(each pixel keeps its triangle; which pixels a moved vertex covers changes in steps no
derivative sees).

A fragment input no vertex output feeds is refused (GL would not link the pair). The result
is a prepared frame (``pipeline.raster.Prepared``) whose raster is the grid's coverage (its
``world`` the interpolated grid position, the plane point under the displaced one) and the
fragment shader's bindings; :meth:`UserVertex.render` and :meth:`UserVertex.shade` run the
fragment shader on it as ``spirv.translated`` does on the study's quad.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections import OrderedDict

import drjit as dr
import numpy as np

from ..gl.grid import grid_renderer_class
from ..pipeline.frame import finish_output
from ..pipeline.interpolate import (
    Coverage,
    interpolate,
    interpolate_tangent,
    quad_helpers,
    rasterize_triangles,
    water_grid,
    weight_tangents,
)
from ..pipeline.raster import Raster, prepare
from ..pipeline.texture import backend_types
from . import engine_names as names_
from . import quads as _quads
from . import translated as spirv_port
from .vertex import ATTRIBUTES, VertexShader, explicit_locations, glsl_type, pointee_type

__all__ = ["UserVertex", "DEFAULT_CELLS"]

DEFAULT_CELLS = (64, 64)
_PER_PIXEL = ("varyingVecWorldPosition", "varyingVecEye", "varyingVecLight", "vTexCoord0",
              "vTexCoord1", "vTexCoord2", "vTexCoord3", "gl_FragCoord")  # fmt: skip
_FRAMES: OrderedDict = OrderedDict()  # the last few frames (a joint fit alternates scenes)
_UPLOADS = itertools.count(1)


def _lanes_of(m, a: np.ndarray, kind: str):
    """(N, ...) array -> the executor's nested lists of per-lane Dr.Jit values."""
    if a.ndim > 1:
        return [_lanes_of(m, a[:, i], kind) for i in range(a.shape[1])]
    if kind == "float":
        return m.Float(a.astype(np.float32))
    return (m.Int32 if kind == "int" else m.UInt32)(np.rint(a).astype(np.int64))


def _leaves(values: dict) -> list:
    """The scalars of resolved values (name -> value or tuple of values)."""
    return [x for v in values.values() for x in (v if isinstance(v, (tuple, list)) else (v,))]


def _numbers(values: dict) -> tuple:
    """Resolved values as Python floats (a cache key)."""
    return tuple(float(x[0]) if isinstance(x, dr.ArrayBase) else float(x) for x in _leaves(values))


class _Motion:
    """What the vertex shader's constants ``params`` move, for one frame's ``lanes`` at window
    pixels ``(x, y)``: ``douts[j]`` the outputs' per-vertex derivatives in ``params[j]``
    (``tangents`` of ``VertexShader.run``), ``weights[j]`` the interpolation weights'
    (``pipeline.interpolate.weight_tangents``, the coverage held fixed), ``deltas[j]`` the
    zero Dr.Jit scalar ``p - detach(p)`` that carries a derivative into a lane."""

    def __init__(self, clip, tangents, params, grid, lanes, x, y, inputs):
        self.vertices = np.asarray(grid.triangles, np.int64)[lanes.triangle]
        self.douts = [t[1] for t in tangents]
        self.weights = [
            weight_tangents(
                clip, t[0], grid.triangles, lanes.triangle, x, y, inputs.width, inputs.height
            )  # fmt: skip
            for t in tangents
        ]
        self.deltas = [p - dr.detach(p) for p in params]

    def varying(self, values, name: str, mode: str) -> list:
        """The derivatives (N, ...) of the output ``name`` (``values`` (V, ...)) interpolated
        by ``mode`` at the lanes, one per param."""
        key = "linear" if mode == "noperspective" else "smooth"
        return [
            interpolate_tangent(values, d[name], w[key], w["d" + key], self.vertices, mode)
            for d, w in zip(self.douts, self.weights)
        ]

    def lanes(self, m, value: np.ndarray, tangents: list, kind: str):
        """``value`` (N, ...) as the executor's lanes (``_lanes_of``), each float lane plus
        ``tangent * delta`` per param: the same numbers, with the derivatives attached."""
        if value.ndim > 1:
            return [self.lanes(m, value[:, i], [t[:, i] for t in tangents], kind)
                    for i in range(value.shape[1])]  # fmt: skip
        out = _lanes_of(m, value, kind)
        if kind != "float":
            return out
        for t, d in zip(tangents, self.deltas):
            if np.any(t):
                out = out + m.Float(np.asarray(t, np.float32)) * d
        return out


def _joined(cov: Coverage, helpers: Coverage) -> Coverage:
    """The covered pixels' lanes then the helper lanes (``mask`` None)."""
    fields = ("index", "triangle", "smooth", "linear", "depth", "inv_w", "front")
    cat = {f: np.concatenate([getattr(cov, f), getattr(helpers, f)]) for f in fields}
    return Coverage(mask=None, **cat)


def _kind(t: tuple) -> str:
    return t[2] if t[0] == "vec" else ("float" if t[0] == "mat" else t[0])


class UserVertex:
    """The user's vertex shader ``shader`` (a ``VertexShader``) on a grid of ``cells``."""

    def __init__(self, shader: VertexShader, cells=DEFAULT_CELLS):
        cells = tuple(int(c) for c in cells)
        if len(cells) != 2 or min(cells) < 1 or max(cells) > 1024:
            raise ValueError(f"fit.vertex_grid: {list(cells)} must be two cell counts in 1..1024")
        self.shader, self.cells = shader, cells

    @property
    def label(self) -> str:
        return self.shader.label

    @classmethod
    def from_file(cls, path, cells=DEFAULT_CELLS, defines=(), include_paths=(),
                  shared=False) -> "UserVertex":  # fmt: skip
        return cls(VertexShader.from_file(path, defines, include_paths, shared), cells)

    def grid(self, inputs):
        return water_grid(inputs.water_rect, inputs.normal_tile, self.cells)

    def with_constants(self, names) -> "UserVertex":
        """This vertex shader with the constants ``names`` (declared in its text) made uniforms
        bound to each run's values (``spirv.user_shader.UserShader`` finds them)."""
        return UserVertex(self.shader.with_constants(names), self.cells)

    def with_bindings(self, bindings: dict) -> "UserVertex":
        """This vertex shader with the declared ``bindings`` added (``VertexShader.
        with_bindings``)."""
        return UserVertex(self.shader.with_bindings(bindings), self.cells)

    # ---- one frame -------------------------------------------------------------------------
    def frame(self, m, inputs, spec, C=None, params=()):
        """``(P, bindings)``: the prepared frame of the grid's coverage and the fragment
        shader's bindings (see the module doc), the vertex shader's constants at their values
        in ``C`` (resolved values, ``C.values``: name -> executor value). ``params``: gradient-
        enabled size-1 Floats; those among the vertex shader's constants make every varying
        and ``gl_FragCoord`` carry its forward-mode derivatives in them, through the vertex
        shader and the interpolation, the coverage held fixed (a pixel keeps its triangle).
        Frames without such derivatives are remembered, the last eight."""
        values = {n: C.values[n] for n in self.shader.constants} if C is not None else {}
        moving = [p for p in params if any(x is p for x in _leaves(values))]
        P0 = prepare(inputs, m)
        key = (P0.upload, m.__name__, self.shader.source, self.shader.constants, self.cells,
               _numbers(values), tuple(sorted(self.shader.values.items())), spec.prepared_source(),
               spec.bindings, spec.engine)  # fmt: skip
        hit = None if moving else _FRAMES.get(key)
        if hit is not None:
            _FRAMES.move_to_end(key)
            return hit
        grid, study, run = self._run(m, P0, inputs, spec, values, moving)
        clip, outs = run[0], run[1]
        cov = rasterize_triangles(clip, grid.triangles, inputs.width, inputs.height)
        if cov.index.size == 0:
            raise ValueError(
                f"{self.label}: the vertex shader's triangles cover no pixel (check its "
                "gl_Position: clip space, projection * view * model * position)"
            )
        mod = spirv_port.module_of(spec)
        b = {k: v for k, v in study.items() if k not in _PER_PIXEL}
        b.update({n: b[t] for n, t in spec.bindings if t in b})  # a bound mipmapped sampler
        lanes, group = cov, None
        x, y = cov.index % inputs.width, inputs.height - 1 - cov.index // inputs.width
        if _quads.uses_quads(mod, {k: v for k, v in b.items() if k in mod.bound_names}):
            x, y, group, helpers = quad_helpers(cov, inputs.width, inputs.height)
            lanes = _joined(cov, helpers)
        motion = None
        if moving:
            motion = _Motion(clip, run[2], moving, grid, lanes, x, y, inputs)
        b.update(self._varyings(m, spec, lanes, grid, outs, motion))
        b.update(self._builtins(m, lanes, x, y, motion))
        for name, target in spec.bindings:
            if target in b:
                b[name] = b[target]
        b = {k: v for k, v in b.items() if k in mod.bound_names}
        if group is not None:
            b[_quads.QUADS_KEY] = _quads.quads_of_pixels(m, x, y, cov.index.size, group)
        hit = (self._prepared(m, P0, cov, grid, inputs), b)
        if not moving:
            _FRAMES[key] = hit
            while len(_FRAMES) > 8:
                _FRAMES.popitem(last=False)
        return hit

    def _run(self, m, P0, inputs, spec, values: dict, params=()):
        """``(grid, study bindings, VertexShader.run's result)`` of one frame ``P0``."""
        study = spirv_port.study_bindings(m, P0, inputs, spec.engine)
        for k in range(4):
            study[f"wave{k + 1}"] = [float(v) for v in np.asarray(inputs.waves[k], np.float32)]
        grid = self.grid(inputs)
        up = dict(spec.engine).get("up", "y")
        return grid, study, self.shader.run(m, inputs, grid, study, up, values, params)

    def motion(self, m, inputs, spec, C, params) -> list[float]:
        """For each of ``params`` (gradient-enabled scalars of ``C``, see :meth:`frame`): the
        largest |derivative| of a vertex's clip-space position (``gl_Position``) in it."""
        values = {n: C.values[n] for n in self.shader.constants}
        run = self._run(m, prepare(inputs, m), inputs, spec, values, params)[2]
        return [float(np.abs(t[0]).max()) for t in run[2]]

    def feeds(self, mod, source: str, label: str) -> dict:
        """Fragment input name -> the vertex output that feeds it (by name, else by an explicit
        ``layout(location = N)`` on both sides) for every ``in`` of the fragment module ``mod``
        (its GLSL ``source``, file name ``label``); ValueError naming an input nothing feeds."""
        vouts = self.shader.outputs
        by_loc = {v.location: n for n, v in vouts.items() if v.location is not None}
        places = explicit_locations(source, "in")
        out = {}
        for vid, ins in mod.defs.items():
            if ins.opname != "OpVariable" or ins.operands[0] != "Input":
                continue
            name = mod.binding_name(vid)
            if name.startswith("gl_"):
                continue
            src = name if name in vouts else by_loc.get(places.get(name, -1))
            if src is None:
                raise ValueError(
                    f"{label}: the fragment shader reads `in {name}`, which the vertex "
                    f"shader {self.label} does not write (its outputs: "
                    f"{', '.join(vouts) or 'none'}); write it there or name it alike"
                )
            out[name] = src
        return out

    def _varyings(self, m, spec, cov, grid, outs: dict, motion=None) -> dict:
        mod = spirv_port.module_of(spec)
        fed = self.feeds(mod, spec.source, spec.label)
        b = {}
        for vid, ins in mod.defs.items():
            if ins.opname != "OpVariable" or ins.operands[0] != "Input":
                continue
            name = mod.binding_name(vid)
            if name not in fed:
                continue
            src = fed[name]
            if src not in outs:
                raise ValueError(
                    f"{self.label}: the output {src} that {spec.label} reads is never written"
                )
            deco = mod.decorations.get(vid, {})
            mode = "flat" if "Flat" in deco else (
                "noperspective" if "NoPerspective" in deco else "smooth")  # fmt: skip
            t = pointee_type(mod, vid)
            kind = _kind(t)
            if kind != "float" and mode != "flat":
                raise ValueError(f"{spec.label}: the integer input {name} must be `flat`")
            value = interpolate(outs[src], cov, grid.triangles, mode)
            if motion is None:
                b[name] = _lanes_of(m, value, kind)
            else:
                b[name] = motion.lanes(m, value, motion.varying(outs[src], src, mode), kind)
        return b

    def _builtins(self, m, cov, x, y, motion=None) -> dict:
        """``gl_FragCoord`` and ``gl_FrontFacing`` of the lanes ``cov`` at window pixels
        ``(x, y)`` (int, y up); with ``motion`` (:class:`_Motion`) the depth and ``1 / w``
        carry their derivatives."""
        depth, inv_w = cov.depth, cov.inv_w
        if motion is None:
            z, w = m.Float(depth.astype(np.float32)), m.Float(inv_w.astype(np.float32))
        else:
            z = motion.lanes(m, depth, [t["ddepth"] for t in motion.weights], "float")
            w = motion.lanes(m, inv_w, [t["dinv_w"] for t in motion.weights], "float")
        return {
            "gl_FragCoord": [
                m.Float(x.astype(np.float32) + np.float32(0.5)),
                m.Float(y.astype(np.float32) + np.float32(0.5)),
                z,
                w,
            ],
            "gl_FrontFacing": m.Bool(cov.front),
        }

    def _prepared(self, m, P0, cov, grid, inputs):
        world = interpolate(grid.position, cov, grid.triangles, "smooth")
        base = world[:, [0, 2]] / inputs.normal_tile
        tex = np.stack([base + np.asarray(inputs.waves[k], np.float64) for k in range(4)])
        r = Raster(
            mask=cov.mask,
            index=cov.index,
            world=world.astype(np.float32),
            vec_eye=(np.asarray(inputs.viewpos, np.float64) - world).astype(np.float32),
            vec_light=(np.asarray(inputs.lightpos, np.float64) - world).astype(np.float32),
            texcoord=tex.astype(np.float32),
            width=inputs.width,
            height=inputs.height,
        )
        return dataclasses.replace(
            P0,
            raster=r,
            varyingVecWorldPosition=m.Array3f(r.world.T),
            varyingVecEye=m.Array3f(r.vec_eye.T),
            varyingVecLight=m.Array3f(r.vec_light.T),
            texcoord=[(m.Float(tex[k, :, 0]), m.Float(tex[k, :, 1])) for k in range(4)],
            upload=-next(_UPLOADS),  # negative: never a number of pipeline.raster.prepare's
        )

    # ---- renders -----------------------------------------------------------------------------
    def shade(self, m, inputs, spec, C, differentiate: bool = False, params=()):
        """``(P, colour Array3f, diag)`` of the fragment shader ``spec`` (a
        ``spirv.translated.ShaderSpec``) with resolved constants ``C`` on the grid's frame;
        ``params``: the gradient-enabled scalars of ``C`` (see :meth:`frame`)."""
        P, b = self.frame(m, inputs, spec, C, params)
        color, diag, _ = spirv_port.shade_lanes(m, P, b, spec, C, differentiate)
        return P, color, diag

    def render(self, inputs, spec, C, backend: str | None = None):
        """A ``ShaderOutput`` of ``spec`` after this vertex shader. Traced on every call, not
        replayed from a recording (``pipeline.frame.call_frozen``): the vertex stage's values
        freed by the garbage collector while a recording runs abort Dr.Jit."""
        m = backend_types(backend)
        P, color, diag = self.shade(m, inputs, spec, C)
        return finish_output(m, P, color, diag, spec.label)

    # ---- OpenGL ----------------------------------------------------------------------------
    def gl_class(self, base, inputs, up: str = "y", source: str | None = None, builtins=None):
        """``base`` (a ``GLRenderer`` class) drawing the grid with this vertex shader (its GLSL
        330 text, or ``source``: the file as written, whose compatibility built-in attributes
        ``builtins`` names, ``gl.grid``): its attributes and recognised uniforms set as
        :meth:`frame` binds them, in the world frame ``up``."""
        mod, grid = self.shader.module, self.grid(inputs)
        attributes, uniforms = {}, {}
        for vid, ins in mod.defs.items():
            if ins.opname != "OpVariable" or ins.operands[0] not in ("Input", "UniformConstant"):
                continue
            name = mod.binding_name(vid)
            meaning = names_.meaning_of(name, self.shader.bindings)
            if meaning in ATTRIBUTES:
                attributes[name] = names_.attribute_values(grid, meaning, up).astype(np.float32)
            elif meaning is not None:
                t = glsl_type(mod, mod.defs[ins.type_id].operands[1])
                v = np.asarray(names_.meaning_values(inputs, meaning, up), np.float32)
                if v.ndim == 2 and name in names_.TRANSPOSED and name not in self.shader.bindings:
                    v = v.T  # the engine's row-major upload (Urho3D's `p * cViewProj`)
                v = v.T if v.ndim == 2 else v[: t[1]]  # GL's column-major order
                uniforms[name] = np.ascontiguousarray(v).tobytes()
            elif name in self.shader.values:  # a `// @study value` pragma's
                uniforms[name] = np.float32(self.shader.values[name]).tobytes()
        text = self.shader.source if source is None else source
        return grid_renderer_class(base, text, attributes, grid.triangles, uniforms, builtins)
