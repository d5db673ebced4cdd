"""Job functions for the sweep tests (importable by the spawned workers through PYTHONPATH)."""

import os
from pathlib import Path

PARENT_MARK = "not set"  # the parent test process changes it; a spawned worker never sees that


def square(job: dict) -> dict:
    """Appends one line per execution to ``job["log"]`` so tests can count executions."""
    with open(job["log"], "a") as f:
        f.write(f"{job['x']}\n")
    if job["x"] == 3:
        raise ValueError("three is refused on purpose")
    return {"y": job["x"] ** 2, "nested": {"a": 1.5, "list": [1, 2]}}


def worker_state(job: dict) -> dict:
    """What a worker process looks like from inside: the mark, Dr.Jit's threads, the variant."""
    import drjit as dr
    import mitsuba as mi

    return {
        "mark": PARENT_MARK,
        "threads": dr.thread_count(),
        "variant": mi.variant(),
        "pid": os.getpid(),
        "jax_platforms": os.environ.get("JAX_PLATFORMS"),
        "jax_preallocate": os.environ.get("XLA_PYTHON_CLIENT_PREALLOCATE"),
    }


def scene_job(job: dict) -> dict:
    from study.sweep import load_scene

    exp, ref, inputs = load_scene(job["scene"])
    return {
        "shape": list(ref.image.shape),
        "spp": ref.spp,
        "tex": inputs.refraction_texture.shape[0],
        "cache": str(Path(ref.path).parent),
    }


def collector_state(job: dict) -> dict:
    """Whether Python's cyclic collector runs while a job runs (it must not: see
    ``study._backend.collect_here``)."""
    import gc

    return {"gc_enabled": gc.isenabled()}


def drjit_sum(job: dict) -> dict:
    """A job that launches Dr.Jit kernels: the sum of ``job["n"]`` values, read back."""
    import drjit as dr
    from drjit.llvm import Float64

    x = dr.arange(Float64, int(job["n"]))
    return {"total": float(dr.sum(x * x + job["n"])[0])}
