"""What Dr.Jit launched, per stage: its kernel history summed.

:class:`KernelLedger` switches Dr.Jit's kernel history on (``dr.JitFlag.KernelHistory``: a
record per kernel launch and memory operation, at a very small cost) and, at each
:meth:`KernelLedger.take`, sums what was launched since the last one (:func:`kernel_summary`):
launches by kind, the JIT kernels compiled, found in the kernel cache (in memory or on disk) or
replayed from a frozen function's recording, their code generation and compile milliseconds,
and the memory copies with their bytes (host <-> device on a GPU; on the CPU backend Dr.Jit
copies only what it must, NumPy reads share memory). The benchmarks record it
(``benchmarks/bench_gpu.py``, ``benchmarks/bench_normal_equations.py``).
"""

from __future__ import annotations

import drjit as dr


def kernel_summary(history: list) -> dict:
    """Sums of ``dr.kernel_history()`` entries: ``launches``, ``by_kind`` (kind name -> count),
    ``jit_compiled`` / ``jit_cache_hits`` / ``jit_replayed`` (JIT kernels), ``codegen_ms`` and
    ``backend_ms`` (their code generation and compilation), ``copies`` and ``copy_bytes``
    (``Memcpy`` entries; a copy's ``size`` is its bytes)."""
    out: dict = {"launches": len(history), "by_kind": {}}
    compiled = hits = replayed = 0
    codegen = backend = 0.0
    copies = copy_bytes = 0
    for e in history:
        kind = str(e["type"]).rsplit(".", 1)[-1]
        out["by_kind"][kind] = out["by_kind"].get(kind, 0) + 1
        if e["type"] == dr.KernelType.Memcpy:
            copies += 1
            copy_bytes += int(e.get("size", 0))
        if e["type"] != dr.KernelType.JIT:
            continue
        if "Replay" in str(e.get("recording_mode", "")):
            replayed += 1
        elif e.get("cache_hit") or e.get("cache_disk"):
            hits += 1
        else:
            compiled += 1
        codegen += float(e.get("codegen_time", 0.0))
        backend += float(e.get("backend_time", 0.0))
    out.update(jit_compiled=compiled, jit_cache_hits=hits, jit_replayed=replayed,
               codegen_ms=codegen, backend_ms=backend, copies=copies,
               copy_bytes=copy_bytes)  # fmt: skip
    return out


class KernelLedger:
    """Per-stage kernel summaries: ``with KernelLedger() as k: ...; k.take("fit")``;
    ``k.stages`` maps each stage to its :func:`kernel_summary`."""

    def __init__(self):
        self.stages: dict = {}
        self._was = False

    def __enter__(self) -> "KernelLedger":
        self._was = bool(dr.flag(dr.JitFlag.KernelHistory))
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        dr.kernel_history()  # what came before is no stage's
        return self

    def take(self, stage: str) -> dict:
        """The summary of what was launched since the last take (or the start), as ``stage``."""
        self.stages[stage] = kernel_summary(dr.kernel_history())
        return self.stages[stage]

    def __exit__(self, *exc):
        dr.kernel_history()
        dr.set_flag(dr.JitFlag.KernelHistory, self._was)
        return False
