"""Dask clusters for sweeps: an embedded ``LocalCluster`` by default, an existing scheduler by
address, and the Dr.Jit/Mitsuba backend set up once in every worker process.

Dr.Jit is not fork-safe (its LLVM backend owns thread pools and a JIT; its maintainer's word on
forking is that it "is not going to work"), so workers are *spawned* processes
(``distributed.worker.multiprocessing-method = spawn``, Dask's default, set explicitly here and
checked by a test). The parent never needs the backend to run a sweep. Each worker:

* gets ``XLA_FLAGS`` / thread variables and JAX kept on the host
  (``study._backend.JAX_ON_HOST``: several workers share one GPU) through
  ``distributed.nanny.pre-spawn-environ`` (they must be in the environment before the
  interpreter starts);
* runs :class:`BackendPlugin` once on start: ``init_backend(variant)`` (the libLLVM check of
  ``study._backend``) and ``dr.set_thread_count(threads)`` before any scene is built (Embree
  sizes its pool on the first scene).

The address comes from ``scheduler=`` or the ``STUDY_SCHEDULER`` environment variable; with
neither, a LocalCluster with ``workers`` processes (default: one per core) and one Dask thread
each is started and closed with the sweep. The kernel cache (``~/.drjit`` or
``DRJIT_CACHE_DIR``) is shared by the processes; the render cache (``STUDY_CACHE``) must be on a
file system all workers see when the cluster spans machines.
"""

from __future__ import annotations

import contextlib
import os

from distributed.diagnostics.plugin import WorkerPlugin

from .._backend import init_backend, keep_jax_on_host

SCHEDULER_ENV = "STUDY_SCHEDULER"
HEARTBEAT_WAIT_S = 2.5  # longest wait, seconds, for a closing worker's heartbeat to be answered


def cpu_count() -> int:
    """Cores this process may use (the affinity mask, not the machine's count)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


class BackendPlugin(WorkerPlugin):
    """Dask worker plugin: initialise the Mitsuba variant and Dr.Jit's thread count once per
    worker process, before any job runs there."""

    name = "study-backend"

    def __init__(self, variant: str = "llvm_ad_rgb", threads: int = 1):
        """``threads``: Dr.Jit threads of the worker (0: all cores of its machine)."""
        self.variant, self.threads = variant, int(threads)

    def setup(self, worker=None):
        init_backend(self.variant)
        import drjit as dr

        dr.set_thread_count(self.threads or cpu_count())  # 0: every core of the worker's machine
        self._beating = False
        beat = getattr(worker, "periodic_callbacks", {}).get("heartbeat")
        if beat is not None:  # the heartbeat, marked while it runs (see teardown)
            heartbeat = beat.callback

            async def marked():
                self._beating = True
                try:
                    await heartbeat()
                finally:
                    self._beating = False

            beat.callback = marked

    async def teardown(self, worker=None):
        """On a worker's close, stop its heartbeat and let one under way finish before the
        worker shuts its connections. ``Worker.close`` removes plugins first and stops the
        heartbeat and closes its connection pool after; a heartbeat sent just before reads from a
        connection closed under it, and distributed logs that as an error with a traceback (its
        worker does not wait for the heartbeat on close, an open race upstream). The wait is
        bounded by ``HEARTBEAT_WAIT_S``, within the 4 s a nanny gives its worker to exit."""
        import asyncio
        import time

        from distributed.core import Status

        if worker is None or worker.status != Status.closing:
            return  # the plugin is replaced or removed from a running worker: leave it be
        beat = worker.periodic_callbacks.get("heartbeat")
        if beat is not None:
            beat.stop()
        deadline = time.monotonic() + HEARTBEAT_WAIT_S
        while getattr(self, "_beating", False) and time.monotonic() < deadline:
            await asyncio.sleep(0.01)


def scheduler_address(scheduler: str | None = None) -> str | None:
    """``scheduler`` or ``$STUDY_SCHEDULER`` (empty = None)."""
    return scheduler or os.environ.get(SCHEDULER_ENV) or None


@contextlib.contextmanager
def open_client(
    scheduler: str | None = None, workers: int | None = None, variant: str = "llvm_ad_rgb", log=None
):
    """A ``distributed.Client`` with :class:`BackendPlugin` registered on every worker.

    Args:
        scheduler: address of a running Dask scheduler (``tcp://host:8786``); None: the
            ``STUDY_SCHEDULER`` variable, else an embedded LocalCluster.
        workers: LocalCluster worker processes (default: one per core); ignored with a scheduler.
        variant: Mitsuba variant the workers initialise.
    """
    import dask
    from distributed import Client, LocalCluster

    address = scheduler_address(scheduler)
    n = workers or cpu_count()
    if n < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    threads = max(1, cpu_count() // n)
    # XLA's CPU client (the JAX bridge of the fits) starts its own thread pools: keep them to the
    # worker's share of the cores unless the user set XLA_FLAGS
    xla = (
        "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1" if threads == 1 else ""
    )
    env = {
        "XLA_FLAGS": os.environ.get("XLA_FLAGS", xla),
        "OMP_NUM_THREADS": str(threads),
        "LP_NUM_THREADS": os.environ.get("LP_NUM_THREADS", str(threads)),
    }  # llvmpipe's rasteriser
    for k in ("STUDY_CACHE", "DRJIT_LIBLLVM_PATH", "DRJIT_CACHE_DIR", "PYTHONPATH"):
        if k in os.environ:
            env[k] = os.environ[k]
    keep_jax_on_host(env)  # workers sharing one GPU: their JAX stays off it
    config = {
        "distributed.worker.multiprocessing-method": "spawn",
        "distributed.nanny.pre-spawn-environ": env,
        "distributed.worker.daemon": False,
        "distributed.scheduler.worker-ttl": None,
        "distributed.admin.tick.limit": "3h",
        "logging.distributed": "error",
    }
    with dask.config.set(config):
        if address:
            if log:
                log(f"sweep: connecting to the Dask scheduler at {address}")
            cluster = None
            client = Client(address, timeout="30s")
        else:
            cluster = LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                dashboard_address=":0",  # no dashboard wanted: a free port, never 8787
                silence_logs=40,
            )
            client = Client(cluster)
        try:
            # a remote worker sizes Dr.Jit's pool to its own machine, a local one to its share
            client.register_plugin(
                BackendPlugin(variant, 0 if address else threads), name=BackendPlugin.name
            )
            yield client
        finally:
            client.close()
            if cluster is not None:
                close_cluster(cluster, log)


def _gone(pid: int) -> bool:
    """True when process ``pid`` has exited (it may be a zombie not yet reaped)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[-1].split()[0] in ("Z", "X")
    except FileNotFoundError:
        return True
    except OSError:  # no /proc: ask the kernel
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        return False


def close_cluster(cluster, log=None, wait_s: float = 120.0) -> None:
    """Close an embedded ``LocalCluster`` without raising when its worker processes are slow to
    exit. A nanny waits 5 s (``distributed``'s fixed default) for its worker to exit after asking
    it to and then killing it, and raises TimeoutError when a loaded machine takes longer; that
    error would replace a sweep's own outcome (its result, or the interrupt of Ctrl-C). Here the
    worker processes are killed and waited for up to ``wait_s`` seconds instead."""
    import signal
    import time

    pids = []
    for w in list(cluster.workers.values()):
        proc = getattr(getattr(w, "process", None), "process", None)
        if proc is not None and proc.pid is not None:
            pids.append(proc.pid)
    try:
        cluster.close()
    except TimeoutError:
        for pid in pids:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline and not all(_gone(p) for p in pids):
            time.sleep(0.1)
        alive = [p for p in pids if not _gone(p)]
        if log:
            log(
                "sweep: a worker process took longer than the cluster's 5 s to exit; killed"
                + (f" (still alive: {alive})" if alive else "")
            )
