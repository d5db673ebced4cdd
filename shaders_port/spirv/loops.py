"""Loops of the SPIR-V executor (``spirv.execute``): unrolled, symbolic, or unrolled for AD.

A structured loop (``OpLoopMerge``) is run by :meth:`LoopRunner.loop`:

* if every exit of an iteration is the same for every lane (the condition is a folded Python
  value: a loop over an integer constant), the loop is unrolled in Python;
* otherwise it is a Dr.Jit symbolic loop (``dr.while_loop``) whose state is the function
  variables its blocks store, the cost counters and a lane mask (``break`` clears it); the
  number of passes through its body is kept per lane (``passes``, by loop header); a lane
  still in the loop after :data:`MAX_PASSES` passes is stopped there with ``MAX_PASSES + 1``
  passes, which :func:`check_passes` reports as an error naming the loop's line;
* with ``differentiate``: when only variables updated as ``v = v + X`` (``X`` the same on
  every pass), copies of them and temporaries of one pass (:meth:`LoopRunner.pass_locals`)
  carry derivatives (two probing passes with AD say so), the
  loop runs symbolically on detached values counting each variable's adds, and the
  derivative parts of ``v0 + n X`` are attached after it (:meth:`LoopRunner.replayed_loop`,
  the ports' 'replay'); otherwise it is unrolled its largest trip count (``trips``: over the
  frame, from a plain run; or found by a symbolic run on detached values) under lane masks,
  so that forward-mode AD sees straight-line code.
"""

from __future__ import annotations

import drjit as dr

from . import ops
from .dialects import ShaderError
from .ops import TRUE, Mask, both, lift

MAX_UNROLL = 4096  # iterations of a loop with lane-independent exits
MAX_PASSES = 4096  # passes of one lane through a symbolic loop's body before it is stopped


class UnsupportedInstruction(ShaderError, NotImplementedError):
    """The shader uses an instruction (or a form of one) the executor does not implement."""


def check_passes(module, passes: dict, label: str) -> None:
    """ShaderError if a symbolic loop was stopped at :data:`MAX_PASSES` for some lane
    (``passes``: loop header -> per-lane passes, ``MAX_PASSES + 1`` where stopped), naming the
    loop's GLSL line and how many pixels it did not leave."""
    for header, p in passes.items():
        if not dr.width(p) or int(dr.max(p)[0]) <= MAX_PASSES:
            continue
        n = int(dr.count(p > MAX_PASSES)[0])
        merge = next(
            (f.blocks[header].merge for f in module.functions.values() if header in f.blocks), None
        )
        where = merge.where() if merge is not None else label
        raise ShaderError(
            f"{where}: a loop did not end within {MAX_PASSES} passes for {n} pixel(s) (a loop "
            "that never ends for them?); bound it, e.g. `for (int i = 0; i < N && cond; i++)`"
        )


class LoopRunner:
    """The loop methods of ``spirv.execute.Executor`` (a mixin: it uses the executor's
    ``blocks``, ``vars``, ``counts``, ``base``, ``region`` and ``unsupported``)."""

    def loop_members(self, header: int, merge: int) -> set:
        members, todo = {header}, [header]
        while todo:
            for s in self.blocks[todo.pop()].successors():
                if s not in members and s != merge:
                    members.add(s)
                    todo.append(s)
        return members

    def loop(self, hdr, entry: Mask):
        """Run the loop headed by block ``hdr`` for the lanes of ``entry`` (module doc)."""
        merge = hdr.merge.operands[0]
        members = self.loop_members(hdr.label, merge)
        counter = self.counting_edge(hdr.label, merge)
        outer, snapshot, counts = self.base, dict(self.vars), dict(self.counts)
        self.base = both(outer, entry)
        try:
            for _ in range(MAX_UNROLL):  # lane-independent exits: unroll
                ex, back = self.iteration(hdr.label, members, merge, counter)
                if back.value is False:  # every lane left in this pass (a do {} while (false))
                    return
                if not (ex.static and back.static):
                    break
            else:
                raise self.unsupported(hdr.merge, f"a loop of more than {MAX_UNROLL} iterations")
            self.vars, self.counts = snapshot, counts
            if self.differentiate:
                plan = self.replay_plan(hdr.label, members)
                if plan is not None and self.replay_ok(hdr, members, merge, counter, plan):
                    self.replayed_loop(hdr, members, merge, counter, plan)
                    return
                self.unrolled = True
                if self.trips is not None and hdr.label in self.trips:
                    n = self.trips[hdr.label]
                else:
                    n = self.trip_count(hdr, members, merge, counter)
                for _ in range(n):
                    ex, back = self.iteration(hdr.label, members, merge, counter)
                    self.base = both(self.base, back)
            else:
                passes = self.symbolic_loop(hdr, members, merge, counter)
                old = self.passes.get(hdr.label)
                self.passes[hdr.label] = passes if old is None else dr.maximum(old, passes)
        finally:
            self.base = outer

    def iteration(self, header, members, merge, counter):
        """One pass through the loop body; ``counter`` is the edge that enters the body."""
        outer, self.counter = self.counter, counter
        try:
            return self.region(header, members, TRUE, header, merge)
        finally:
            self.counter = outer

    def counting_edge(self, header: int, merge: int) -> tuple:
        """The edge whose crossing counts one iteration: the branch that does not leave the
        loop of the first conditional branch after the header, or the header itself."""
        label = header
        for _ in range(4):
            t = self.blocks[label].terminator
            if t.opname == "OpBranchConditional" and merge in t.operands[1:]:
                target = t.operands[2] if t.operands[1] == merge else t.operands[1]
                return (label, target)
            if t.opname != "OpBranch":
                break
            label = t.operands[0]
        return (None, header)

    def written(self, members) -> list:
        """Variables stored by the loop's blocks (its Dr.Jit loop state)."""
        out = []
        for label in members:
            for ins in self.blocks[label].body:
                if ins.opname == "OpStore":
                    vid = self.root(ins.operands[0])
                    if vid not in out:
                        out.append(vid)
        return sorted(out)

    def pass_locals(self, header: int, members, merge) -> set:
        """Variables the loop stores that are temporaries of one pass (a variable declared in
        the loop's body): function variables loaded nowhere outside the loop, stored whole in a
        block that every pass runs through before any other access to them in that pass (so
        no value reaches them from an earlier pass). No value, and so no derivative, leaves
        the loop or passes from one pass to the next through them."""
        order = self.order(header, members, header, merge)
        preds: dict = {label: set() for label in order}
        for label in order:
            b = self.blocks[label]
            nested = b.merge is not None and b.merge.opname == "OpLoopMerge" and label != header
            for s in [b.merge.operands[0]] if nested else b.successors():
                if s in preds and s != header:
                    preds[s].add(label)
        dom: dict = {}
        for label in order:  # reverse post-order of a DAG: one pass
            ps = [dom[p] for p in preds[label] if p in dom]
            dom[label] = (set.intersection(*ps) if ps else set()) | {label}
        accesses: dict = {}  # variable -> [(block, index, whole store?)] inside the loop
        outside = set()
        for label, b in self.blocks.items():
            for k, ins in enumerate(b.body):
                if ins.opname not in ("OpLoad", "OpStore"):
                    continue
                vid = self.root(ins.operands[0])
                if label not in members:
                    if ins.opname == "OpLoad":
                        outside.add(vid)
                    continue
                whole = ins.opname == "OpStore" and ins.operands[0] == vid
                accesses.setdefault(vid, []).append((label, k, whole))
        out = set()
        for vid in self.written(members):
            acc = accesses.get(vid, [])
            if vid in self.M.defs or vid in outside or any(a[0] not in dom for a in acc):
                continue  # a global (an output), read after the loop, or in a nested loop
            first = min((a for a in acc if a[2]), key=lambda a: order.index(a[0]), default=None)
            if first is not None and all(
                a == first or (first[0] in dom[a[0]] and (a[0] != first[0] or a[1] > first[1]))
                for a in acc
            ):
                out.add(vid)
        return out

    def _state(self, vids):
        """Loop state: the variables lifted to Dr.Jit, and the counters."""
        vals = []
        for vid in vids:
            ptype = self.pointee(vid)
            v = self.vars.get(vid)
            v = self.zero(ptype) if v is None else v
            vals.append(ops.cw(lambda x, k=self.kind(ptype): lift(self.m, x, k), v))
        counts = [lift(self.m, self.counts[k], "float") for k in sorted(self.counts)]
        return vals, counts

    def _set_state(self, vids, vals, counts):
        for vid, v in zip(vids, vals):
            self.vars[vid] = v
        self.counts = dict(zip(sorted(self.counts), counts))

    def symbolic_loop(self, hdr, members, merge, counter, detached: bool = False):
        """The loop as ``dr.while_loop`` over the variables it stores; returns the per-lane
        number of passes through its body (``detached``: on detached values, the state
        restored by the caller)."""
        m, vids = self.m, self.written(members)
        vals, counts = self._state(vids)
        if detached:
            vals = ops.detach(vals)
        active = m.Bool(True) if self.base.value is True else m.Bool(self.base.value)
        outer = self.base

        def body(active, vals, counts, passes):
            self._set_state(vids, vals, counts)
            self.base = TRUE
            ex, back = self.iteration(hdr.label, members, merge, counter)
            new_vals, new_counts = self._state(vids)
            go = back.value
            return (lift(m, go, "bool"), new_vals, new_counts, passes + 1)

        self.detached = detached
        try:
            state = dr.while_loop(
                (active, vals, counts, m.UInt32(0)),
                lambda active, vals, counts, passes: active & (passes < MAX_PASSES),
                body,
                labels=("active", "vars", "counts", "passes"),
                label=f"spirv_loop_{hdr.label}",
            )
        finally:
            self.detached = False
            self.base = outer
        self._set_state(vids, state[1], state[2])
        return dr.select(state[0], MAX_PASSES + 1, state[3])  # stopped lanes: over the bound

    def trip_count(self, hdr, members, merge, counter) -> int:
        """The largest number of body passes of the loop over the frame's lanes (runs it
        symbolically on detached values, then restores the state)."""
        snapshot, counts = dict(self.vars), dict(self.counts)
        passes = self.symbolic_loop(hdr, members, merge, counter, detached=True)
        self.vars, self.counts = snapshot, counts
        check_passes(self.M, {hdr.label: passes}, "the shader")
        return int(dr.max(passes)[0]) if dr.width(passes) else 0

    # ---- replay: a loop on detached values, derivatives of its affine state attached after --
    def replay_plan(self, header: int, members) -> dict | None:
        """Each variable the loop stores, by how: ``('affine', where)`` (``v = v + X``, ``X``
        the same on every pass: ``('id', X)`` defined outside the loop or ``('var', u)`` a
        load of a variable the loop does not store), ``('copy', u)`` (``w = u``, ``u``
        affine), ``('local',)`` (a temporary of one pass, :meth:`pass_locals`: no derivative
        leaves the loop through it) or ``('other',)``. None when another variable is stored
        twice or in part, or the loop holds another loop."""
        defined = {i.result for b in members for i in self.blocks[b].body if i.result}
        written = set(self.written(members))
        temps = self.pass_locals(header, members, self.blocks[header].merge.operands[0])

        def invariant(x):
            """('id', x) for a value defined outside the loop, ('var', v) for a load inside it
            of a whole variable the loop does not store, else None."""
            if x not in defined:
                return ("id", x)
            d = self._defining(x)
            if d.opname == "OpLoad" and self.root(d.operands[0]) == d.operands[0]:
                return ("var", d.operands[0]) if d.operands[0] not in written else None
            return None

        plan = {}
        for label in members:
            b = self.blocks[label]
            if label != header and b.merge is not None and b.merge.opname == "OpLoopMerge":
                return None
            for ins in b.body:
                if ins.opname != "OpStore":
                    continue
                ptr, vid = ins.operands[0], self.root(ins.operands[0])
                if vid in temps:
                    continue
                if vid in plan or ptr != vid:
                    return None
                src, kind = self._defining(ins.operands[1]), ("other",)
                if src is not None and src.opname == "OpFAdd":
                    for a, inc in (src.operands, src.operands[::-1]):
                        load = self._defining(a)
                        if (
                            load is not None
                            and load.opname == "OpLoad"
                            and load.operands[0] == vid
                            and invariant(inc) is not None
                        ):
                            kind = ("affine", invariant(inc))
                elif src is not None and src.opname == "OpLoad" and src.operands[0] != vid:
                    kind = ("copy", src.operands[0])
                plan[vid] = kind
        for vid, kind in plan.items():
            if kind[0] == "copy" and plan.get(kind[1], ("other",))[0] != "affine":
                plan[vid] = ("other",)
        plan.update((vid, ("local",)) for vid in temps)
        return plan

    def replay_ok(self, hdr, members, merge, counter, plan) -> bool:
        """Whether only affine and copied variables carry derivatives: two passes through the
        body with AD (then undone) store no differentiable value in an 'other' variable."""
        snapshot, counts, base = dict(self.vars), dict(self.counts), self.base
        self.probe = {}
        try:
            for _ in range(2):
                ex, back = self.iteration(hdr.label, members, merge, counter)
                self.base = both(self.base, back)
        finally:
            grads, self.probe = self.probe, None
            self.vars, self.counts, self.base = snapshot, counts, base
        return not any(g and plan[v][0] == "other" for v, g in grads.items())

    def store_hook(self, vid: int, value, eff: Mask) -> None:
        """Called by every store: records differentiable stores (probe) and counts the adds
        and copies of a replayed loop."""
        if self.probe is not None:
            self.probe[vid] = self.probe.get(vid, False) or ops.any_grad(value)
        if self.replay is None or vid not in self.replay:
            return
        kind = self.replay[vid]
        one = 1.0 if eff.value is True else dr.select(eff.value, 1.0, 0.0)
        if kind[0] == "affine":
            self.counts[f"n{vid}"] = self.counts[f"n{vid}"] + one
        elif kind[0] == "copy":
            src, old = self.counts[f"n{kind[1]}"], self.counts[f"k{vid}"]
            self.counts[f"k{vid}"] = src if eff.value is True else dr.select(eff.value, src, old)
            self.counts[f"s{vid}"] = self.counts[f"s{vid}"] + one

    def replayed_loop(self, hdr, members, merge, counter, plan) -> None:
        """The loop symbolically on detached values, then each affine variable ``v`` set to
        its value plus the derivative parts of ``v0 + n X`` (``n`` the adds it took), each
        copy ``w = u`` likewise with the adds ``u`` had taken then: exactly the derivative
        of the unrolled loop (the other variables carry none, ``replay_ok``); values are
        unchanged (the added parts are exact zeros)."""
        init = {v: self.vars.get(v) if self.vars.get(v) is not None else
                self.zero(self.pointee(v)) for v in plan}  # fmt: skip
        for vid, kind in plan.items():
            if kind[0] == "affine":
                self.counts[f"n{vid}"] = 0.0
            elif kind[0] == "copy":
                self.counts[f"k{vid}"], self.counts[f"s{vid}"] = 0.0, 0.0
        self.replay = plan
        try:
            self.symbolic_loop(hdr, members, merge, counter, detached=True)
        finally:
            self.replay = None
        extra = {k: self.counts.pop(k) for k in list(self.counts) if k[0] in "nks"}
        tang = ops.tangent_part

        def increment(where):  # the attached value of an affine variable's increment
            return self.get(where[1]) if where[0] == "id" else self.load(("ptr", where[1], ()))

        for vid, kind in plan.items():
            if kind[0] == "affine":
                n, inc = extra[f"n{vid}"], increment(kind[1])
                self.vars[vid] = ops.cw(
                    lambda v, a, d: v + tang(a) + n * tang(d), self.vars[vid], init[vid], inc
                )
            elif kind[0] == "copy":
                u = kind[1]
                k, stored = extra[f"k{vid}"], extra[f"s{vid}"] > 0.0
                inc = increment(plan[u][1])
                self.vars[vid] = ops.cw(
                    lambda w, a, d, w0: w + dr.select(stored, tang(a) + k * tang(d), tang(w0)),
                    self.vars[vid],
                    init[u],
                    inc,
                    init[vid],
                )
