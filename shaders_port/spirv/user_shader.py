"""A user's own GLSL water shader: its declaration, its renders and derivatives through SPIR-V,
and its constants written back into its file.

The shader is a GLSL fragment shader in any dialect of ``spirv.dialects`` (GLSL 1.10-4.60,
GLSL ES 1.00-3.20; ``#include`` files searched in ``include_paths``, preprocessor names
``defines``) that runs after the study's ``water.vert`` (so it reads the study's varyings,
:data:`spirv.translated.STUDY_INPUTS`) or after the user's own vertex shader
(``spirv.user_vertex``). Its *declaration* says which constants to fit and what
its own names of inputs mean, either as pragmas in the file::

    // @study constant FOG_DENSITY 0.01 4.0      (a constant to fit and its range)
    // @study constant uWaterTint 0.0 1.0 0.3    (... and its start value: a bare uniform)
    // @study bind waterNormals normalMap        (the shader's sampler -> a study input)
    // @study normal n world                     (the variable holding the surface normal)

or as a table (an experiment's TOML), ``{"constants": {"FOG_DENSITY": [0.01, 4.0]},
"bindings": {"waterNormals": "normalMap"}}``; the table adds to and overrides the pragmas.
Every constant is a one-line declaration (``spirv.declaration``), ``float``, ``vec2``,
``vec3`` or ``vec4``, in the fragment shader's file, in the vertex shader's (whose ``constant``
pragmas count too) or in both (one constant, as GL links a uniform of one name): with an
initializer, ``const float FOG_DENSITY = 0.35;`` or ``uniform float FOG_DENSITY = 0.35;``
(desktop GLSL 1.20 and later), whose value is the start value; or a uniform without one,
``uniform float FOG_DENSITY;``, as an engine's material sets it (GLSL ES has no uniform
initializers), whose start value the declaration gives (``LOW HIGH START``; a vector's START
is one number or its components joined by commas, ``0.1,0.2,0.3``). Written back
(:meth:`UserShader.written`), a bare uniform gets the fitted value as an initializer where its
dialect allows one (desktop GLSL 1.20 and later) and is left as it is otherwise (GLSL 1.10,
GLSL ES): the fitted value is then only in ``constants.json`` and the binding sheets, for the
engine to set; the GL check sets it as a uniform. The engine targets are made from the text
with no uniform initializer (``written(values, uniform_initializers=False)``). The GL check
runs the file as ``spirv.gl_run`` chooses (as written on a context of its dialect, or its
core-profile translation).
Every problem is refused by :meth:`UserShader.validate` with a message naming it: a constant
without such a declaration, a range that is empty or excludes the start value, a binding to a
name that is not a study input, a bound name the shader does not use, a sampler or uniform the
shader reads that is neither a study input nor bound (at the first render).

Values are dicts ``{GLSL name: float | tuple}``; scalar names of vector components are
``NAME[i]``. :meth:`UserShader.written` is the file's text with the values in place of the
initializers, byte for byte the same elsewhere; :meth:`UserShader.vertex_written` the vertex
shader file's. The derivatives in the vertex shader's constants go through its per-vertex run
and the interpolation, the coverage held fixed (``spirv.user_vertex.UserVertex.frame``).
"""

from __future__ import annotations

import copy
import hashlib
import re
import types
from pathlib import Path

import drjit as dr
import numpy as np

from ..pipeline.frame import jacobian_output, tangents
from ..pipeline.raster import prepare
from ..pipeline.texture import backend_types
from . import dialects, gl_run
from . import engine_inputs as _engine
from . import translated as spirv_port
from .declaration import BARE, UserConstant, declared, find_constants, written_text
from .declaration import initialized_uniforms, split_bindings, without_initializers
from .module import referenced
from .support import check_supported
from .vertex import normal_pragma, value_pragma

__all__ = ["UserShader", "UserConstant"]

_PRAGMA = re.compile(r"^\s*//\s*@study\s+(?P<verb>\S+)\s*(?P<args>.*?)\s*$", re.M)


class UserShader:
    """A user's fragment shader file with its declaration (see the module doc)."""

    def __init__(self, source: str, label: str, declaration: dict | None = None, path=None,
                 defines=(), include_paths=(), vertex=None):  # fmt: skip
        # vertex: the user's own vertex shader (``spirv.user_vertex.UserVertex``), or None for
        # the study's water.vert
        self.source, self.label, self.path, self.vertex = source, label, path, vertex
        self.defines, self.include_paths = tuple(defines), tuple(str(p) for p in include_paths)
        self.dialect = dialects.detect(source, label, dialects.version_define(self.defines))
        ranges, bindings, self.engine = {}, {}, {"up": "y", "normal_map": None}
        self.values = values = {}  # `value` pragmas: uniforms the engine sets, not fitted
        self.normal = None  # `normal` pragma: (variable holding the surface normal, its frame)
        for m in _PRAGMA.finditer(source):
            args = m["args"].split()
            line = source.count("\n", 0, m.start()) + 1
            where = f"{label}:{line}"
            if m["verb"] == "constant" and len(args) in (3, 4):
                try:
                    ranges[args[0]] = (float(args[1]), float(args[2]), *args[3:])
                except ValueError:
                    msg = "`// @study constant NAME LOW HIGH [START]`"
                    raise ValueError(f"{where}: {msg}") from None
            elif m["verb"] == "bind" and len(args) == 2:
                bindings[args[0]] = args[1]
            elif m["verb"] in ("up", "normal_map") and len(args) == 1:
                self.engine[m["verb"]] = args[0]
            elif m["verb"] == "value" and len(args) == 2:
                values.update([value_pragma(args, where)])
            elif m["verb"] == "normal" and len(args) in (1, 2):
                self.normal = normal_pragma(args, where)
            else:
                raise ValueError(
                    f"{where}: unknown pragma `// @study {m['verb']} {m['args']}`; write "
                    "`// @study constant NAME LOW HIGH [START]`, `// @study bind NAME "
                    "STUDY_INPUT`, `// @study value NAME V[,V...]`, `// @study up z` or "
                    "`// @study normal_map FILE` or `// @study normal NAME [world|tangent]`"
                )
        decl = dict(declaration or {})
        if "normal" in decl:
            self.normal = normal_pragma(str(decl.pop("normal")).split(), f"{label}: normal")
        self.engine.update({k: decl.pop(k) for k in ("up", "normal_map") if k in decl})
        self._declared_values(dict(decl.pop("values", {})), vertex)
        unknown = set(decl) - {"constants", "bindings"}
        if unknown:
            raise ValueError(
                f"{label}: unknown declaration key(s) {sorted(unknown)}; "
                "use 'constants', 'bindings', 'values', 'normal', 'up' and 'normal_map'"
            )
        for name, r in dict(decl.get("constants", {})).items():
            if not (isinstance(r, (list, tuple)) and len(r) in (2, 3)):
                raise ValueError(
                    f"{label}: constants.{name} must be [low, high] or [low, high, start], "
                    f"got {r!r}"
                )
            ranges[name] = (float(r[0]), float(r[1]), *r[2:])
        bindings.update(self._declared_bindings(dict(decl.get("bindings", {}))))
        self.bindings = bindings
        self.constants = self._constants(self._with_vertex_pragmas(ranges, decl))
        self._vertex_constants()
        self._initialized_uniforms()
        self._engine_options(path)
        self.validate()

    @classmethod
    def from_file(cls, path, declaration: dict | None = None, defines=(), include_paths=(),
                  vertex=None):  # fmt: skip
        """The shader of the file ``path``; its ``#include`` s are searched in its folder, then
        in ``include_paths``; ``vertex``: the user's vertex shader (``UserVertex``) or None."""
        p = Path(path)
        if not p.is_file():
            raise ValueError(f"fit.shader: no file {str(p)!r}")
        incs = (str(p.resolve().parent), *include_paths)
        return cls(p.read_text(encoding="utf-8"), p.name, declaration, p, defines, incs, vertex)

    def _with_vertex_pragmas(self, ranges: dict, decl: dict) -> dict:
        """``ranges`` (the fragment file's pragmas and the table's) with the vertex file's
        ``constant`` pragmas; the table overrides either file's, the two files must agree."""
        v = self.vertex.shader if self.vertex is not None else None
        if v is None or not v.ranges:
            return ranges
        table = set(dict(decl.get("constants", {})))
        out = dict(ranges)
        for name, (r, where) in v.ranges.items():
            if name in table:
                continue
            if name in out and tuple(out[name]) != tuple(r):
                raise ValueError(
                    f"{where}: the constant {name} is declared with the range {list(r)} here and "
                    f"{list(out[name])} in {self.label}; declare it once (one constant of both "
                    "stages) or alike"
                )
            out[name] = r
        return out

    def _vertex_constants(self) -> None:
        """The user's vertex shader compiled again with the constants its text declares made
        uniforms, which every run binds to the values of the run."""
        if self.vertex is None:
            return
        decls, bare = declared(self.vertex.shader.source)
        names = tuple(n for n in self.constants if n in decls or n in bare)
        if names:
            self.vertex = self.vertex.with_constants(names)

    def stage_of(self, name: str) -> str:
        """'fragment', 'vertex' or 'both': the stages whose compiled code reads the constant
        ``name`` (those whose files declare it, if neither reads it)."""
        c = self.constants[name]
        if self.vertex is None:
            return "fragment"
        reads = [name in spirv_port.module_of(self.spec()).bound_names,
                 name in self.vertex.shader.constants
                 and name in self.vertex.shader.module.bound_names]  # fmt: skip
        if not any(reads):
            return c.stage
        return "both" if all(reads) else ("fragment" if reads[0] else "vertex")

    def _constants(self, ranges: dict) -> dict:
        texts = {"fragment": (self.source, self.label)}
        v = self.vertex.shader if self.vertex is not None else None
        if v is not None and not v.shared:  # a file of its own (else the fragment's file)
            texts["vertex"] = (v.original, v.label)
        decls, bare = declared(self.source)
        if "vertex" in texts:
            more = declared(texts["vertex"][0])
            decls, bare = {**decls, **more[0]}, {**bare, **more[1]}
        included = self._included_uniforms(set(ranges) - set(decls) - set(bare))
        out = find_constants(ranges, texts, included)
        if not out:
            raise ValueError(
                f"{self.label}: the declaration names no constant to fit; add "
                "`// @study constant NAME LOW HIGH` lines to the file, or `constant NAME LOW "
                "HIGH` lines to the experiment's fit.declare (docs/user-shader.md)"
            )
        return out

    def _declared_values(self, values: dict, vertex) -> None:
        """The declaration's ``values`` (name -> components: uniforms the engine sets, as
        ``// @study value`` gives them) to the stage that declares each: this shader (its
        file or an ``#include``), its vertex shader (``UserVertex``; a copy of it becomes
        ``self.vertex``, the caller's is left as it was), or both."""
        if not values:
            return
        if vertex is not None:
            shader = copy.copy(vertex.shader)
            shader.values = dict(vertex.shader.values)
            vertex = self.vertex = copy.copy(vertex)
            vertex.shader = shader
        text = self.source
        if dialects.has_includes(self.source):
            text = dialects.front_end(self.source, self.label, self.defines, self.include_paths,
                                      True)  # fmt: skip
        vtext = "" if vertex is None else vertex.shader.source
        for name, comps in values.items():
            comps = tuple(float(c) for c in comps)
            pattern = rf"\b{re.escape(name)}\b"
            found = [t for t in (text, vtext) if re.search(pattern, t)]
            if not found:
                raise ValueError(
                    f"{self.label}: value {name}: neither this shader nor its vertex shader "
                    f"reads a uniform {name}; remove the line or correct the name"
                )
            if re.search(pattern, text):
                self.values[name] = comps
            if vertex is not None and re.search(pattern, vtext):
                vertex.shader.values[name] = comps

    def _declared_bindings(self, bindings: dict) -> dict:
        """The declaration's ``bindings`` this shader reads (``declaration.split_bindings``);
        those only its vertex shader reads bind there (``self.vertex``: a copy with them)."""
        if not bindings:
            return {}
        text = self.source
        if dialects.has_includes(self.source):
            text = dialects.front_end(self.source, self.label, self.defines, self.include_paths,
                                      True)  # fmt: skip
        vtext = "" if self.vertex is None else self.vertex.shader.source
        ours, theirs = split_bindings(bindings, text, vtext, self.label)
        if theirs:
            self.vertex = self.vertex.with_bindings(theirs)
        return ours

    def _initialized_uniforms(self) -> None:
        """A uniform with an initializer neither fitted nor given a value: a value the engine
        sets, the initializer's (``declaration.initialized_uniforms``; ``self.initialized``),
        so that every engine target gets it (GLSL ES refuses a uniform initializer)."""
        v = self.vertex.shader if self.vertex is not None else None
        texts = {"fragment": self.source, "vertex": None if v is None or v.shared else v.original}
        found = initialized_uniforms(texts, set(self.constants) | set(self.engine_values()),
                                     self.label)  # fmt: skip
        if any(stage == "vertex" for stage, _ in found.values()):
            self.vertex = copy.copy(self.vertex)
            self.vertex.shader = copy.copy(v)
            self.vertex.shader.values = dict(v.values)
        for name, (stage, comps) in found.items():
            (self.values if stage == "fragment" else self.vertex.shader.values)[name] = comps
        self.initialized = {name: comps for name, (_, comps) in found.items()}

    def _included_uniforms(self, names: set) -> dict:
        """name -> ``(BARE match, stage)`` in a stage's preprocessed text, for the ``names``
        declared as a uniform without initializer in an ``#include`` d file only (an engine's
        common uniforms, e.g. Urho3D's ``cFogColor`` in ``Uniforms.glsl``): the fragment
        shader's, else the vertex shader's."""
        out = {}
        v = self.vertex.shader if self.vertex is not None else None
        if names and v is not None and v.source != v.original:  # preprocessed or translated
            out = {m["name"]: (m, "vertex") for m in BARE.finditer(v.source) if m["name"] in names}
        if names and dialects.has_includes(self.source):
            text = dialects.front_end(self.source, self.label, self.defines, self.include_paths,
                                      True)  # fmt: skip
            out.update({m["name"]: (m, "fragment") for m in BARE.finditer(text)
                        if m["name"] in names})  # fmt: skip
        return out

    def validate(self) -> "UserShader":
        for name, study in self.bindings.items():
            if study not in spirv_port.STUDY_INPUTS:
                raise ValueError(
                    f"{self.label}: the binding {name} -> {study!r} names no study input; the "
                    f"study's inputs: {', '.join(spirv_port.STUDY_INPUTS)}"
                )
            code = re.sub(r"//.*", "", self.source)
            if "#include" not in code and not re.search(rf"\b{re.escape(name)}\b", code):
                raise ValueError(f"{self.label}: the bound name {name} is not used by the shader")
        return self

    def _engine_options(self, path) -> None:
        """``up`` checked and ``normal_map`` made a path (relative to the shader's file)."""
        if self.engine["up"] not in ("y", "z"):
            raise ValueError(f"{self.label}: `// @study up {self.engine['up']}`: write up y or z")
        nm = self.engine["normal_map"]
        if nm:
            p = Path(nm) if path is None else Path(path).parent / nm
            if not p.is_file():
                raise ValueError(f"{self.label}: normal_map: no image file {str(p)!r}")
            self.engine["normal_map"] = str(p.resolve())

    def engine_values(self) -> dict:
        """Name -> components of every uniform the engine sets (``value`` lines), of both
        stages."""
        vertex = {} if self.vertex is None else self.vertex.shader.values
        return {**vertex, **self.values}

    def engine_record(self) -> list:
        """Sorted ``(option, value)`` pairs of the engine options (``up``, ``normal_map``), the
        normal-map image given by the SHA-256 of its bytes: what a digest of the shader's images
        takes (the image may change under the same name)."""
        engine = dict(self.engine)
        if engine.get("normal_map"):
            image = Path(engine["normal_map"]).read_bytes()
            engine["normal_map"] = hashlib.sha256(image).hexdigest()
        return sorted(engine.items())

    def run_bindings(self) -> dict:
        """The bindings the shader runs with: its own and the engine names it reads
        (``spirv.engine_inputs.resolve_bindings``)."""
        return _engine.resolve_bindings(
            self.source, self.bindings, self.constants, bool(self.engine["normal_map"])
        )

    def study_inputs(self) -> set[str]:
        """The study's inputs (:data:`spirv.translated.STUDY_INPUTS`) the shader reads: by their own
        names in its code (comments left out), or through a binding."""
        code = re.sub(r"//[^\n]*|/\*.*?\*/", "", self.source, flags=re.S)
        named = {n for n in spirv_port.STUDY_INPUTS if re.search(rf"\b{re.escape(n)}\b", code)}
        return named | set(self.bindings.values()) | set(self.run_bindings().values())

    # ---- values ----------------------------------------------------------------------------
    def defaults(self) -> dict:
        return {n: c.default if len(c.default) > 1 else c.default[0] for n, c in
                self.constants.items()}  # fmt: skip

    def scalar_names(self) -> list[str]:
        """The scalar names to fit: each float, and the first three components of a vector
        (RGB; an alpha is never compared)."""
        return [s for c in self.constants.values() for s in c.scalar_names()]

    def declared_range(self, name: str) -> list:
        """``[low, high]`` of constant ``name``, with its start value (a float or a list) for a
        uniform without initializer: the declaration table's entry."""
        c = self.constants[name]
        start = list(c.default) if len(c.default) > 1 else c.default[0]
        return [c.lo, c.hi, start] if c.bare else [c.lo, c.hi]

    def bounds(self, scalar: str) -> tuple[float, float]:
        c = self.constants[scalar.split("[")[0]]
        return c.lo, c.hi

    def with_scalars(self, values: dict, scalars: dict) -> dict:
        """``values`` with scalar names (``NAME`` or ``NAME[i]``) set from ``scalars``."""
        out = dict(values)
        for s, v in scalars.items():
            base, _, idx = s.partition("[")
            if base not in self.constants:
                raise ValueError(f"{self.label}: {s!r} is no constant of the declaration")
            if idx:
                comps = list(out[base])
                comps[int(idx[:-1])] = v
                out[base] = tuple(comps)
            else:
                out[base] = v
        return out

    def _checked(self, values: dict | None) -> dict:
        vals = self.defaults() if values is None else {**self.defaults(), **values}
        for n, v in vals.items():
            c = self.constants.get(n)
            if c is None:
                raise ValueError(f"{self.label}: {n!r} is no constant of the declaration")
            comps = v if isinstance(v, (tuple, list)) else (v,)
            for x in comps:
                if isinstance(x, dr.ArrayBase):
                    continue
                if not (np.isfinite(float(x)) and c.lo <= float(x) <= c.hi):
                    raise ValueError(f"{self.label}: {n} = {v!r} is outside [{c.lo}, {c.hi}]")
        return vals

    def spec(self) -> spirv_port.ShaderSpec:
        return spirv_port.ShaderSpec(
            self.source,
            self.label,
            defines=self.defines,
            constants=tuple((n, n) for n in [*self.fragment_constants(), *self.values]),
            bindings=tuple(self.run_bindings().items()),
            include_paths=self.include_paths,
            engine=tuple(sorted(self.engine.items())),
        )

    def fragment_constants(self) -> list[str]:
        """The constants the fragment shader's file (or an ``#include`` of it) declares."""
        return [n for n, c in self.constants.items() if c.site("fragment") is not None]

    def check(self) -> "UserShader":
        """Compile the shader (``dialects.ShaderError`` with glslang's errors, file and line)
        and check that every input, uniform and sampler it reads is a study input, bound or a
        constant, and that the executor implements every instruction of it (and of its
        vertex shader): before anything is rendered."""
        mod = spirv_port.module_of(self.spec())
        check_supported(mod)
        if self.vertex is not None:
            check_supported(self.vertex.shader.module)
        known = set(spirv_port.STUDY_INPUTS) | set(self.run_bindings()) | set(self.constants)
        if self.vertex is not None:  # every input of it is fed by the vertex shader
            try:
                self.vertex.feeds(mod, self.spec().source, self.label)
                self.vertex.shader.check_bound()
            except ValueError as exc:
                raise dialects.ShaderError(str(exc)) from None
        known |= set(self.values)
        used = referenced(mod)
        for vid, ins in mod.defs.items():
            name = mod.binding_name(vid)
            if vid not in used:
                continue  # declared, never read (an engine's common uniforms and samplers)
            if (
                self.vertex is not None
                and ins.opname == "OpVariable"
                and (ins.operands[0] == "Input")
            ):
                continue  # fed by the vertex shader: linked by user_vertex (by name or location)
            if (ins.opname == "OpVariable" and ins.operands[0] in ("Input", "UniformConstant")
                    and len(ins.operands) == 1 and name not in known):  # fmt: skip
                raise dialects.ShaderError(
                    f"{self.label}: the shader reads {name!r} but nothing binds it: bind it to "
                    "one of the study's inputs (`// @study bind NAME INPUT` or fit.declare), or "
                    "declare it a constant to fit"
                )
        return self

    def resolved_values(self, m, values: dict | None = None):
        """``values`` (default: the start values) checked and resolved for a run on the Dr.Jit
        type module ``m``."""
        return self._resolved(m, self._checked(values))

    def _resolved(self, m, values: dict):
        def conv(x):
            return x if isinstance(x, dr.ArrayBase) else dr.opaque(m.Float, float(np.float32(x)))

        vals = {}
        for n, v in values.items():
            vals[n] = tuple(conv(x) for x in v) if isinstance(v, (tuple, list)) else conv(v)
        for n, v in self.values.items():  # `value` pragmas' (one float, or a vector)
            vals[n] = conv(v[0]) if len(v) == 1 else tuple(conv(x) for x in v)
        return types.SimpleNamespace(values=vals)

    # ---- renders ---------------------------------------------------------------------------
    def render(self, inputs, values: dict | None = None, backend: str | None = None):
        """A ``ShaderOutput`` (colour (H, W, 3) linear RGB, mask, ``fetches``/``iterations``)."""
        m = backend_types(backend)
        C = self.resolved_values(m, values)
        if self.vertex is not None:
            return self.vertex.render(inputs, self.spec(), C, backend)
        return spirv_port.render(inputs, None, spec=self.spec(), backend=backend, resolved=C)

    def _params(self, m, values, names: list[str]) -> tuple[dict, list]:
        """``(values with each scalar of names a gradient-enabled size-1 Float, those Floats)``."""
        vals, params = dict(self._checked(values)), []
        for s in names:
            base, _, idx = s.partition("[")
            v = vals[base]
            cur = v[int(idx[:-1])] if idx else v
            p = dr.opaque(m.Float, float(np.float32(cur)))
            dr.enable_grad(p)
            params.append(p)
            vals = self.with_scalars(vals, {s: p})
        return vals, params

    def vertex_motion(self, inputs, values, names: list[str], backend: str | None = None) -> list:
        """For each scalar of ``names``: the largest |derivative| of a vertex's ``gl_Position``
        in it (all 0 without a vertex shader of the user's)."""
        if self.vertex is None:
            return [0.0] * len(names)
        m = backend_types(backend)
        vals, params = self._params(m, values, names)
        try:
            return self.vertex.motion(m, inputs, self.spec(), self._resolved(m, vals), params)
        finally:
            for p in params:
                dr.disable_grad(p)

    def render_with_jacobian(
        self, inputs, values, names: list[str], backend: str | None = None, lanes=None
    ):
        """``(ShaderOutput, J)``, ``J`` float32 (H, W, 3, len(names)): forward-mode derivatives
        of the colour in the scalar names ``names`` (lane-dependent loops unrolled); those in
        the constants of the user's vertex shader through its outputs and the interpolation,
        the coverage held fixed (``spirv.user_vertex.UserVertex.frame``). ``lanes``: what
        takes the lanes in place of the images (``pipeline.frame.jacobian_passes``)."""
        m = backend_types(backend)
        vals, params = self._params(m, values, names)
        P = prepare(inputs, m)
        try:
            if self.vertex is not None:
                P, color, diag = self.vertex.shade(
                    m, inputs, self.spec(), self._resolved(m, vals), True, params
                )
            else:
                color, diag = spirv_port.shade(
                    m, P, inputs, self.spec(), self._resolved(m, vals), differentiate=True
                )
            color, diag, grads = tangents(m, color, diag, params)
            dr.eval(color, diag, grads)
        finally:
            for p in params:
                dr.disable_grad(p)
        return jacobian_output(m, P, color, diag, grads, self.label, lanes)

    # ---- the file ----------------------------------------------------------------------------
    def written(self, values: dict, bare_initializers: bool = True,
                uniform_initializers: bool = True) -> str:  # fmt: skip
        """The shader's text with ``values`` in place of its constants' initializers; every
        other byte as in the file. A uniform declared without initializer gets one where its
        dialect allows (desktop GLSL 1.20 and later) and ``bare_initializers`` asks.
        ``uniform_initializers`` False: no uniform of a constant has an initializer (those the
        file gives one lose it), the text the engine targets are made from (GLSL ES refuses
        uniform initializers, HLSL and Metal ignore them: the material sets the values,
        ``study.export.bindings``)."""
        d = self.dialect
        initializers = bare_initializers and uniform_initializers and not d.es and d.version >= 120
        vals = self._checked(values)
        text = written_text(self.source, self.constants.values(), vals, "fragment",
                            initializers, uniform_initializers)  # fmt: skip
        return text if uniform_initializers else without_initializers(text, self.initialized)

    def vertex_written(self, values: dict, bare_initializers: bool = True,
                       uniform_initializers: bool = True) -> str | None:  # fmt: skip
        """The user's vertex shader file's text with ``values`` in place of the initializers of
        the constants it declares, as :meth:`written` (None without a vertex shader; the
        fragment shader's :meth:`written` for one file of both stages)."""
        if self.vertex is None:
            return None
        v = self.vertex.shader
        if v.shared:
            return self.written(values, bare_initializers, uniform_initializers)
        d = dialects.detect(v.original, v.label, dialects.version_define(v.defines))
        initializers = bare_initializers and uniform_initializers and not d.es and d.version >= 120
        vals = self._checked(values)
        text = written_text(v.original, self.constants.values(), vals, "vertex", initializers,
                            uniform_initializers)  # fmt: skip
        return text if uniform_initializers else without_initializers(text, self.initialized)

    def vertex_gl_source(self, values: dict | None = None, bare_initializers: bool = True,
                         uniform_initializers: bool = True):  # fmt: skip
        """The GLSL 330 core OpenGL runs for :meth:`vertex_written` (translated as the vertex
        shader is compiled: ``spirv.vertex.VertexShader.gl_text``); None without one."""
        if self.vertex is None:
            return None
        text = self.vertex_written(values or {}, bare_initializers, uniform_initializers)
        return self.vertex.shader.gl_text(text)

    def gl_source(self, values: dict | None = None, uniform_initializers: bool = True) -> str:
        """The core-profile GLSL of :meth:`written` with ``values`` (and
        ``uniform_initializers``): that text for a GLSL 330+ core file, else its translation to
        GLSL 330 core (``dialects.front_end``; a file with ``#include`` s or ``defines``
        preprocessed). ShaderError for GLSL ES 3.10 and later, which has no translation."""
        d = self.dialect
        if not d.runs_on_desktop_gl:
            raise dialects.ShaderError(
                f"{self.label} is {d.name}, which has no core-profile translation (glslang "
                "compiles it with its ES profile)"
            )
        text = self.written(values or {}, uniform_initializers=uniform_initializers)
        return dialects.for_opengl(text, self.label, self.defines, self.include_paths)

    def gl_renderer(self, inputs, values: dict | None = None, source=None, reflection=None,
                    es=None, **how):  # fmt: skip
        """A ``GLRenderer`` (OpenGL, llvmpipe) drawing the written-back shader with ``values``
        as ``spirv.gl_run.plan`` chooses (the file as written on a context of its dialect, or
        its core-profile translation; ``r.gl_run`` says which; ``how``: ``as_written`` and
        ``highp`` of ``spirv.gl_run.plan``); or, given ``source`` and its
        ``reflection`` (``spirv.tools.hlsl_round_trip`` of the exported HLSL), that GLSL
        through a ``TranslatedRenderer``, or, given ``source`` and ``es`` (the export's GLSL ES
        3.00 fragment and vertex shaders), those on an OpenGL ES context: every uniform
        constant set as the material sets it. Its samplers and uniforms are bound to the
        study's inputs by the declaration. Use it as a context manager, ``render(None)`` /
        ``time_frames(None, n, warmup)``."""
        return gl_run.renderer(self, inputs, self._checked(values), source, reflection, es, **how)

    def gl_render(self, inputs, values: dict | None = None, **how):
        """The written-back shader on OpenGL (llvmpipe): ``(rgba (H, W, 4), mask (H, W))``."""
        with self.gl_renderer(inputs, values, **how) as r:
            return r.render(None)
