"""The sweep engine: Dask workers (spawned, backend set up once), resumable tidy tables, failing
jobs recorded, scenes prepared once, the cache lock between real processes."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from helpers import REPO, TESTS, sweep_jobs
from helpers.experiments import SMALL_OVERRIDES as SMALL


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    """One LocalCluster (2 spawned workers) for the module; workers see tests/ and a private
    cache."""
    from study.sweep.cluster import open_client

    mp = pytest.MonkeyPatch()
    mp.setenv("PYTHONPATH", os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")]))
    mp.setenv("STUDY_CACHE", str(tmp_path_factory.mktemp("sweep_cache")))
    with open_client(workers=2) as c:
        yield c
    mp.undo()


def test_workers_are_spawned_and_set_up_once(tmp_path, monkeypatch):
    """Dr.Jit is not fork-safe upstream, so workers are spawned: a forked worker would inherit the
    parent's modules (and the mark set here before the cluster starts)."""
    from study.sweep import run_sweep
    from study.sweep.cluster import cpu_count

    monkeypatch.setenv("PYTHONPATH", str(TESTS))
    monkeypatch.setattr(sweep_jobs, "PARENT_MARK", "changed in the parent")
    for key in ("JAX_PLATFORMS", "XLA_PYTHON_CLIENT_PREALLOCATE"):
        monkeypatch.delenv(key, raising=False)
    rows = run_sweep(
        sweep_jobs.worker_state, [{"i": i} for i in range(3)], tmp_path / "w.parquet", workers=1
    )
    assert all(r["status"] == "ok" for r in rows), rows
    assert {r["mark"] for r in rows} == {"not set"}  # spawned, not forked
    assert {r["variant"] for r in rows} == {"llvm_ad_rgb"}  # the plugin initialised the backend
    assert {r["threads"] for r in rows} == {cpu_count()}  # one worker: every core
    assert len({r["pid"] for r in rows}) == 1  # set up once, reused by every job
    # workers that share one GPU keep their JAX on the host (study._backend.JAX_ON_HOST)
    assert {(r["jax_platforms"], r["jax_preallocate"]) for r in rows} == {("cpu", "false")}


def test_sweep_records_failures_and_resumes(client, tmp_path):
    from study.sweep import read_table, run_sweep

    log = tmp_path / "runs.txt"
    table = tmp_path / "t.parquet"
    jobs = [{"x": i, "log": str(log)} for i in range(5)]
    rows = run_sweep(sweep_jobs.square, jobs, table, client=client)
    by_x = {r["job.x"]: r for r in rows}
    assert by_x[3]["status"] == "error" and "three is refused" in by_x[3]["error"]
    assert [by_x[x]["y"] for x in (0, 1, 2, 4)] == [0, 1, 4, 16]
    assert by_x[2]["nested.a"] == 1.5 and by_x[2]["nested.list"] == [1.0, 2.0]
    assert sorted(log.read_text().split()) == ["0", "1", "2", "3", "4"]
    # a re-run with one more job runs only the new one and the failed one
    rows = run_sweep(sweep_jobs.square, jobs + [{"x": 5, "log": str(log)}], table, client=client)
    assert sorted(log.read_text().split()) == ["0", "1", "2", "3", "3", "4", "5"]
    assert len(rows) == 6 and len(read_table(table)) == 6
    assert {r["job.x"]: r["status"] for r in rows}[5] == "ok"


def test_rows_of_an_earlier_fit_are_set_aside_and_measured_again(client, tmp_path, capsys):
    """A table written before the current ``SCHEMA_VERSION`` (its rows without ``schema``): its
    rows go to a file beside it, never into the results, and their jobs run again."""
    from study.sweep import read_table, run_sweep
    from study.sweep.table import SCHEMA_VERSION, write_table

    table = tmp_path / "t.parquet"
    jobs = [{"x": i, "log": str(tmp_path / "runs.txt")} for i in (1, 2)]
    first = run_sweep(sweep_jobs.square, jobs, table, client=client)
    earlier = [{k: v for k, v in r.items() if k != "schema"} for r in first]  # as version 1 wrote
    write_table(table, earlier)
    rows = run_sweep(sweep_jobs.square, jobs, table, client=client, log=print)
    assert "moved to" in capsys.readouterr().out
    assert len(rows) == 2 and all(r["schema"] == SCHEMA_VERSION for r in rows)
    assert read_table(table) == rows
    assert read_table(tmp_path / "t.schema1.parquet") == earlier
    assert sorted((tmp_path / "runs.txt").read_text().split()) == ["1", "1", "2", "2"]


def test_duplicate_jobs_are_refused(tmp_path):
    from study.sweep import run_sweep

    with pytest.raises(ValueError, match="same job twice"):
        run_sweep(sweep_jobs.square, [{"x": 1}, {"x": 1}], tmp_path / "t.parquet", client=object())


def test_damaged_table_is_named_not_replaced(tmp_path):
    from study.sweep import read_table

    bad = tmp_path / "t.parquet"
    bad.write_bytes(b"not parquet")
    with pytest.raises(ValueError, match="move it away"):
        read_table(bad)
    assert bad.read_bytes() == b"not parquet"


def test_scene_prepared_once_and_shared(client, tmp_path):
    from study.sweep import run_sweep, scene_spec

    spec = scene_spec(REPO / "experiments" / "default.toml", SMALL)
    rows = run_sweep(
        sweep_jobs.scene_job,
        [{"scene": spec, "i": i} for i in range(3)],
        tmp_path / "s.parquet",
        client=client,
    )
    assert all(r["status"] == "ok" for r in rows), [r["error"] for r in rows]
    assert {tuple(r["shape"]) for r in rows} == {(32.0, 32.0, 3.0)}
    refs = list(Path(rows[0]["cache"]).glob("*.exr"))
    assert len(refs) == 1  # one reference file for the three jobs


_RENDER = textwrap.dedent("""
    import sys
    sys.path.insert(0, {tests!r})
    from study import init_backend, load_experiment
    from study.scene.reference import load_or_render
    init_backend("llvm_ad_rgb")
    exp = load_experiment({exp!r}, {small!r})
    load_or_render(exp, "llvm_ad_rgb", log=lambda m: print(m, flush=True))
""")


def test_two_processes_on_one_key_render_once(tmp_path):
    env = {**os.environ, "STUDY_CACHE": str(tmp_path)}
    code = _RENDER.format(
        tests=str(TESTS), exp=str(REPO / "experiments" / "default.toml"), small=SMALL
    )
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", code],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for _ in range(2)
    ]
    outs = [p.communicate(timeout=600)[0] for p in procs]
    assert all(p.returncode == 0 for p in procs), outs
    rendered = sum("reference: rendered" in o for o in outs)
    cached = sum("reference: cached" in o for o in outs)
    assert (rendered, cached) == (1, 1), outs
    assert len(list((tmp_path / "references").glob("*.exr"))) == 1
    assert not list((tmp_path / "references").glob("*.tmp"))


def test_lock_of_a_killed_holder_is_recovered(tmp_path):
    from study._io import file_lock

    lock = tmp_path / "x.lock"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            textwrap.dedent(f"""
        import time
        from study._io import file_lock
        with file_lock({str(lock)!r}):
            print("held", flush=True)
            time.sleep(600)
    """),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert holder.stdout.readline().strip() == "held"
    with pytest.raises(TimeoutError, match="stayed locked"):
        with file_lock(lock, timeout=0.5):
            pass
    holder.send_signal(signal.SIGKILL)
    holder.wait(timeout=30)
    t0 = time.monotonic()
    with file_lock(lock, timeout=10):
        pass
    assert time.monotonic() - t0 < 10


def test_jobs_run_with_the_cyclic_collector_off_and_collect_after(monkeypatch):
    """A job's Dr.Jit garbage must not be freed by the collector on a worker's event-loop thread
    (Dr.Jit's state lock against the GIL: a deadlock seen in a multi-start sweep). The job runs
    with the collector off; afterwards one collection runs in the job's thread and the
    collector is back on."""
    import gc

    from study.sweep.engine import _run_job

    calls = []
    monkeypatch.setattr(gc, "collect", lambda *a: calls.append(a) or 0)
    assert gc.isenabled()
    row = _run_job(sweep_jobs.collector_state, {}, "k")
    assert row["status"] == "ok" and row["gc_enabled"] is False
    assert calls and gc.isenabled()


def test_a_job_row_counts_what_dr_jit_launched_for_it():
    """Each row says what Dr.Jit launched for its job (``study._kernels``): a job that computes
    with Dr.Jit counts its kernels (the first run of a new kernel compiles it or finds it in
    the disk cache), a job that does not counts none; the history is off again after."""
    import drjit as dr

    from study.sweep.engine import _run_job

    n = 1000 + int(time.time_ns() % 100000)  # a kernel shape this process has not run
    row = _run_job(sweep_jobs.drjit_sum, {"n": n}, "k")
    assert row["status"] == "ok"
    assert row["total"] == pytest.approx(sum(i * i + n for i in range(n)), rel=1e-12)
    assert row["kernels_launched"] >= 2  # the kernel and its reduction
    assert row["kernels_compiled"] + row["kernels_cached"] >= 1
    assert row["copies"] >= 1 and row["copy_bytes"] >= 8  # the sum read back
    assert not dr.flag(dr.JitFlag.KernelHistory)
    none = _run_job(lambda job: {"y": 1}, {}, "k2")
    assert none["kernels_launched"] == 0 and none["kernels_compiled"] == 0


def test_a_worker_slow_to_exit_at_close_keeps_the_sweeps_outcome(monkeypatch):
    """A nanny that waits longer than its 5 s for its worker to exit raises TimeoutError from the
    cluster's close (as on a loaded machine after Ctrl-C); the sweep's own outcome, here an
    interrupt, is what the caller sees, and the worker processes are gone."""
    from distributed import LocalCluster

    from study.sweep.cluster import _gone, open_client

    real_close = LocalCluster.close

    def close_then_time_out(self, timeout=None):
        real_close(self, timeout)
        raise TimeoutError  # what distributed's Nanny.kill raises when join() outlasts 5 s

    monkeypatch.setattr(LocalCluster, "close", close_then_time_out)
    said, pids = [], []
    with pytest.raises(KeyboardInterrupt):
        with open_client(workers=1, log=said.append) as c:
            pids += list(c.run(os.getpid).values())
            raise KeyboardInterrupt
    assert len(pids) == 1 and all(_gone(p) for p in pids)
    assert any("took longer than the cluster's 5 s to exit" in m for m in said), said


def test_a_heartbeat_in_flight_at_close_is_not_reported_as_an_error(capfd):
    """A worker closing while its heartbeat waits for the scheduler's answer: distributed's
    ``Worker.close`` shuts its connections under that heartbeat, which it then logs as an error
    with a traceback (in a sweep's output after Ctrl-C). The scheduler here answers heartbeats
    1.5 s late, and the cluster is closed while one waits; the worker's log stays clean."""
    import asyncio
    import threading

    from study.sweep.cluster import open_client

    waiting = threading.Event()
    with open_client(workers=1) as c:
        scheduler = c.cluster.scheduler
        answer = scheduler.handlers["heartbeat_worker"]

        async def late(*args, **kwargs):
            waiting.set()
            await asyncio.sleep(1.5)
            return answer(*args, **kwargs)

        scheduler.handlers["heartbeat_worker"] = late
        assert waiting.wait(30), "no heartbeat reached the scheduler"
    err = capfd.readouterr().err
    assert "during heartbeat" not in err and "Traceback" not in err, err[-3000:]


def test_progress_writes_to_the_stderr_of_its_sweep(monkeypatch):
    """The progress line goes to ``sys.stderr`` as it is when the sweep runs, not as it was when
    the engine was imported (a capture closed since: "I/O operation on closed file")."""
    import io

    from study.sweep.engine import Progress

    now = io.StringIO()
    monkeypatch.setattr(sys, "stderr", now)
    p = Progress("screen", 2)
    p.update(True)
    p.update(False)
    assert "screen [" in now.getvalue() and "2/2, 1 failed" in now.getvalue()
