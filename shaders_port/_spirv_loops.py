"""Loops of the SPIR-V executor (``_spirv_exec``): unrolled, symbolic, or unrolled for AD.

A structured loop (``OpLoopMerge``) is run by :meth:`LoopRunner.loop`:

* if every exit of an iteration is the same for every lane (the condition is a folded Python
  value: a loop over an integer constant), the loop is unrolled in Python;
* otherwise it is a Dr.Jit symbolic loop (``dr.while_loop``) whose state is the function
  variables its blocks store, the cost counters and a lane mask (``break`` clears it); the
  number of passes through its body is kept per lane (``passes``, by loop header);
* with ``differentiate``, the loop is unrolled that many times (``trips``: the largest number
  of passes of each loop over the frame, from a plain run; or found by a symbolic run on
  detached values) under lane masks, so that forward-mode AD sees straight-line code.
"""

from __future__ import annotations

import drjit as dr

from . import _spirv_ops as ops
from ._spirv_ops import TRUE, Mask, both, lift

MAX_UNROLL = 4096  # iterations of a loop with lane-independent exits


class UnsupportedInstruction(NotImplementedError):
    """The shader uses an instruction (or a form of one) the executor does not implement."""


class LoopRunner:
    """The loop methods of ``_spirv_exec.Executor`` (a mixin: it uses the executor's
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
                if not (ex.static and back.static):
                    break
                if back.value is False:
                    return
            else:
                raise self.unsupported(hdr.merge, f"a loop of more than {MAX_UNROLL} iterations")
            self.vars, self.counts = snapshot, counts
            if self.differentiate:
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

    def _state(self, vids):
        """Loop state: the variables lifted to Dr.Jit, and the counters."""
        vals = []
        for vid in vids:
            ptype = self.pointee(vid)
            v = self.vars.get(vid)
            v = self.zero(ptype) if v is None else v
            vals.append(ops.cw(lambda x, k=self.kind(ptype): lift(self.m, x, k), v))
        counts = [lift(self.m, self.counts[k], "float") for k in ("fetches", "iterations")]
        return vals, counts

    def _set_state(self, vids, vals, counts):
        for vid, v in zip(vids, vals):
            self.vars[vid] = v
        self.counts = {"fetches": counts[0], "iterations": counts[1]}

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
                lambda active, vals, counts, passes: active,
                body,
                labels=("active", "vars", "counts", "passes"),
                label=f"spirv_loop_{hdr.label}",
            )
        finally:
            self.detached = False
            self.base = outer
        self._set_state(vids, state[1], state[2])
        return state[3]

    def trip_count(self, hdr, members, merge, counter) -> int:
        """The largest number of body passes of the loop over the frame's lanes (runs it
        symbolically on detached values, then restores the state)."""
        snapshot, counts = dict(self.vars), dict(self.counts)
        passes = self.symbolic_loop(hdr, members, merge, counter, detached=True)
        self.vars, self.counts = snapshot, counts
        return int(dr.max(passes)[0]) if dr.width(passes) else 0
