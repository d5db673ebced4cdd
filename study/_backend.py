"""The one place that chooses the compute backend.

* Finds a libLLVM that Dr.Jit 1.5's LLVM backend can use (LLVM 15 makes the process
  abort with "Cannot select ... fmaximum"; LLVM 19 is tested) and stops with a message
  naming the fix *before* Dr.Jit can abort.
* Sets the Mitsuba variant (``llvm_ad_rgb`` by default, a CUDA variant on request).

Nothing here runs at import time: call :func:`init_backend` from the entry point.
"""

from __future__ import annotations

import contextlib
import gc
import glob
import os
import re

MIN_LLVM_MAJOR = 16
TESTED_LLVM_MAJOR = 19
DEFAULT_VARIANT = "llvm_ad_rgb"
VARIANTS = ("llvm_ad_rgb", "cuda_ad_rgb")
_LIB_DIRS = (
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib/aarch64-linux-gnu",
    "/usr/lib64",
    "/usr/lib",
    "/usr/local/lib",
    "/opt/homebrew/opt/llvm/lib",
    "/usr/local/opt/llvm/lib",
)

FIX = (
    "install a newer libLLVM (Debian/Ubuntu: `apt-get install libllvm19`, or run "
    "`bash scripts/setup.sh`), or point DRJIT_LIBLLVM_PATH at a libLLVM.so of version "
    f">= {MIN_LLVM_MAJOR}"
)


# the fits' JAX (the solvers, FLIP) runs on the host: a JAX built with CUDA on a GPU machine would
# otherwise take most of the GPU's memory at its first array, from Dr.Jit and from every other
# sweep worker on that GPU. Set before JAX starts; a value the user set is kept.
JAX_ON_HOST = {"JAX_PLATFORMS": "cpu", "XLA_PYTHON_CLIENT_PREALLOCATE": "false"}


def keep_jax_on_host(env: dict | None = None) -> dict:
    """Put :data:`JAX_ON_HOST` into ``env`` (default ``os.environ``) where it has no value of
    its own; returns ``env``."""
    env = os.environ if env is None else env
    for key, value in JAX_ON_HOST.items():
        env.setdefault(key, os.environ.get(key, value))
    return env


class BackendError(RuntimeError):
    """The requested backend cannot run on this machine; the message says how to fix it."""


def _major_from_name(path: str) -> int | None:
    m = re.search(r"libLLVM[-.]?(\d+)", os.path.basename(path))
    return int(m.group(1)) if m else None


def find_libllvm() -> list[tuple[int, str]]:
    """Candidate libLLVM shared libraries on this machine as (major version, path), newest first."""
    found: dict[str, int] = {}
    for d in _LIB_DIRS:
        for p in glob.glob(os.path.join(d, "libLLVM*.so*")) + glob.glob(
            os.path.join(d, "libLLVM*.dylib")
        ):
            major = _major_from_name(p)
            if major is not None and os.path.isfile(p):
                found.setdefault(os.path.realpath(p), major)
    return sorted(((v, p) for p, v in found.items()), reverse=True)


_checked: tuple[int, int, int] | None = None


def ensure_llvm() -> tuple[int, int, int]:
    """Make sure Dr.Jit's LLVM backend will load a usable libLLVM; return its version.

    If ``DRJIT_LIBLLVM_PATH`` is unset, the newest libLLVM >= MIN_LLVM_MAJOR found in the
    usual library folders is selected through it. Raises :class:`BackendError` when none
    is usable. Must run before the first Dr.Jit LLVM computation of the process.
    """
    global _checked
    if _checked is not None:
        return _checked
    if not os.environ.get("DRJIT_LIBLLVM_PATH"):
        good = [(v, p) for v, p in find_libllvm() if v >= MIN_LLVM_MAJOR]
        if good:
            os.environ["DRJIT_LIBLLVM_PATH"] = good[0][1]
    import drjit as dr

    version = tuple(dr.detail.llvm_version())
    if version[0] < 0:
        where = os.environ.get("DRJIT_LIBLLVM_PATH", "the default search path")
        raise BackendError(f"Dr.Jit could not load libLLVM (tried {where}); {FIX}.")
    if version[0] < MIN_LLVM_MAJOR:
        raise BackendError(
            f"Dr.Jit found libLLVM {'.'.join(map(str, version))}, which makes Dr.Jit 1.5 abort "
            f"(instruction selection fails on fmaximum); {FIX}."
        )
    _checked = version
    return version


CUDA_FIX = (
    f"run on the CPU with --backend {DEFAULT_VARIANT} (the default; or variant = "
    f'"{DEFAULT_VARIANT}" in the experiment), or on a machine with an NVIDIA GPU and its driver'
)

_active: list[str] = []  # the variant init_backend set in this process


def init_backend(variant: str | None = None) -> str:
    """Check the backend, set the Mitsuba variant and make its Dr.Jit backend the default of
    every port, the SPIR-V executor and the fit's models (``backend=None`` there); return the
    variant in use. The one switch of a run: every stage takes its backend from here.

    Args:
        variant: ``"llvm_ad_rgb"`` (default, CPU) or ``"cuda_ad_rgb"`` (NVIDIA GPU).

    Raises:
        BackendError: an unknown variant, an unusable libLLVM, or a CUDA variant on a machine
            where Dr.Jit finds no CUDA device; the message names the fix.
    """
    variant = variant or DEFAULT_VARIANT
    if variant not in VARIANTS:
        raise BackendError(f"unknown variant {variant!r}; choose one of {', '.join(VARIANTS)}")
    keep_jax_on_host()
    if variant.startswith("llvm"):
        ensure_llvm()
    else:
        import drjit as dr

        if not dr.has_backend(dr.JitBackend.CUDA):
            raise BackendError(
                f"{variant} needs an NVIDIA GPU, and Dr.Jit found no CUDA device on this "
                f"machine (no GPU, or no driver / libcuda.so); {CUDA_FIX}."
            )
    import mitsuba as mi

    try:
        mi.set_variant(variant)
    except Exception as exc:  # e.g. a driver Dr.Jit found but Mitsuba cannot use
        raise BackendError(
            f"cannot use Mitsuba variant {variant!r}: {exc}. Use {DEFAULT_VARIANT} (CPU) instead."
        ) from exc
    # keeps `import study._backend` free of Dr.Jit (its libLLVM check may run before Dr.Jit)
    # local: the ports' default backend, set once the variant is chosen
    from shaders_port.pipeline.texture import set_default_backend

    set_default_backend(drjit_backend(variant))
    _active[:] = [variant]
    return variant


def active_variant() -> str | None:
    """The variant :func:`init_backend` set in this process, or None before it ran."""
    return _active[0] if _active else None


def drjit_backend(variant: str) -> str:
    """The shader port's backend name ("llvm" or "cuda") for a Mitsuba variant."""
    return "cuda" if variant.startswith("cuda") else "llvm"


@contextlib.contextmanager
def collect_here():
    """Python's cyclic garbage collector off while the block runs, then one collection in this
    thread (and the collector restored).

    Dr.Jit takes its state lock before it calls back into Python (a frozen function walking its
    inputs, a log callback) and waits for the GIL there; a thread holding the GIL that frees a
    Dr.Jit variable waits for the state lock (Dr.Jit issue 524's lock inversion). The collector
    runs in whichever thread happens to allocate, so in a Dask worker it collected the Dr.Jit
    garbage of a job on the worker's event-loop thread while the job's thread was inside a
    frozen call, and both threads waited for ever (a multi-start sweep hung so). With the
    collector off, Dr.Jit garbage is freed only by the thread that drops it, or by the
    collection here, in the thread that ran the Dr.Jit work."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        gc.collect()
        if was_enabled:
            gc.enable()


JIT_INPUT_ALIGN = 64  # bytes: an 8-wide float32 vector load needs 32, a cache line is 64


def jit_input(cls, values, dtype=None):
    """``cls(values)`` (a flat Dr.Jit array type such as ``mi.Float``) read from a copy of the
    flattened NumPy ``values`` (cast to ``dtype``, default float32) in memory aligned to
    :data:`JIT_INPUT_ALIGN` bytes.

    Dr.Jit's LLVM backend maps a NumPy array's memory instead of copying it, and a kernel that
    reads it declares its vector loads aligned only when that memory is 32-byte aligned. NumPy's
    allocations are aligned to 16 bytes, sometimes 32, by chance: the same computation on an
    array built the same way then compiles to one of several kernels, each missing the kernel
    cache (in memory and on disk) and compiling anew. An animation's frames built the traced
    skylight and sunlight kernels again on every frame so (0.6 and 0.8 s of LLVM time each)."""
    import numpy as np

    a = np.asarray(values, np.float32 if dtype is None else dtype).ravel()
    buf = np.empty(a.nbytes + JIT_INPUT_ALIGN, np.uint8)
    start = -buf.ctypes.data % JIT_INPUT_ALIGN
    out = buf[start : start + a.nbytes].view(a.dtype)
    out[:] = a
    return cls(out)
