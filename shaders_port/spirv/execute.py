"""Executes a SPIR-V fragment shader on Dr.Jit types, all pixels at once (one lane each).

The module (``spirv.module.Module``, calls already inlined) is run instruction by instruction
in Python; every instruction becomes the Dr.Jit operations of ``spirv.ops``, so the whole
shader is traced into one kernel, as a hand port is. Control flow:

* a selection (``OpSelectionMerge``) runs both sides, each under the lane mask of its edge
  (``spirv.ops.Mask``); a store under a mask is a ``select``; an ``OpPhi`` selects by the
  masks of its incoming edges; texture fetches are masked;
* a loop (``OpLoopMerge``) whose exits are the same for every lane (a loop over an integer
  constant, e.g. ``for (j = 0; j < REFINE_STEPS; j++)``) is unrolled; any other loop is a
  Dr.Jit symbolic loop (``dr.while_loop``) over the function variables it stores, with a lane
  mask for ``break`` (``spirv.loops``). With ``differentiate=True`` such a loop either runs
  on detached values with the derivatives of its affine state attached after it (the ports'
  'replay', when only variables updated as ``v = v + X`` and their copies carry
  derivatives), or is unrolled its largest trip count over the frame under lane masks, so
  that forward-mode AD sees straight-line code: forward mode through a symbolic loop with
  texture fetches is not trusted (``water_refraction``'s docstring) and is never used. Values
  are the same either way; derivatives are checked against central differences in the tests.

Variables of the ``Input`` and ``UniformConstant`` storage classes are bound by their GLSL
names through ``bindings`` (name -> value: a sampler object of ``pipeline.texture``, a list of
per-lane values for an input, Python floats or lists for a uniform); a name without a binding
is an error naming the variable and its declaration line. An instruction the executor does not
implement raises :class:`UnsupportedInstruction` naming the opcode and the GLSL line.

Costs counted from the translated code, per lane: ``fetches`` (texture samples executed) and
``iterations`` (loop bodies entered, over every loop).
"""

from __future__ import annotations

import struct
from collections import defaultdict

import drjit as dr

from . import ops
from . import quads as _quads
from .images import IMAGE_OPS, ImageOps
from .loops import LoopRunner, UnsupportedInstruction
from .module import grammar
from .ops import TRUE, Mask, both, branch, is_py, join, lift


def module_discards(module) -> bool:
    """Whether the entry point can discard (``OpKill``, ``OpTerminateInvocation``,
    ``OpDemoteToHelperInvocation``)."""
    kills = ("OpKill", "OpTerminateInvocation", "OpDemoteToHelperInvocation")
    return any(
        i.opname in kills
        for b in module.functions[module.entry].blocks.values()
        for i in [*b.body, b.terminator]
    )


class UnboundVariable(ValueError):
    """The shader reads an input, uniform or sampler that nothing binds."""


class Executor(LoopRunner, ImageOps):
    """One run of ``module``'s entry point over the lanes of one frame (see the module doc).

    ``m``: the Dr.Jit type module (``drjit.llvm.ad``); ``bindings``: GLSL name -> value;
    ``differentiate``: unroll lane-dependent loops, ``trips`` times each (loop header ->
    count, from the ``passes`` of a plain run; a loop not in it finds its own)."""

    def __init__(
        self, module, m, bindings: dict, differentiate: bool = False, trips: dict | None = None
    ):
        self.M, self.m, self.bindings = module, m, bindings
        self.differentiate, self.trips = differentiate, trips
        self.passes: dict = {}  # loop header -> per-lane passes through its body (plain runs)
        self.probe = self.replay = None  # see spirv.loops.LoopRunner.replay_ok / replayed_loop
        self.unrolled = False  # a lane-dependent loop was unrolled (it needed its trip count)
        self.env: dict = {}  # SSA id -> value
        self.vars: dict = {}  # variable id -> value (function variables and outputs)
        self.base = TRUE  # lanes the current straight-line code runs for
        self.counts = {"fetches": 0.0, "iterations": 0.0}
        if module_discards(module):  # discards counted per lane (loop state like the costs)
            self.counts["discarded"] = 0.0
        self.detached = False
        self.counter = None  # the edge that counts the iterations of the innermost loop
        self.quads = bindings.get(_quads.QUADS_KEY)  # the lanes' pixel quads (spirv.quads)
        self.lane_loops = 0  # symbolic loops (lane-dependent trip counts) being traced
        self.fn = module.functions[module.entry]
        self.blocks = self.fn.blocks
        self._types: dict = {}

    # ---- types and constants -----------------------------------------------------------------
    def type(self, tid: int) -> tuple:
        """A type as a tuple: ('float',) ('int', signed) ('bool',) ('vector', elem, n)
        ('matrix', column, n) ('array', elem, n) ('struct', members) ('pointer', pointee) ..."""
        t = self._types.get(tid)
        if t is not None:
            return t
        ins = self.M.defs[tid]
        o = ins.operands
        op = ins.opname
        if op == "OpTypeFloat":
            if o[0] != 32:
                raise self.unsupported(ins, f"{o[0]}-bit floats")
            t = ("float",)
        elif op == "OpTypeInt":
            t = ("int", bool(o[1]))
        elif op == "OpTypeBool":
            t = ("bool",)
        elif op in ("OpTypeVector", "OpTypeMatrix"):
            t = (op[6:].lower(), o[0], o[1])
        elif op == "OpTypeArray":
            t = ("array", o[0], self.constant(o[1]))
        elif op == "OpTypeStruct":
            t = ("struct", tuple(o))
        elif op == "OpTypePointer":
            t = ("pointer", o[1], o[0])
        else:
            t = (op,)
        self._types[tid] = t
        return t

    def kind(self, tid: int) -> str:
        """'float' | 'int' | 'uint' | 'bool' of a scalar type or of a vector's components."""
        t = self.type(tid)
        while t[0] in ("vector", "matrix", "array"):
            t = self.type(t[1])
        if t[0] == "int":
            return "int" if t[1] else "uint"
        return t[0]

    def zero(self, tid: int):
        t = self.type(tid)
        if t[0] in ("vector", "matrix", "array"):
            return [self.zero(t[1]) for _ in range(t[2])]
        if t[0] == "struct":
            return [self.zero(s) for s in t[1]]
        return {"float": 0.0, "int": 0, "uint": 0, "bool": False}[self.kind(tid)]

    def constant(self, cid: int):
        ins = self.M.defs[cid]
        op = ins.opname
        if op in ("OpConstant", "OpSpecConstant"):
            k, word = self.kind(ins.type_id), ins.operands[0][0]
            if k == "float":
                return struct.unpack("<f", struct.pack("<I", word))[0]
            return word - (1 << 32) if k == "int" and word >= 1 << 31 else word
        if op in ("OpConstantTrue", "OpSpecConstantTrue"):
            return True
        if op in ("OpConstantFalse", "OpSpecConstantFalse"):
            return False
        if op in ("OpConstantComposite", "OpSpecConstantComposite"):
            return [self.constant(c) for c in ins.operands]
        if op in ("OpConstantNull", "OpUndef"):
            return self.zero(ins.type_id)
        raise self.unsupported(ins)

    def unsupported(self, ins, what: str | None = None) -> UnsupportedInstruction:
        form = f" ({what})" if what else ""
        return UnsupportedInstruction(
            f"the SPIR-V executor does not support {ins.opname}{form}, at {ins.where()}"
        )

    # ---- values ------------------------------------------------------------------------------
    def get(self, vid: int):
        if vid in self.env:
            v = self.env[vid]
        elif vid in self.M.defs:
            ins = self.M.defs[vid]
            if ins.opname == "OpVariable":
                v = ("ptr", vid, ())
            else:
                v = self.constant(vid)
            self.env[vid] = v
        else:
            raise ValueError(f"SPIR-V: id %{vid} is used before it is defined")
        return ops.detach(v) if self.detached and not isinstance(v, tuple) else v

    def global_value(self, vid: int):
        """The bound value of an Input / Uniform / UniformConstant variable: its binding, or
        a struct's or block's members bound one by one (``name.member``; a block's member by
        its own name too; ``name[i].member`` in an array of structs)."""
        ins = self.M.defs[vid]
        key = self.M.binding_name(vid)
        if key in self.bindings:
            return self.bindings[key]
        if len(ins.operands) > 1:  # a uniform's initializer: its value when nothing sets it
            return self.constant(ins.operands[1])
        missing: list = []
        value = self._members(key, self.pointee(vid), missing)
        if not missing:
            return value
        use = next(
            (
                i
                for b in self.blocks.values()
                for i in b.body
                if i.opname == "OpLoad" and self.root(i.operands[0]) == vid
            ),
            ins,
        )
        raise UnboundVariable(
            f"the shader reads {ins.operands[0]} variable {missing[0]!r} (at {use.where()}) but "
            "nothing binds it: bind it to one of the study's inputs in the shader's "
            "declaration (docs/user-shader.md)"
        )

    def _members(self, name: str, tid: int, missing: list):
        """The value of a struct / array of structs bound member by member (see
        :meth:`global_value`); the unbound names are appended to ``missing``."""
        t = self.type(tid)
        if t[0] == "struct":
            names = self.M.member_names.get(tid, {})
            block = "Block" in self.M.decorations.get(tid, {})
            out = []
            for i, sub in enumerate(t[1]):
                member = names.get(i, str(i))
                keys = ([f"{name}.{member}"] if name else []) + ([member] if block else [])
                hit = next((k for k in keys if k in self.bindings), None)
                out.append(self.bindings[hit] if hit else self._members(keys[0], sub, missing))
            return out
        if t[0] == "array" and self.type(t[1])[0] == "struct":
            return [self._members(f"{name}[{i}]", t[1], missing) for i in range(t[2])]
        missing.append(name)
        return None

    def load(self, ptr):
        _, vid, path = ptr
        if vid in self.vars:
            v = self.vars[vid]
        else:
            sc = self.M.defs[vid].operands[0]
            if sc not in ("Input", "UniformConstant", "Uniform"):
                raise UnsupportedInstruction(f"loading from a {sc} variable")
            v = self.global_value(vid)
        for i in path:
            v = self._pick(v, i)
        return ops.detach(v) if self.detached else v

    def _pick(self, v, i):
        """``v[i]``; ``i`` a per-lane Dr.Jit index selects per lane (an index outside the array,
        undefined in GL, gives element 0)."""
        if isinstance(i, int):
            return v[i]
        out = v[0]
        for k in range(1, len(v)):
            out = ops.select_any(self.m, i == k, v[k], out)
        return out

    def store(self, ptr, value, mask: Mask):
        _, vid, path = ptr
        eff = both(self.base, mask)
        if eff.value is False:
            return
        ptype = self.pointee(vid)
        old = self.vars.get(vid)
        if old is None:
            old = self.zero(ptype)

        def put(cur, tid, path, eff):
            if not path:
                if eff.value is True:
                    return value
                return ops.select(self.m, eff.value, value, cur, self.kind(tid))
            t, i = self.type(tid), path[0]
            sub = t[1][i] if t[0] == "struct" else t[1]
            out = list(cur)
            if isinstance(i, int):
                out[i] = put(cur[i], sub, path[1:], eff)
            else:  # an index that differs between pixels: each element where it points
                for k in range(len(cur)):
                    out[k] = put(cur[k], sub, path[1:], both(eff, Mask(i == k)))
            return out

        self.vars[vid] = put(old, ptype, list(path), eff)
        self.store_hook(vid, value, eff)

    def count(self, key: str, mask: Mask):
        eff = both(self.base, mask)
        if eff.value is False:
            return
        one = 1.0 if eff.value is True else dr.select(eff.value, 1.0, 0.0)
        self.counts[key] = self.counts[key] + one

    # ---- running -----------------------------------------------------------------------------
    def run(self) -> dict:
        """Run the entry point; returns {output variable name: value} and sets ``counts``."""
        start = next(iter(self.blocks))
        self.region(start, set(self.blocks), TRUE, None, None)
        outs = {}
        for vid in self.M.interface:
            if self.M.defs[vid].operands[0] == "Output":
                outs[self.M.name(vid)] = self.vars.get(vid)
        if self.quads is not None:  # helper lanes leave no output and cost nothing
            outs = {k: self.quads.shaded_part(self.m, v) for k, v in outs.items()}
            self.counts = {k: self.quads.shaded_part(self.m, v) for k, v in self.counts.items()}
        return outs

    @property
    def discarded(self):
        """Bool per lane: the lanes that ran ``discard`` (or ``demote``); None when the
        shader cannot discard."""
        if "discarded" not in self.counts:
            return None
        return lift(self.m, self.counts["discarded"], "float") > 0.0

    def symbolic_loop(self, *args, **kw):
        self.lane_loops += 1
        try:
            return super().symbolic_loop(*args, **kw)
        except RuntimeError as exc:  # dr.while_loop wraps an error of the shader it traced
            cause = exc.__cause__ or exc.__context__
            if isinstance(cause, (UnsupportedInstruction, UnboundVariable)):
                raise cause from None
            raise
        finally:
            self.lane_loops -= 1

    def discard(self, bm: Mask) -> None:
        """Mark the lanes of ``bm`` (under the current base) discarded."""
        self.count("discarded", bm)

    def release(self) -> None:
        """Drop every Dr.Jit value the run holds (a recorded frozen kernel of a port must not
        see them freed later by the garbage collector)."""
        self.env, self.vars, self.bindings, self.base, self.passes = {}, {}, {}, TRUE, {}
        self.quads = None
        self.counts = {k: 0.0 for k in self.counts}

    def region(self, start, members, mask, header, merge):
        """Run the blocks of ``members`` reachable from ``start`` in topological order under
        lane masks; returns (mask leaving to ``merge``, mask taking the back edge to
        ``header``)."""
        incoming = defaultdict(list)
        incoming[start].append((None, mask))
        out_exit, out_back = [], []
        for label in self.order(start, members, header, merge):
            edges = incoming.pop(label, [])
            bm = join([k for _, k in edges])
            if bm.value is False:
                continue
            block = self.blocks[label]
            if self.counter == (None, label):
                self.count("iterations", bm)
            if block.merge is not None and block.merge.opname == "OpLoopMerge" and label != header:
                self.loop(block, bm)
                if self.discarded is not None:  # lanes that discarded in the loop stop there
                    bm = both(bm, Mask(~self.discarded))
                succ = [(block.merge.operands[0], bm)]
            else:
                for ins in block.body:
                    self.execute(ins, bm, edges)
                succ = self.edges(block.terminator, bm)
            for target, em in succ:
                if self.counter == (label, target):
                    self.count("iterations", em)
                if target == merge:
                    out_exit.append(em)
                elif target == header:
                    out_back.append(em)
                elif target in members:
                    incoming[target].append((label, em))
                else:
                    raise self.unsupported(block.terminator, "a branch out of its construct")
        return join(out_exit), join(out_back)

    def order(self, start, members, header, merge) -> list:
        """Reverse post-order of the region's blocks; a nested loop is one node (its header),
        followed by its merge block."""
        seen, post = set(), []

        def succ(label):
            b = self.blocks[label]
            if b.merge is not None and b.merge.opname == "OpLoopMerge" and label != header:
                return [b.merge.operands[0]]
            return b.successors()

        stack = [(start, iter(succ(start)))]
        seen.add(start)
        while stack:
            label, it = stack[-1]
            for s in it:
                if s in members and s not in seen and s not in (header, merge):
                    seen.add(s)
                    stack.append((s, iter(succ(s))))
                    break
            else:
                post.append(label)
                stack.pop()
        return post[::-1]

    def edges(self, term, bm: Mask) -> list:
        op = term.opname
        if op == "OpBranch":
            return [(term.operands[0], bm)]
        if op == "OpBranchConditional":
            c = self.get(term.operands[0])
            return [
                (term.operands[1], branch(bm, c, True)),
                (term.operands[2], branch(bm, c, False)),
            ]
        if op == "OpSwitch":
            sel, default = self.get(term.operands[0]), term.operands[1]
            signed = self.kind(self._value_type(term.operands[0])) == "int"
            out, rest = [], bm
            for lit, target in term.operands[2:]:
                lit = lit[0] if isinstance(lit, list) else lit
                lit = lit - (1 << 32) if signed and lit >= 1 << 31 else lit
                hit = sel == lit
                out.append((target, branch(rest, hit, True)))
                rest = branch(rest, hit, False)
            return out + [(default, rest)]
        if op in ("OpReturn", "OpUnreachable"):
            return []
        if op in ("OpKill", "OpTerminateInvocation"):
            self.discard(bm)
            return []
        raise self.unsupported(term)

    def _value_type(self, vid: int) -> int:
        ins = self.M.defs.get(vid) or self._defining(vid)
        return ins.type_id

    def root(self, pid: int) -> int:
        ins = self._defining(pid)
        while ins is not None and ins.opname in ("OpAccessChain", "OpInBoundsAccessChain"):
            pid = ins.operands[0]
            ins = self._defining(pid)
        return pid

    def pointee(self, vid: int) -> int:
        """The type id of what variable ``vid`` holds."""
        ins = self.M.defs.get(vid) or self._defining(vid)
        return self.type(ins.type_id)[1]

    def _defining(self, vid: int):
        if not hasattr(self, "_defs"):
            self._defs = {
                i.result: i for b in self.blocks.values() for i in b.body if i.result is not None
            }
        return self._defs.get(vid)

    # ---- instructions ------------------------------------------------------------------------
    def execute(self, ins, bm: Mask, edges):
        op, o = ins.opname, ins.operands
        if op == "OpVariable":
            self.vars[ins.result] = self.get(o[1]) if len(o) > 1 else None
            self.env[ins.result] = ("ptr", ins.result, ())
            return
        if op == "OpStore":
            self.store(self.get(o[0]), self.get(o[1]), bm)
            return
        if op in ("OpLine", "OpNoLine", "OpNop", "OpSelectionMerge", "OpLoopMerge"):
            return
        if op == "OpDemoteToHelperInvocation":
            self.discard(bm)
            return
        value = self.value_of(ins, bm, edges)
        self.env[ins.result] = value

    def value_of(self, ins, bm: Mask, edges):
        op, o, m = ins.opname, ins.operands, self.m
        if op == "OpLoad":
            return self.load(self.get(o[0]))
        if op in ("OpAccessChain", "OpInBoundsAccessChain"):
            _, vid, path = self.get(o[0])
            idx = [self.get(i) for i in o[1:]]  # an index that differs between pixels: a Dr.Jit int
            return ("ptr", vid, path + tuple(idx))
        if op in _quads.DERIVATIVES:
            return self.derivative(ins)
        if op in IMAGE_OPS:
            return self.image_op(ins, bm)
        if op in ops.BINARY:
            return ops.cw(ops.BINARY[op], self.get(o[0]), self.get(o[1]))
        if op in ops.UNARY:
            return ops.cw(ops.UNARY[op], self.get(o[0]))
        if op == "OpExtInst":
            if self.M.ext_sets.get(o[0]) != "GLSL.std.450":
                raise self.unsupported(ins, f"extended set {self.M.ext_sets.get(o[0])}")

            name = grammar()["glsl"].get(o[1], str(o[1]))
            out = ops.std450(m, name, [self.get(a) for a in o[2:]], None)
            if out is None:
                raise self.unsupported(ins, f"GLSL.std.450 {name}")
            return out
        return self.composite(ins, bm, edges)

    def composite(self, ins, bm: Mask, edges):
        op, o, m = ins.opname, ins.operands, self.m
        mul = ops.BINARY["OpFMul"]
        add = ops.BINARY["OpFAdd"]
        if op == "OpCompositeConstruct":
            parts = [self.get(a) for a in o]
            if self.type(ins.type_id)[0] == "vector":
                return [c for p in parts for c in (p if isinstance(p, list) else [p])]
            return parts
        if op == "OpCompositeExtract":
            v = self.get(o[0])
            for i in o[1:]:
                v = v[i]
            return v
        if op == "OpCompositeInsert":
            obj, v = self.get(o[0]), self.get(o[1])

            def ins_at(c, path):
                c = list(c)
                c[path[0]] = obj if len(path) == 1 else ins_at(c[path[0]], path[1:])
                return c

            return ins_at(v, list(o[2:]))
        if op == "OpVectorShuffle":
            a, b = self.get(o[0]), self.get(o[1])
            both_ = a + b
            return [both_[i] if i != 0xFFFFFFFF else 0.0 for i in o[2:]]
        if op == "OpCopyObject":
            return self.get(o[0])
        if op == "OpSelect":
            c, a, b = self.get(o[0]), self.get(o[1]), self.get(o[2])
            k = self.kind(ins.type_id)
            if isinstance(c, list):
                return [ops.select(m, ci, ai, bi, k) for ci, ai, bi in zip(c, a, b)]
            return ops.select(m, c, a, b, k)
        if op == "OpVectorTimesScalar":
            s = self.get(o[1])
            return [mul(x, s) for x in self.get(o[0])]
        if op == "OpMatrixTimesScalar":
            s = self.get(o[1])
            return [[mul(x, s) for x in col] for col in self.get(o[0])]
        if op == "OpMatrixTimesVector":
            cols, v = self.get(o[0]), self.get(o[1])
            out = [mul(c, v[0]) for c in cols[0]]
            for j in range(1, len(cols)):
                out = [add(acc, mul(c, v[j])) for acc, c in zip(out, cols[j])]
            return out
        if op == "OpVectorTimesMatrix":
            v, cols = self.get(o[0]), self.get(o[1])
            return [ops.dot(m, v, col) for col in cols]
        if op == "OpMatrixTimesMatrix":
            a, b = self.get(o[0]), self.get(o[1])
            return [self._mat_vec(a, col) for col in b]
        if op == "OpTranspose":
            a = self.get(o[0])
            return [[col[i] for col in a] for i in range(len(a[0]))]
        if op == "OpDot":
            return ops.dot(m, self.get(o[0]), self.get(o[1]))
        if op in ("OpAny", "OpAll"):
            v = self.get(o[0])
            f = ops.BINARY["OpLogicalOr" if op == "OpAny" else "OpLogicalAnd"]
            out = v[0]
            for x in v[1:]:
                out = f(out, x)
            return out
        if op in ("OpConvertSToF", "OpConvertUToF", "OpConvertFToS", "OpConvertFToU"):
            k = self.kind(ins.type_id)
            py = {"float": float, "int": int, "uint": int}[k]
            return ops.cw(lambda x: py(x) if is_py(x) else lift(m, x, k), self.get(o[0]))
        if op == "OpPhi":
            return self.phi(ins, edges)
        if op == "OpUndef":
            return self.zero(ins.type_id)
        raise self.unsupported(ins)

    def derivative(self, ins):
        """OpDPdx / OpDPdy / OpFwidth and their Fine and Coarse forms (``spirv.quads``)."""
        if self.quads is None:
            raise self.unsupported(ins, "a derivative without the frame's pixel quads")
        if self.lane_loops:
            raise self.unsupported(
                ins,
                "a derivative inside a loop whose trip count differs between pixels (undefined "
                "in GL); take it before the loop",
            )
        axis = _quads.DERIVATIVES[ins.opname]
        return ops.cw(
            lambda v: _quads.derivative(self.m, self.quads, v, axis), self.get(ins.operands[0])
        )

    def _mat_vec(self, cols, v):
        mul, add = ops.BINARY["OpFMul"], ops.BINARY["OpFAdd"]
        out = [mul(c, v[0]) for c in cols[0]]
        for j in range(1, len(cols)):
            out = [add(acc, mul(c, v[j])) for acc, c in zip(out, cols[j])]
        return out

    def phi(self, ins, edges):
        masks = {label: k for label, k in edges}
        pairs = [(self.get(v), p) for v, p in ins.operands]
        live = [(v, masks[p]) for v, p in pairs if p in masks and masks[p].value is not False]
        if not live:
            raise self.unsupported(ins, "a phi whose incoming blocks did not run")
        out = live[-1][0]
        for v, k in live[:-1][::-1]:
            out = ops.select(self.m, k.value, v, out, self.kind(ins.type_id))
        return out
