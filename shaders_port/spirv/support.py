"""The instructions the SPIR-V executor implements, and a scan of a module for any other, so
that a shader using one is refused when it is loaded rather than at its first render.

The supported set is read from the executor's dispatch itself, not kept as a second list:

* the tables the executor dispatches through: ``spirv.ops.BINARY`` and ``UNARY``,
  ``spirv.images.IMAGE_OPS``, ``spirv.quads.DERIVATIVES``;
* the opcodes the executor's own dispatch methods (``Executor.execute``, ``value_of``,
  ``composite``, ``edges``) compare the instruction's opname with (``op == "OpX"``,
  ``op in ("OpX", ...)``), read from their source with :mod:`ast`;
* for ``OpExtInst``: the ``GLSL.std.450`` set only, its instructions those of
  ``spirv.ops.STD450`` and the names ``spirv.ops.std450`` compares with (``name == ...``).

:func:`check_supported` raises the executor's own error
(:class:`~shaders_port.spirv.loops.UnsupportedInstruction`: the opcode and the GLSL line) for
the first instruction outside that set. What depends on an operand rather than the opcode (a
level that differs between pixels, ``texelFetch`` of a cube map, a derivative in a loop whose
trip count differs between pixels) is still found when the shader runs.
"""

from __future__ import annotations

import ast
import functools
import inspect
import textwrap

from . import ops
from .execute import Executor
from .images import IMAGE_OPS
from .loops import UnsupportedInstruction
from .module import grammar
from .quads import DERIVATIVES

__all__ = ["supported_opcodes", "supported_std450", "check_supported"]

_DISPATCH = ("execute", "value_of", "composite", "edges")


def _compared_names(func, variable: str) -> set[str]:
    """The string constants that ``func``'s source compares the name ``variable`` with
    (``variable == "X"``, ``variable in ("X", "Y")``)."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(func)))
    out: set[str] = set()
    for node in ast.walk(tree):
        if not isinstance(node, ast.Compare) or not isinstance(node.left, ast.Name):
            continue
        if node.left.id != variable:
            continue
        for op, right in zip(node.ops, node.comparators):
            if isinstance(op, ast.Eq) and isinstance(right, ast.Constant):
                out.add(right.value)
            elif isinstance(op, ast.In) and isinstance(right, ast.Tuple):
                out.update(e.value for e in right.elts if isinstance(e, ast.Constant))
    return {s for s in out if isinstance(s, str)}


@functools.cache
def supported_opcodes() -> frozenset:
    """Every SPIR-V opname the executor dispatches (see the module doc)."""
    own = set()
    for name in _DISPATCH:
        own |= _compared_names(getattr(Executor, name), "op")
    tables = set(ops.BINARY) | set(ops.UNARY) | set(IMAGE_OPS) | set(DERIVATIVES)
    return frozenset(own | tables)


@functools.cache
def supported_std450() -> frozenset:
    """Every GLSL.std.450 instruction name ``spirv.ops.std450`` implements."""
    return frozenset(set(ops.STD450) | _compared_names(ops.std450, "name"))


def _unsupported(ins, what: str | None = None) -> UnsupportedInstruction:
    form = f" ({what})" if what else ""
    return UnsupportedInstruction(
        f"the SPIR-V executor does not support {ins.opname}{form}, at {ins.where()}"
    )


def check_supported(module) -> None:
    """Raise :class:`UnsupportedInstruction` (the opcode and its GLSL line, as the executor
    words it) for the first instruction of ``module``'s entry point (every call inlined into
    it) that the executor does not implement; nothing when it implements them all."""
    known, std = supported_opcodes(), supported_std450()
    for b in module.functions[module.entry].blocks.values():
        for ins in [*b.body, b.merge, b.terminator]:
            if ins is None:
                continue
            if ins.opname not in known:
                raise _unsupported(ins)
            if ins.opname == "OpExtInst":
                ext = module.ext_sets.get(ins.operands[0])
                if ext != "GLSL.std.450":
                    raise _unsupported(ins, f"extended set {ext}")
                name = grammar()["glsl"].get(ins.operands[1], str(ins.operands[1]))
                if name not in std:
                    raise _unsupported(ins, f"GLSL.std.450 {name}")
