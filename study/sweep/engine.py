"""Run a sweep: many independent jobs as Dask tasks, one tidy Parquet row per job, resumable.

:func:`run_sweep` takes a module-level job function and a list of JSON-able job dicts:

1. every job gets a key (:func:`study.sweep.table.job_key`); rows of the table that already hold
   that key with ``status == "ok"`` are kept and the job is skipped (a re-run resumes; failed
   jobs run again);
2. each distinct ``job["scene"]`` is prepared once (:func:`study.sweep.scenes.prepare_scene`:
   reference and shader inputs rendered under the cache lock) as a task the scene's jobs
   depend on;
3. the jobs run on the workers (``job_fn(job) -> dict``); an exception becomes a row with
   ``status = "error"`` and the message, and the sweep goes on; a worker that dies takes only
   its job with it (Dask reschedules or reports it; either way the row says so);
4. rows are written to the table after each completion (atomic Parquet writes), so a sweep
   stopped at any point keeps every finished row; a progress line counts done/failed/total.

The job function runs in a worker process whose backend was set up by ``BackendPlugin``; it must
be importable by name (a module-level function of an installed package). Jobs that need no
scene leave out the ``scene`` entry.
"""

from __future__ import annotations

import contextlib
import io
import signal
import socket
import sys
import threading
import time
from pathlib import Path

from .._backend import collect_here
from .._kernels import KernelLedger
from .._progress import log as _log
from .._progress import progress_line
from .scenes import prepare_scene, spec_text
from .table import (
    SCHEMA_VERSION,
    clip_error,
    flatten,
    job_columns,
    job_key,
    read_table,
    set_aside,
    write_table,
)


def _qualname(fn) -> str:
    return f"{fn.__module__}.{fn.__qualname__}"


def _run_job(fn, job: dict, key: str, scene_ready=None) -> dict:
    """Worker side: run one job; never raises (the error is the row). What the job prints is
    captured; the last lines are kept in the row (``log_tail``) when it fails. What Dr.Jit
    launched for the job is counted (:func:`kernel_columns`)."""
    t0 = time.perf_counter()
    row = {"key": key, "schema": SCHEMA_VERSION, "status": "ok", "error": None}
    captured = io.StringIO()
    ledger = KernelLedger()
    try:
        with (
            collect_here(),  # no Dr.Jit garbage freed on the event loop's thread (see there)
            contextlib.redirect_stdout(captured),
            contextlib.redirect_stderr(captured),
            ledger,
        ):
            if isinstance(scene_ready, dict) and scene_ready.get("error"):
                raise RuntimeError(f"scene preparation failed: {scene_ready['error']}")
            out = fn(job)
            ledger.take("job")
        if not isinstance(out, dict):
            raise TypeError(
                f"{_qualname(fn)} returned {type(out).__name__}, expected a dict of results"
            )
        row.update(flatten(out))
    except Exception as exc:  # recorded, not raised: one failing job never stops a sweep
        row["status"], row["error"] = "error", clip_error(exc)
        row["log_tail"] = "\n".join(captured.getvalue().replace("\r", "\n").splitlines()[-20:])
    row.update(kernel_columns(ledger.stages.get("job")))
    row["seconds"] = time.perf_counter() - t0
    row["worker"] = socket.gethostname()
    return row


def kernel_columns(summary: dict | None) -> dict:
    """A job's ``study._kernels.kernel_summary`` as row columns: kernels launched, JIT kernels
    compiled / found in the kernel cache / replayed from a recording, their compile ms, memory
    copies and bytes (an empty dict for a job that failed)."""
    if summary is None:
        return {}
    return {
        "kernels_launched": summary["launches"],
        "kernels_compiled": summary["jit_compiled"],
        "kernels_cached": summary["jit_cache_hits"],
        "kernels_replayed": summary["jit_replayed"],
        "kernel_compile_ms": summary["codegen_ms"] + summary["backend_ms"],
        "copies": summary["copies"],
        "copy_bytes": summary["copy_bytes"],
    }


def _prepare(spec: dict, variant: str) -> dict:
    try:
        with collect_here(), contextlib.redirect_stdout(io.StringIO()):
            return prepare_scene(spec, variant)
    except Exception as exc:
        return {"error": clip_error(exc)}


class Progress:
    """One status line on stderr: ``label [#####.....] done/total (n failed) elapsed``."""

    def __init__(self, label: str, total: int, stream=None, width: int = 30):
        # the stream at the time of the sweep (a default bound at import would keep whatever
        # sys.stderr was then, e.g. a capture that is closed since)
        stream = sys.stderr if stream is None else stream
        self.label, self.total, self.stream, self.width = label, total, stream, width
        self.done = self.failed = 0
        self.t0 = time.perf_counter()

    def update(self, ok: bool) -> None:
        self.done += 1
        self.failed += 0 if ok else 1
        self.show()

    def show(self) -> None:
        frac = self.done / self.total if self.total else 1.0
        bar = "#" * round(frac * self.width) + "." * (self.width - round(frac * self.width))
        fail = f", {self.failed} failed" if self.failed else ""
        progress_line(
            f"{self.label} [{bar}] {self.done}/{self.total}{fail} "
            f"{time.perf_counter() - self.t0:.0f} s",
            self.done >= self.total,
            self.stream,
        )


def run_sweep(
    job_fn,
    jobs: list[dict],
    table,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    variant: str = "llvm_ad_rgb",
    label: str = "sweep",
    client=None,
    log=None,
) -> list[dict]:
    """Run ``job_fn`` on every job (see the module doc) and return all rows of the table, in the
    order of ``jobs`` (rows of other jobs already in the table follow them).

    Args:
        job_fn: module-level function ``job -> dict`` of results.
        jobs: JSON-able dicts, each with an optional ``"scene"`` spec.
        table: Parquet path of the sweep's table (read to resume, rewritten as rows finish).
        scheduler: Dask scheduler address (else ``$STUDY_SCHEDULER``, else a LocalCluster).
        workers: LocalCluster worker processes (default one per core).
        client: an open ``distributed.Client`` to use instead of opening one.
    """
    log = log or _log
    table = Path(table)
    name = _qualname(job_fn)
    keys = [job_key(name, j) for j in jobs]
    if len(set(keys)) != len(keys):
        raise ValueError("the sweep holds the same job twice; make every job dict distinct")
    current, aside = set_aside(table, read_table(table))
    if aside is not None:
        log(
            f"{label}: the rows of an earlier version of the study's fit in {table} moved to "
            f"{aside}; their jobs are measured again"
        )
    old = {r["key"]: r for r in current}
    rows = {k: old[k] for k in keys if k in old and old[k].get("status") == "ok"}
    todo = [(k, j) for k, j in zip(keys, jobs) if k not in rows]
    if rows:
        log(f"{label}: {len(rows)} of {len(jobs)} jobs already in {table}; running {len(todo)}")
    if todo:
        if client is None:
            # local: distributed takes 0.65 s to import, paid only when a sweep runs
            from .cluster import open_client

            with open_client(scheduler, workers, variant, log=log) as c:
                _submit_all(c, job_fn, todo, rows, old, table, variant, label)
        else:
            _submit_all(client, job_fn, todo, rows, old, table, variant, label)
    ordered = [rows[k] for k in keys] + [r for k, r in old.items() if k not in rows]
    write_table(table, ordered)
    return ordered


@contextlib.contextmanager
def _ctrl_c():
    """While active, SIGINT (Ctrl-C) sets the yielded event instead of raising wherever the
    main thread happens to be (inside Dask's client, a table write); the sweep loop checks it
    between results and stops cleanly. Outside the main thread, a no-op event."""
    stop = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return
    old = signal.signal(signal.SIGINT, lambda signum, frame: stop.set())
    try:
        yield stop
    finally:
        signal.signal(signal.SIGINT, old)


def _submit_all(client, job_fn, todo, rows, old, table, variant, label) -> None:
    from distributed import as_completed

    scenes = {}
    for _, job in todo:
        spec = job.get("scene")
        if spec is not None and spec_text(spec) not in scenes:
            scenes[spec_text(spec)] = client.submit(
                _prepare, spec, variant, pure=False, key=f"scene-{len(scenes)}-{time.time_ns()}"
            )
    futures = {}
    for key, job in todo:
        spec = job.get("scene")
        dep = scenes[spec_text(spec)] if spec is not None else None
        f = client.submit(
            _run_job, job_fn, job, key, dep, pure=False, key=f"job-{key}-{time.time_ns()}"
        )
        futures[f] = (key, job)
    progress = Progress(label, len(futures))
    progress.show()

    def save():  # the finished rows, then the table's rows of other jobs
        write_table(table, list(rows.values()) + [r for k, r in old.items() if k not in rows])

    last_write = 0.0
    with _ctrl_c() as stop:
        pending = as_completed(list(futures))
        while not pending.is_empty() and not stop.is_set():
            for f in pending.next_batch(block=False):
                key, job = futures[f]
                try:
                    row = f.result()
                except Exception as exc:  # the worker died (e.g. a crash in native code)
                    row = {"key": key, "schema": SCHEMA_VERSION, "status": "error",
                           "error": clip_error(exc), "seconds": None}  # fmt: skip
                rows[key] = {**job_columns(job), **row}
                progress.update(row["status"] == "ok")
                if time.perf_counter() - last_write > 2.0:  # keep finished rows on disk
                    save()
                    last_write = time.perf_counter()
            time.sleep(0.05)
    if stop.is_set():  # Ctrl-C: every finished row is kept, the rest re-run later
        client.cancel(list(futures) + list(scenes.values()))
        save()
        raise KeyboardInterrupt
