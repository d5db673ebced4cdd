"""A user's own vertex shader, compiled to SPIR-V and executed per vertex of the water grid.

The shader is core GLSL (``#version 330 core`` or later), or an older dialect (GLSL 1.10-1.50,
a compatibility profile, GLSL ES 1.00 / 3.00) translated to it first (``spirv.dialects``:
``attribute`` / ``varying``, and the compatibility names ``gl_Vertex``, ``gl_MultiTexCoord0``,
``gl_Normal``, ``gl_ModelViewProjectionMatrix``, ``gl_ModelViewMatrix``,
``gl_ProjectionMatrix``, ``gl_NormalMatrix``, ``ftransform()`` and ``gl_TexCoord[i]`` become
names that bind themselves); :attr:`VertexShader.source` is the text compiled and drawn,
:attr:`VertexShader.original` the file's. It is compiled as the fragment
shaders are (``spirv.module``: ``glslangValidator -G --aml --amb -g``, every call inlined by
``spirv-opt``, ``spirv-val``) with ``-S vert``, and run by the same executor
(``spirv.execute.Executor``), one lane per vertex of the tessellated water quad
(``pipeline.interpolate.water_grid``). Its ``Input`` variables are the grid's attributes, its
uniforms the frame's matrices and vectors, each bound by its declared name
(``spirv.engine_names``: the names of three.js, Babylon.js, jMonkeyEngine, Urho3D, OGRE and the
study's ``water.vert``), by a pragma of the file::

    // @study bind aPos position          (the shader's name -> a meaning or an engine name)

or by the study's own uniform names, which bind only as themselves (``wave1`` ... ``wave4``,
``viewpos``, ``lightpos``, the texture matrices, its samplers). Its outputs are
``gl_Position`` (the ``gl_PerVertex`` block's first member) and every ``Output`` variable,
each with its ``flat`` / ``noperspective`` decoration and its ``layout(location = N)`` when
the source gives one.

Its constants to fit are declared as a fragment shader's (``// @study constant NAME LOW HIGH
[START]``, collected in :attr:`VertexShader.ranges`; ``spirv.user_shader`` finds their
declarations); the shader is compiled with them made uniforms (``constants``), which each run
binds. :meth:`VertexShader.run` returns the outputs as NumPy arrays, one row per vertex, and,
given gradient-enabled constants, their forward-mode derivatives alike.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import drjit as dr
import numpy as np

from . import dialects
from . import engine_inputs as _engine
from . import engine_names as names_
from .translated import STUDY_INPUTS, prepared_source
from .execute import Executor, UnboundVariable
from .loops import UnsupportedInstruction
from .module import OPT_PASSES, Module, referenced, without_bool_uniforms

__all__ = ["VertexShader", "Varying", "compile_vertex", "value_pragma", "ATTRIBUTES"]

ATTRIBUTES = ("position", "uv", "normal", "tangent")
_INPUTS = set(STUDY_INPUTS) | {"wave1", "wave2", "wave3", "wave4"}
_PRAGMA = re.compile(r"^\s*//\s*@study\s+(?P<verb>\S+)\s*(?P<args>.*?)\s*$", re.M)
_LOCATION = re.compile(
    r"layout\s*\(\s*location\s*=\s*(?P<loc>\d+)\s*\)\s*(?:(?:flat|noperspective|smooth|"
    r"centroid|highp|mediump|lowp)\s+)*(?P<dir>in|out)\s+\w+\s+(?P<name>\w+)"
)


def explicit_locations(source: str, direction: str) -> dict:
    """name -> ``layout(location = N)`` of the ``in`` or ``out`` variables ``source`` places
    itself (not those glslang maps automatically)."""
    code = re.sub(r"//[^\n]*|/\*.*?\*/", "", source, flags=re.S)  # a line comment ends at \n
    return {m["name"]: int(m["loc"]) for m in _LOCATION.finditer(code) if m["dir"] == direction}


def _range(args: list, where: str) -> tuple:
    """``(low, high[, start])`` of a ``// @study constant NAME LOW HIGH [START]`` pragma."""
    try:
        return (float(args[1]), float(args[2]), *args[3:])
    except ValueError:
        raise ValueError(f"{where}: `// @study constant NAME LOW HIGH [START]`") from None


def compile_vertex(source: str, label: str) -> bytes:
    """SPIR-V of a core GLSL vertex shader, optimised and validated as
    ``spirv.module.compile_fragment`` does a fragment shader; ValueError with the tool's log."""
    with tempfile.TemporaryDirectory(prefix="spirv-vert.") as d:
        src = Path(d) / Path(label).name  # -S vert: the name is the label's (its OpLines)
        raw, opt = Path(d) / "raw.spv", Path(d) / "opt.spv"
        src.write_text(without_bool_uniforms(source, label), encoding="utf-8")
        steps = [
            ["glslangValidator", "-G", "--aml", "--amb", "-g", "-S", "vert", "-o", str(raw),
             str(src)],
            ["spirv-opt", *OPT_PASSES, str(raw), "-o", str(opt)],
            ["spirv-val", str(opt)],
        ]  # fmt: skip
        for args in steps:
            exe = shutil.which(args[0])
            if exe is None:
                pkg = "glslang-tools" if args[0] == "glslangValidator" else "spirv-tools"
                raise RuntimeError(f"{args[0]} not found on PATH; `apt-get install {pkg}`")
            res = subprocess.run([exe, *args[1:]], capture_output=True, text=True, timeout=120,
                                 check=False)  # fmt: skip
            if res.returncode != 0:
                log = (res.stdout + res.stderr).replace(str(src), label).strip()
                raise ValueError(f"{args[0]} failed on the vertex shader {label}:\n{log}")
        return opt.read_bytes()


def value_pragma(args: list, where: str) -> tuple:
    """``(name, components)`` of a ``// @study value NAME V[,V...]`` pragma's arguments: a
    uniform the engine sets (a material's or frame's constant with no meaning of
    ``engine_names``, not fitted)."""
    try:
        if len(args) != 2:
            raise ValueError
        return args[0], tuple(float(x) for x in args[1].split(","))
    except ValueError:
        raise ValueError(
            f"{where}: write `// @study value NAME V` or `// @study value NAME V1,V2,...` "
            "(the uniform's value as the engine sets it, one number per component)"
        ) from None


NORMAL_FRAMES = ("world", "tangent")


def normal_pragma(args: list, where: str) -> tuple:
    """``(name, frame)`` of a ``// @study normal NAME [world|tangent]`` pragma's arguments: the
    fragment shader's variable that holds the surface normal when ``main`` returns, in the
    world frame (the shader's, ``up`` y or z) or the water's tangent frame (default world)."""
    frame = args[1] if len(args) == 2 else "world"
    if len(args) not in (1, 2) or frame not in NORMAL_FRAMES:
        raise ValueError(
            f"{where}: write `// @study normal NAME` or `// @study normal NAME tangent` (the "
            "variable holding the surface normal; its frame world, the default, or tangent)"
        )
    return args[0], frame


@dataclass(frozen=True)
class Varying:
    """A vertex output: its variable id, ``mode`` ('smooth', 'flat', 'noperspective') and
    ``location`` (the source's explicit one, else None)."""

    vid: int
    mode: str
    location: int | None


def _mode(decorations: dict) -> str:
    if "Flat" in decorations:
        return "flat"
    return "noperspective" if "NoPerspective" in decorations else "smooth"


def glsl_type(module: Module, tid: int) -> tuple:
    """A type as ('float' | 'int' | 'uint' | 'bool',) ('vec', n, kind) ('mat', columns, rows)
    or ('other', opname)."""
    ins = module.defs[tid]
    op, o = ins.opname, ins.operands
    if op == "OpTypeFloat":
        return ("float",)
    if op == "OpTypeInt":
        return ("int",) if o[1] else ("uint",)
    if op == "OpTypeBool":
        return ("bool",)
    if op == "OpTypeVector":
        return ("vec", o[1], glsl_type(module, o[0])[0])
    if op == "OpTypeMatrix":
        return ("mat", o[1], glsl_type(module, o[0])[1])
    return ("other", op)


def pointee_type(module: Module, vid: int) -> tuple:
    """:func:`glsl_type` of what the global variable ``vid`` holds."""
    ptr = module.defs[module.defs[vid].type_id]
    return glsl_type(module, ptr.operands[1])


def _describe(t: tuple) -> str:
    if t[0] == "vec":
        return f"vec{t[1]}"
    if t[0] == "mat":
        return f"mat{t[1]}" if t[1] == t[2] else f"mat{t[1]}x{t[2]}"
    return t[-1] if t[0] == "other" else t[0]


class VertexShader:
    """A user's vertex shader file (see the module doc): ``source``, ``label`` (file name),
    ``bindings`` (declared name -> meaning or engine name, from its pragmas), ``defines`` (the
    preprocessor names it is compiled with)."""

    def __init__(self, source: str, label: str, path=None, defines=(), include_paths=(),
                 shared=False, constants=(), bindings=None):  # fmt: skip
        # defines, include_paths: as a fragment shader's (``spirv.dialects.front_end``); a
        # file that needs them is compiled and drawn preprocessed. shared: the file is the
        # fragment shader's too (Urho3D's one file for both stages), whose pragmas other than
        # a binding to a vertex meaning or engine name are the fragment shader's. constants:
        # the names of the constants to fit it declares, compiled as uniforms that each run
        # binds (``spirv.user_shader.UserShader`` finds them). bindings: declared name ->
        # meaning, engine name or study input from outside the file (an experiment's
        # fit.declare), over the file's own pragmas
        self.original, self.label, self.path = source, label, path
        self.defines = tuple(defines)
        self.include_paths = tuple(str(p) for p in include_paths)
        self.shared, self.constants = bool(shared), tuple(constants)
        compiled = self.gl_text(source, file_lines=True)
        self.source = source if compiled is source else dialects.without_file_lines(compiled)
        self.bindings, self.values, self.ranges = {}, {}, {}
        for m in _PRAGMA.finditer(source):
            args, line = m["args"].split(), source.count("\n", 0, m.start()) + 1
            if m["verb"] == "value":
                self.values.update([value_pragma(args, f"{label}:{line}")])
                continue
            ours = len(args) == 2 and (args[1] in names_.MEANINGS or args[1] in names_.ENGINE_NAMES)
            if shared and not (m["verb"] == "bind" and ours):
                continue
            if m["verb"] == "constant" and len(args) in (3, 4):
                self.ranges[args[0]] = (_range(args, f"{label}:{line}"), f"{label}:{line}")
                continue
            if m["verb"] != "bind" or len(args) != 2:
                raise ValueError(
                    f"{label}:{line}: a vertex shader takes `// @study bind NAME MEANING`, "
                    "`// @study value NAME V[,V...]` and `// @study constant NAME LOW HIGH "
                    "[START]` pragmas only"
                )
            self.bindings[args[0]] = args[1]
        self.declared = dict(bindings or {})
        self.bindings.update(self.declared)
        text = prepared_source(compiled, label, self.constants)
        self.module = Module(compile_vertex(text, label), label=label, stage="Vertex")
        for name, target in self.bindings.items():
            if names_.meaning_of(name, self.bindings) is None and target not in names_.MEANINGS \
                    and _engine.canonical(target) not in _INPUTS:  # fmt: skip
                raise ValueError(
                    f"{label}: the binding {name} -> {target} names no meaning, engine name "
                    f"or study input; the meanings: {', '.join(names_.MEANINGS)}; the inputs: "
                    "docs/engine-inputs.md"
                )
        self.outputs, self.position = self._outputs()
        # uniforms that are study or engine inputs (``time``, ``textureMatrix``, ...): their
        # engine names and the pragmas binding one of them, name -> the study input
        plain = {n: t for n, t in self.bindings.items() if names_.meaning_of(n, self.bindings)
                 is None}  # fmt: skip
        found = _engine.resolve_bindings(self.source, plain, ())
        self.inputs = {n: t for n, t in found.items() if t in _INPUTS}

    def gl_text(self, text: str, file_lines: bool = False) -> str:
        """``text`` (this file's, e.g. with fitted values written in) as it is drawn: GLSL 330
        core, translated from an older dialect and preprocessed where the file needs it
        (defines, ``#include`` s); ``file_lines``: as glslang compiles it, an ``#include`` d
        file's lines still named by their file, so that errors name it."""
        return dialects.for_opengl(text, self.label, self.defines, self.include_paths, "vert",
                                   file_lines=file_lines)  # fmt: skip

    def with_constants(self, names) -> "VertexShader":
        """This shader compiled again with the constants ``names`` made uniforms (the values
        given it after it was read, ``value`` lines of a declaration, kept)."""
        out = VertexShader(self.original, self.label, self.path, self.defines,
                           self.include_paths, self.shared, tuple(names),
                           self.declared)  # fmt: skip
        out.values.update(self.values)
        return out

    def with_bindings(self, bindings: dict) -> "VertexShader":
        """This shader with the declared ``bindings`` (name -> meaning, engine name or study
        input) added to its own, checked as its pragmas are (the values given it kept)."""
        out = VertexShader(self.original, self.label, self.path, self.defines,
                           self.include_paths, self.shared, self.constants,
                           {**self.declared, **bindings})  # fmt: skip
        out.values.update(self.values)
        return out

    @classmethod
    def from_file(cls, path, defines=(), include_paths=(), shared=False) -> "VertexShader":
        """The shader of the file ``path``; its ``#include`` s are searched in its folder, then
        in ``include_paths``; ``shared``: the file is the fragment shader's too."""
        p = Path(path)
        if not p.is_file():
            raise ValueError(f"fit.vertex: no file {str(p)!r}")
        incs = (str(p.resolve().parent), *(str(i) for i in include_paths))
        return cls(p.read_text(encoding="utf-8"), p.name, p, defines, incs, shared)

    def _outputs(self) -> tuple[dict, int | None]:
        mod, places = self.module, explicit_locations(self.source, "out")
        outs, position = {}, None
        for vid in mod.interface:
            if mod.defs[vid].operands[0] != "Output":
                continue
            ptr = mod.defs[mod.defs[vid].type_id]
            tname = mod.names.get(ptr.operands[1], "")
            if tname == "gl_PerVertex" or mod.binding_name(vid) == "gl_Position":
                position = vid
                continue
            name = mod.name(vid)
            outs[name] = Varying(vid, _mode(mod.decorations.get(vid, {})), places.get(name))
        return outs, position

    # ---- the bindings of one frame -----------------------------------------------------------
    def _attribute(self, m, meaning: str, t: tuple, grid, name: str, up: str) -> list:
        n = len(grid.position)
        base = names_.attribute_values(grid, meaning, up)
        k = t[1] if t[0] == "vec" else 1
        if t[0] not in ("vec", "float") or (t[0] == "vec" and t[2] != "float"):
            raise ValueError(
                f"{self.label}: the attribute {name} ({names_.MEANINGS[meaning][1]}) is "
                f"declared {_describe(t)}; declare it a float vector"
            )
        fill = np.array([0.0, 0.0, 0.0, 1.0])
        cols = [base[:, i] if i < base.shape[1] else np.full(n, fill[i]) for i in range(k)]
        lanes = [m.Float(c.astype(np.float32)) for c in cols]
        return lanes if t[0] == "vec" else lanes[0]

    def _uniform(self, inputs, meaning: str, t: tuple, name: str, up: str):
        want = names_.MEANINGS[meaning][0]
        if _describe(t) not in want:
            raise ValueError(
                f"{self.label}: {name} is the {meaning} ({names_.MEANINGS[meaning][1]}), a "
                f"{' or '.join(want)}; the shader declares it {_describe(t)}"
            )
        try:
            v = np.asarray(names_.meaning_values(inputs, meaning, up), np.float32)
        except ValueError as exc:
            raise ValueError(f"{self.label}: {name}: {exc}") from None
        if v.ndim == 2 and name in names_.TRANSPOSED and name not in self.bindings:
            v = v.T  # the engine's row-major upload read as GL's columns
        if v.ndim == 2:
            return [[float(v[i, j]) for i in range(v.shape[0])] for j in range(v.shape[1])]
        return [float(x) for x in v[: t[1]]]

    def bindings_for(self, m, inputs, grid, study: dict, up: str = "y") -> dict:
        """Binding name -> value of every input and uniform the module reads: the grid's
        attributes (per-vertex Floats), the recognised matrices and vectors, in the world frame
        ``up`` (``spirv.engine_names``), ``study`` (the study's uniform and sampler values by
        name, ``spirv.translated.study_bindings``, in the same frame)."""
        out, mod = {}, self.module
        for vid, ins in mod.defs.items():
            if ins.opname != "OpVariable" or ins.operands[0] not in ("Input", "UniformConstant"):
                continue
            name = mod.binding_name(vid)
            meaning = names_.meaning_of(name, self.bindings)
            t = pointee_type(mod, vid)
            if name in self.values and ins.operands[0] == "Input":
                self._value(name, t, attribute=True)  # refused: an attribute takes no value
            if meaning in ATTRIBUTES:
                out[name] = self._attribute(m, meaning, t, grid, name, up)
            elif meaning is not None:
                out[name] = self._uniform(inputs, meaning, t, name, up)
            elif name in self.values:
                out[name] = self._value(name, t)
            elif name in study:
                out[name] = study[name]
            elif self.inputs.get(name) in study:
                out[name] = study[self.inputs[name]]
        return out

    def check_bound(self) -> None:
        """ValueError naming the first attribute or uniform the shader reads that nothing binds
        (no meaning of ``engine_names``, no ``value``, no study or engine input, no
        initializer) and the line that reads it, or a ``value`` that does not fit its
        variable (:meth:`_value`): before anything is rendered."""
        mod, used = self.module, referenced(self.module)
        for vid, ins in mod.defs.items():
            if (ins.opname == "OpVariable" and ins.operands[0] in ("Input", "UniformConstant")
                    and mod.binding_name(vid) in self.values):  # fmt: skip
                self._value(mod.binding_name(vid), pointee_type(mod, vid),
                            ins.operands[0] == "Input")  # fmt: skip
        for vid, ins in mod.defs.items():
            if (vid not in used or ins.opname != "OpVariable" or len(ins.operands) > 1
                    or ins.operands[0] not in ("Input", "UniformConstant")):  # fmt: skip
                continue
            name = mod.binding_name(vid)
            if (name.startswith("gl_") or names_.meaning_of(name, self.bindings) is not None
                    or name in self.values or name in _INPUTS or name in self.inputs
                    or name in self.constants
                    or pointee_type(mod, vid)[0] in ("struct", "array")):  # fmt: skip
                continue
            loads = (i for fn in mod.functions.values() for b in fn.blocks.values()
                     for i in b.body if i.opname == "OpLoad" and i.operands[0] == vid)  # fmt: skip
            use = next(loads, ins)
            raise ValueError(
                f"{self.label}: the vertex shader reads {name!r} (at {use.where()}) but nothing "
                f"binds it: give its value (`// @study value {name} V[,V...]`, or `value` in "
                "fit.declare), bind it to a meaning or input (`// @study bind NAME MEANING`; "
                "docs/user-shader.md), or declare it a constant to fit"
            )

    def _value(self, name: str, t: tuple, attribute: bool = False):
        """The value a ``value`` pragma gives the uniform ``name`` of type ``t``: a float, a
        vector's components, or a matrix's columns (the pragma gives a ``matC[xR]``'s C x R
        numbers column after column, as ``glUniformMatrix*fv`` takes them untransposed).
        ``attribute``: the name is a vertex attribute, which no value sets (refused)."""
        if attribute:
            raise ValueError(
                f"{self.label}: `value {name}`: {name} is a vertex attribute, set per vertex "
                "by the mesh, not a uniform: bind it to a meaning instead (`bind "
                f"{name} position`, or uv, normal, tangent; docs/user-shader.md)"
            )
        v = self.values[name]
        if t[0] == "mat":
            cols, rows = t[1], t[2]
            if len(v) != cols * rows:
                raise ValueError(
                    f"{self.label}: `value {name}` gives {len(v)} component(s); the shader "
                    f"declares it {_describe(t)}: give its {cols * rows} numbers column after "
                    "column (GL's order)"
                )
            return [[float(v[c * rows + r]) for r in range(rows)] for c in range(cols)]
        n = t[1] if t[0] == "vec" and t[2] == "float" else (1 if t[0] == "float" else 0)
        if n != len(v):
            want = "a float" if n == 1 else (f"vec{n}" if n else f"{_describe(t)}: not built")
            raise ValueError(
                f"{self.label}: `value {name}` gives {len(v)} component(s); the "
                f"shader declares it {_describe(t)} ({want})"
            )
        return list(v) if t[0] == "vec" else v[0]

    def run(self, m, inputs, grid, study: dict, up: str = "y", constants=None, params=()):
        """Run the shader on every vertex of ``grid`` (``pipeline.interpolate.Grid``, in the
        study's Y-up world; given to the shader in the world frame ``up``):
        ``(clip (V, 4) float64 gl_Position, {output name: (V, ...) float64})``; an output
        never written is absent. ``constants``: name -> the executor's value (a size-1 Float
        or a tuple of them) of each of :attr:`constants`. ``params``: gradient-enabled size-1
        Floats among those values; given, a third item is returned, one ``(dclip, douts)`` per
        param: the forward-mode derivatives of ``clip`` and of each output, shaped alike."""
        if self.position is None:
            raise ValueError(f"{self.label}: the vertex shader never writes gl_Position")
        b = self.bindings_for(m, inputs, grid, study, up)
        for n in self.constants:
            v = (constants or {}).get(n)
            if v is not None:
                b[n] = list(v) if isinstance(v, tuple) else v
        ex = Executor(self.module, m, b, differentiate=bool(params))
        try:
            ex.run()
            V = len(grid.position)
            pv = ex.vars.get(self.position)
            if pv is None:
                raise ValueError(f"{self.label}: the vertex shader never writes gl_Position")
            if self.module.binding_name(self.position) != "gl_Position":
                pv = pv[0]
            written = {n: ex.vars[v.vid] for n, v in self.outputs.items()
                       if ex.vars.get(v.vid) is not None}  # fmt: skip
            clip = to_numpy(pv, V)
            outs = {n: to_numpy(v, V) for n, v in written.items()}
            if params:
                per = _tangents([pv, *written.values()], params, V)
                tangent = [(t[0], dict(zip(written, t[1:]))) for t in per]
        except UnboundVariable as exc:
            raise ValueError(
                f"{self.label}: {exc}. A vertex shader's attributes and matrices bind by the "
                f"names engines give them ({', '.join(sorted(names_.ENGINE_NAMES))}) or by "
                "`// @study bind NAME MEANING` in its file (docs/user-shader.md)"
            ) from None
        except UnsupportedInstruction as exc:
            raise ValueError(f"{self.label}: {exc}") from None
        finally:
            ex.release()
        return (clip, outs, tangent) if params else (clip, outs)


def _tangents(values: list, params, lanes: int) -> list:
    """For each of ``params``: the forward-mode derivative of each of ``values`` (the
    executor's values: Dr.Jit arrays, numbers, nested lists of them) in that param, as
    :func:`to_numpy` gives the value."""
    leaves: list = []

    def leaf(x):
        if isinstance(x, (list, tuple)):
            return [leaf(y) for y in x]
        if isinstance(x, dr.ArrayBase) and dr.grad_enabled(x):
            # a node of its own: a target of the pass, never an interior node (whose gradient
            # the pass clears)
            leaves.append(x + dr.opaque(type(x), 0.0))
            return len(leaves) - 1
        return None

    def fill(shape, grads):
        if isinstance(shape, list):
            return [fill(y, grads) for y in shape]
        return 0.0 if shape is None else grads[shape]

    shapes = [leaf(v) for v in values]
    keep = dr.ADFlag.ClearInterior | dr.ADFlag.ClearInput
    out = []
    for p in params:
        for q in params:
            dr.clear_grad(q)
        dr.clear_grad(leaves)
        dr.set_grad(p, 1.0)
        grads = list(dr.forward_to(leaves, flags=keep)) if leaves else []
        out.append([to_numpy(fill(s, grads), lanes) for s in shapes])
    for q in params:
        dr.clear_grad(q)
    return out


def to_numpy(value, lanes: int) -> np.ndarray:
    """A value of the executor (a Python number, a Dr.Jit array of 1 or ``lanes`` entries, or
    nested lists of them: vector components, matrix columns) as a float64 array
    ``(lanes, ...)``."""
    if isinstance(value, (list, tuple)):
        return np.stack([to_numpy(v, lanes) for v in value], 1)
    if isinstance(value, dr.ArrayBase):
        dr.eval(value)
        a = np.asarray(value.numpy(), np.float64).ravel()
    else:
        a = np.asarray(float(value), np.float64).ravel()
    return np.broadcast_to(a, (lanes,)).copy()
