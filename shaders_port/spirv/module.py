"""A SPIR-V module read with the machine-readable SPIR-V grammar, for the SPIR-V executor.

:func:`compile_fragment` turns a GLSL fragment shader (any dialect of ``spirv.dialects``, translated
to core GLSL there) into SPIR-V: ``glslangValidator -G
--aml --amb -g`` (OpenGL semantics, locations and bindings mapped automatically, debug line
information kept), then ``spirv-opt`` passes that make the module easier to execute without
changing what it computes (:data:`OPT_PASSES`: every function call inlined into ``main``, a
single return), then ``spirv-val``. Preprocessor names are given to glslang as ``-D`` options,
so the module's line numbers are the source file's.

:class:`Module` decodes the binary with the JSON grammar that Debian's ``spirv-headers`` package
ships (:data:`CORE_GRAMMAR`, :data:`GLSL_GRAMMAR`): every opcode, operand kind and enumerant
comes from the grammar, none is written here. A decoded :class:`Instruction` has its opcode
name, result type id, result id, decoded operands and the GLSL source line of its ``OpLine``.
Functions are split into :class:`Block` s with their structured-merge instruction
(``OpSelectionMerge`` / ``OpLoopMerge``) and terminator.
"""

from __future__ import annotations

import functools
import json
import re
import shutil
import struct
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from .dialects import COMMENTS, ShaderError, front_end, glslang_errors, split_defines

GRAMMAR_DIR = Path("/usr/include/spirv/unified1")
CORE_GRAMMAR = GRAMMAR_DIR / "spirv.core.grammar.json"
GLSL_GRAMMAR = GRAMMAR_DIR / "extinst.glsl.std.450.grammar.json"
MAGIC = 0x07230203
# spirv-opt passes: calls inlined (the executor has no call stack), one return per function
OPT_PASSES = (
    "--merge-return",
    "--inline-entry-points-exhaustive",
    "--eliminate-dead-functions",
)
_TERMINATORS = (
    "OpBranch",
    "OpBranchConditional",
    "OpSwitch",
    "OpReturn",
    "OpReturnValue",
    "OpKill",
    "OpTerminateInvocation",
    "OpUnreachable",
)
_ID_KINDS = ("IdResultType", "IdResult", "IdRef", "IdScope", "IdMemorySemantics")


@functools.lru_cache(maxsize=1)
def grammar() -> dict:
    """The core and GLSL.std.450 grammars: ``{'ops': opcode -> instruction entry, 'kinds':
    operand kind -> entry, 'glsl': ext opcode -> opname}``."""
    missing = [p for p in (CORE_GRAMMAR, GLSL_GRAMMAR) if not p.is_file()]
    if missing:
        raise RuntimeError(
            f"the SPIR-V grammar {missing[0]} is missing; install it with "
            "`apt-get install spirv-headers` (scripts/setup.sh does)"
        )
    core = json.loads(CORE_GRAMMAR.read_text())
    glsl = json.loads(GLSL_GRAMMAR.read_text())
    kinds = {k["kind"]: k for k in core["operand_kinds"]}
    for k in kinds.values():
        if k["category"] in ("ValueEnum", "BitEnum"):
            k["by_value"] = {int(str(e["value"]), 0): e for e in k["enumerants"]}
    return {
        "ops": {i["opcode"]: i for i in core["instructions"]},
        "kinds": kinds,
        "glsl": {i["opcode"]: i["opname"] for i in glsl["instructions"]},
    }


@dataclass
class Instruction:
    """One decoded instruction; ``operands`` are the operands after the result type and id
    (ids as ints, literals as ints or strings, enums as their names, a bit enum as a tuple of
    ``(name, parameters)``); ``line``: ``(file, line)`` of the GLSL source or None."""

    opname: str
    type_id: int | None
    result: int | None
    operands: list
    line: tuple | None = None

    def where(self) -> str:
        """``file:line`` of the instruction's GLSL source, or a note that it has none."""
        if self.line is None:
            return "no source line (compile with debug information)"
        return f"{self.line[0]}:{self.line[1]}"


def _string(words: list, i: int) -> tuple[str, int]:
    raw = b"".join(struct.pack("<I", w) for w in words[i:])
    text = raw.split(b"\0", 1)[0]
    return text.decode("utf-8"), i + len(text) // 4 + 1


def _enumerant_parameters(e: dict, words, i: int) -> tuple[list, int]:
    """The operands an enumerant ``e`` of the grammar takes, read from ``words[i:]``; returns
    (their values, the index after them)."""
    params = []
    for p in e.get("parameters", []):
        v, i = _operand(p["kind"], words, i)
        params.append(v)
    return params, i


def _operand(kind: str, words: list, i: int):
    """Decode one operand of ``kind`` at ``words[i]``: (value, next index)."""
    info = grammar()["kinds"][kind]
    cat = info["category"]
    if kind in _ID_KINDS or cat == "Id":
        return words[i], i + 1
    if kind == "LiteralString":
        return _string(words, i)
    if kind == "LiteralContextDependentNumber":
        return list(words[i:]), len(words)  # the value's width is its type's (the caller's)
    if cat == "Literal":
        return words[i], i + 1
    if cat == "Composite":
        out = []
        for base in info["bases"]:
            v, i = _operand(base, words, i)
            out.append(v)
        return tuple(out), i
    value, i = words[i], i + 1
    if cat == "ValueEnum":
        e = info["by_value"].get(value)
        if e is None:
            raise ValueError(f"SPIR-V: unknown {kind} value {value}")
        params, i = _enumerant_parameters(e, words, i)
        return (e["enumerant"], *params) if params else e["enumerant"], i
    out = []  # BitEnum: each set bit in ascending order, with its parameters
    for bit in range(32):
        if value & (1 << bit):
            e = info["by_value"].get(1 << bit)
            if e is None:
                raise ValueError(f"SPIR-V: unknown {kind} bit {1 << bit:#x}")
            params, i = _enumerant_parameters(e, words, i)
            out.append((e["enumerant"], tuple(params)))
    return tuple(out), i


def decode(words: list) -> list[Instruction]:
    """The instructions of a SPIR-V word stream (after the 5-word header), OpLine applied."""
    g = grammar()
    out, i, line, files = [], 0, None, {}
    while i < len(words):
        count, opcode = words[i] >> 16, words[i] & 0xFFFF
        if count == 0:
            raise ValueError(f"SPIR-V: instruction of zero words at word {i + 5}")
        body = words[i + 1 : i + count]
        i += count
        entry = g["ops"].get(opcode)
        if entry is None:
            raise ValueError(f"SPIR-V: opcode {opcode} is not in the grammar {CORE_GRAMMAR}")
        type_id = result = None
        ops, j = [], 0
        for spec in entry.get("operands", []):
            q = spec.get("quantifier")
            while j < len(body):
                v, j = _operand(spec["kind"], body, j)
                if spec["kind"] == "IdResultType":
                    type_id = v
                elif spec["kind"] == "IdResult":
                    result = v
                else:
                    ops.append(v)
                if q != "*":
                    break
            if q is None and j > len(body):
                raise ValueError(f"SPIR-V: {entry['opname']} is truncated")
        name = entry["opname"]
        if name == "OpString":
            files[result] = ops[0]
        if name == "OpLine":
            line = (files.get(ops[0], "<source>"), ops[1])
            continue
        if name == "OpNoLine":
            line = None
            continue
        out.append(Instruction(name, type_id, result, ops, line))
        if name in _TERMINATORS:
            line = None  # an OpLine does not reach past the end of its block
    return out


@dataclass
class Block:
    """A basic block: its label, body instructions, merge instruction and terminator."""

    label: int
    body: list = field(default_factory=list)
    merge: Instruction | None = None
    terminator: Instruction | None = None

    def successors(self) -> list[int]:
        t = self.terminator
        if t.opname == "OpBranch":
            return [t.operands[0]]
        if t.opname == "OpBranchConditional":
            return [t.operands[1], t.operands[2]]
        if t.opname == "OpSwitch":
            return [t.operands[1]] + [p[1] for p in t.operands[2:]]
        return []


@dataclass
class Function:
    result: int
    blocks: dict  # label -> Block, in module order
    params: list


class Module:
    """A decoded SPIR-V module: ``names`` (id -> OpName), ``decorations`` (id -> {name:
    parameters}), ``defs`` (id -> the instruction defining a type, constant or global
    variable), ``functions`` (id -> :class:`Function`), ``entry`` (the entry point's function
    id, of execution model ``stage``: 'Fragment' or 'Vertex') and ``interface`` (its interface
    variable ids)."""

    def __init__(self, binary: bytes, label: str | None = None, stage: str = "Fragment"):
        if len(binary) % 4 or len(binary) < 20:
            raise ValueError("SPIR-V: a module is a whole number of 32-bit words, at least 5")
        words = list(struct.unpack(f"<{len(binary) // 4}I", binary))
        if words[0] != MAGIC:
            raise ValueError(f"SPIR-V: bad magic number {words[0]:#x} (expected {MAGIC:#x})")
        self.names, self.decorations, self.defs, self.member_names = {}, {}, {}, {}
        self.functions, self.ext_sets = {}, {}
        self.entry, self.interface = None, []
        fn = block = None
        for ins in decode(words[5:]):
            if label is not None and ins.line is not None and _is_main(ins.line[0], label):
                ins.line = (label, ins.line[1])  # the compiled temporary file is the source
            op = ins.opname
            if op == "OpName":
                self.names[ins.operands[0]] = ins.operands[1]
            elif op == "OpMemberName":
                self.member_names.setdefault(ins.operands[0], {})[ins.operands[1]] = ins.operands[2]
            elif op == "OpDecorate":
                dec = ins.operands[1]
                name, params = (dec[0], dec[1:]) if isinstance(dec, tuple) else (dec, ())
                self.decorations.setdefault(ins.operands[0], {})[name] = params
            elif op == "OpExtInstImport":
                self.ext_sets[ins.result] = ins.operands[0]
            elif op == "OpEntryPoint":
                if ins.operands[0] == stage:
                    self.entry, self.interface = ins.operands[1], list(ins.operands[3:])
            elif op == "OpFunction":
                fn = Function(ins.result, {}, [])
                self.functions[ins.result] = fn
            elif op == "OpFunctionParameter":
                fn.params.append(ins.result)
            elif op == "OpFunctionEnd":
                fn = block = None
            elif op == "OpLabel":
                block = Block(ins.result)
                fn.blocks[ins.result] = block
            elif block is not None:
                if op in ("OpSelectionMerge", "OpLoopMerge"):
                    block.merge = ins
                elif op in _TERMINATORS:
                    block.terminator = ins
                    block = None
                else:
                    block.body.append(ins)
            elif ins.result is not None:
                self.defs[ins.result] = ins
        if self.entry is None:
            raise ValueError(f"SPIR-V: the module has no {stage} entry point")

    def name(self, id_: int) -> str:
        return self.names.get(id_, f"%{id_}")

    def binding_name(self, vid: int) -> str:
        """The name a global variable is bound by: ``gl_<BuiltIn>`` for a built-in, else its
        GLSL name."""
        builtin = self.decorations.get(vid, {}).get("BuiltIn")
        return f"gl_{builtin[0]}" if builtin else self.name(vid)

    @functools.cached_property
    def bound_names(self) -> frozenset:
        """The binding names of the module's ``Input``, ``UniformConstant`` and ``Uniform``
        variables, and of the members of a uniform block or struct (``member`` for a block's
        member, ``name.member`` too): what a run may read from its bindings."""
        out = set()
        for vid, ins in self.defs.items():
            if ins.opname == "OpVariable" and ins.operands[0] in ("Input", "UniformConstant",
                                                                  "Uniform"):  # fmt: skip
                out.add(self.binding_name(vid))
                pointee = self.defs[ins.type_id].operands[1]
                block = "Block" in self.decorations.get(pointee, {})
                for name in self.member_names.get(pointee, {}).values():
                    out.add(f"{self.name(vid)}.{name}")
                    if block:
                        out.add(name)
        return frozenset(out)


def _is_main(file: str, label: str) -> bool:
    """Whether an ``OpLine`` file name is the compiled file of ``label`` (not an include)."""
    name = Path(label).name
    return Path(file).name in (name, f"{name}.frag") or not file


def compile_fragment(source: str, label: str, defines: tuple = (), include_paths=()) -> bytes:
    """SPIR-V of a GLSL fragment shader ``source`` in any dialect of ``spirv.dialects``
    (translated to core GLSL there, ``#include`` s searched in ``include_paths``) compiled
    with the preprocessor names ``defines`` (``NAME`` or ``NAME=VALUE``), with debug lines
    naming ``label`` (a file name), optimised by :data:`OPT_PASSES` and validated.
    :class:`~shaders_port.spirv.dialects.ShaderError` with glslang's errors (file and line of
    the user's file) if it does not compile; RuntimeError if a tool is missing."""
    text = without_bool_uniforms(
        front_end(source, label, tuple(defines), tuple(include_paths)), label
    )
    with tempfile.TemporaryDirectory(prefix="spirv-exec.") as d:
        src = Path(d) / Path(label).name
        src = src if src.suffix == ".frag" else src.with_suffix(".frag")
        raw, opt = Path(d) / "raw.spv", Path(d) / "opt.spv"
        src.write_text(text, encoding="utf-8")
        steps = [
            ["glslangValidator", "-G", "--aml", "--amb", "-g", "-S", "frag"]
            + [f"-D{n}" for n in split_defines(defines)[0]]
            + [f"-I{Path(p).resolve()}" for p in include_paths]
            + ["-o", str(raw), src.name],
            ["spirv-opt", *OPT_PASSES, str(raw), "-o", str(opt)],
            ["spirv-val", str(opt)],
        ]
        for args in steps:
            res = subprocess.run(
                [_exe(args[0]), *args[1:]],
                capture_output=True,
                text=True,
                timeout=120,
                check=False,
                cwd=d,
            )
            if res.returncode != 0:
                log = (res.stdout + res.stderr).replace(str(src), label).replace(src.name, label)
                if args[0] == "glslangValidator":
                    raise ShaderError(
                        f"{label} does not compile:\n{glslang_errors(log, label, include_paths)}"
                    )
                raise ShaderError(f"{args[0]} failed on {label}:\n{log.strip()}")
        return opt.read_bytes()


def _exe(name: str) -> str:
    """The path of the program ``name``; RuntimeError naming the Debian package otherwise."""
    package = {"glslangValidator": "glslang-tools"}.get(name, "spirv-tools")
    exe = shutil.which(name)
    if exe is None:
        raise RuntimeError(
            f"{name} not found on PATH; install it with `apt-get install {package}` "
            "(scripts/setup.sh does)"
        )
    return exe


def referenced(mod) -> set:
    """The ids the code of ``mod``'s functions names (every integer operand: an id, or a
    literal that happens to equal one)."""
    out: set = set()

    def walk(x):
        if isinstance(x, int):
            out.add(x)
        elif isinstance(x, (tuple, list)):
            for y in x:
                walk(y)

    for fn in mod.functions.values():
        for b in fn.blocks.values():
            for ins in [*b.body, b.merge, b.terminator]:
                if ins is not None:
                    walk(ins.operands)
    return out


_BOOL_UNIFORM = re.compile(
    r"^(?P<pre>[ \t]*uniform\s+(?:(?:lowp|mediump|highp)\s+)?)bool(?P<post>\s+(?P<name>\w+)\s*;)",
    re.M,
)


def without_bool_uniforms(text: str, label: str) -> str:
    """``text`` (GLSL on its way to SPIR-V for OpenGL, which holds no ``bool`` uniform) with
    each ``uniform bool NAME;`` the code never reads declared ``int`` (an unread uniform changes
    nothing; three.js's program prefix declares ``isOrthographic``); ShaderError naming one
    that is read."""
    code = COMMENTS.sub(" ", text)
    for m in _BOOL_UNIFORM.finditer(code):
        if len(re.findall(rf"\b{m['name']}\b", code)) > 1:
            raise ShaderError(
                f"{label}: uniform bool {m['name']}: SPIR-V for OpenGL has no bool uniform; "
                f"declare it `uniform int {m['name']};` (0 or 1) and read it as `{m['name']} != 0`"
            )
    return _BOOL_UNIFORM.sub(r"\g<pre>int\g<post>", text)
