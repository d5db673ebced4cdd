"""The engine under faults: a full disk, two processes on one new scene, a corrupt kernel cache,
and (slow) a real Dask cluster losing a worker. Ctrl-C in a sweep is part of the tiny tradeoff
through the CLI (``test_tradeoff.py``).

Run by default: the full-disk tests (injected, and a real 256 KiB tmpfs where this user may
mount one), the kernel cache, two calibrations. Slow (``-m slow``): the cluster.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from helpers import REPO
from helpers.experiments import SMALL_OVERRIDES, sets

TESTS = Path(__file__).parent
STUDY = [sys.executable, "-m", "study.cli"]


def _constants_file(tmp_path) -> Path:
    from shaders_port import Constants

    path = tmp_path / "constants.json"
    path.write_text(json.dumps(Constants(bumptex_mult=0.8).to_dict()))
    return path


# ---- a full disk: one line naming the folder, nothing half-written, old entries valid -------


def test_disk_full_is_one_line_and_leaves_nothing(tmp_path, monkeypatch, capsys):
    """ENOSPC injected into the shader export's writes: the CLI prints one line naming the
    output folder and exits 1; no temporary folder is left and the previous export is intact."""
    from study.cli import main

    consts = _constants_file(tmp_path)
    out = tmp_path / "out"
    assert main(["export", str(consts), "--out", str(out)]) == 0
    before = {p: p.read_bytes() for p in (out / "shaders").rglob("*.*")}
    real = Path.write_text
    calls = []

    def full(self, *a, **k):
        calls.append(self)
        if len(calls) > 3:
            raise OSError(errno.ENOSPC, "No space left on device", str(self))
        return real(self, *a, **k)

    monkeypatch.setattr(Path, "write_text", full)
    capsys.readouterr()
    assert main(["export", str(consts), "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no space left" in err[0] and str(out / "shaders") in err[0], err
    assert sorted(p.name for p in out.iterdir()) == ["shaders"]  # no temporary folder
    assert {p: p.read_bytes() for p in (out / "shaders").rglob("*.*")} == before


def test_disk_full_on_a_real_small_filesystem(tmp_path):
    """A 256 KiB tmpfs as the cache: an EXR that does not fit fails with DiskFullError naming
    the folder, leaves no temporary file, and the entry written before still reads back."""
    from study._io import DiskFullError, read_exr, write_exr, write_json

    mnt = tmp_path / "tiny"
    mnt.mkdir()
    if (
        os.geteuid() != 0
        or subprocess.run(
            ["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(mnt)], capture_output=True
        ).returncode
        != 0
    ):
        pytest.skip("mounting a tmpfs needs root (the injected ENOSPC test covers the same path)")
    try:
        small = np.full((8, 8, 3), 0.25, np.float32)
        write_exr(mnt / "refs" / "old.exr", small)
        big = np.random.default_rng(0).random((512, 512, 3)).astype(np.float32)
        with pytest.raises(DiskFullError, match=f"device holding {mnt / 'refs'}"):
            write_exr(mnt / "refs" / "new.exr", big)
        with pytest.raises(DiskFullError, match="no space left"):
            write_json(mnt / "refs" / "big.json", {"x": "y" * 400_000})
        assert sorted(p.name for p in (mnt / "refs").iterdir()) == ["old.exr"]
        assert np.array_equal(read_exr(mnt / "refs" / "old.exr")[0], small)
    finally:
        subprocess.run(["umount", str(mnt)], check=True)


# ---- a stale or foreign kernel cache: rebuilt, never a crash ---------------------------------

_RENDER_PORT = textwrap.dedent("""
    import sys
    sys.path.insert(0, {tests!r})
    import numpy as np
    from helpers.synthetic import synthetic_inputs
    from shaders_port import Constants
    from shaders_port.ports import water_refraction
    out = water_refraction.render(synthetic_inputs(40, 30), Constants(bumptex_mult=0.8)).numpy()
    np.save({out!r}, out["color"])
""")


def test_corrupt_kernel_cache_is_rebuilt(tmp_path):
    """Every cached kernel overwritten with random bytes (same size), one truncated, plus a
    foreign file and a folder in ``DRJIT_CACHE_DIR``: the render succeeds bit for bit."""
    kc = tmp_path / "kernels"
    kc.mkdir()
    env = {**os.environ, "DRJIT_CACHE_DIR": str(kc)}

    def render(name):
        code = _RENDER_PORT.format(tests=str(TESTS), out=str(tmp_path / name))
        r = subprocess.run(
            [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600
        )
        assert r.returncode == 0, r.stderr[-3000:]
        return np.load(tmp_path / name)

    clean = render("clean.npy")
    files = sorted(kc.iterdir())
    assert files, "the render wrote no kernel to DRJIT_CACHE_DIR"
    rng = np.random.default_rng(0)
    for f in files:
        f.write_bytes(rng.integers(0, 256, f.stat().st_size, dtype=np.uint8).tobytes())
    files[0].write_bytes(files[0].read_bytes()[:16])
    (kc / "foreign.txt").write_text("not a kernel")
    (kc / "a_folder.llvm.v6.bin").mkdir()
    assert np.array_equal(render("corrupt.npy"), clean)


# ---- two processes, one new scene: one renders, one waits; the same constants ----------------


def test_two_calibrations_of_one_new_scene(tmp_path):
    env = {**os.environ, "STUDY_CACHE": str(tmp_path / "cache")}
    args = [str(REPO / "experiments" / "default.toml")] + sets(
        SMALL_OVERRIDES + ["fit.max_steps=8"]
    )
    procs = [
        subprocess.Popen(
            STUDY + ["calibrate"] + args + ["--out", str(tmp_path / f"out{i}")],
            env=env,
            cwd=tmp_path,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for i in range(2)
    ]
    outs = [p.communicate(timeout=900)[0] for p in procs]
    assert all(p.returncode == 0 for p in procs), [o[-3000:] for o in outs]
    assert sum("reference: rendered" in o for o in outs) == 1, outs
    assert sum("reference: cached" in o for o in outs) == 1, outs
    consts = [
        json.loads((tmp_path / f"out{i}" / "constants.json").read_text())["constants"]
        for i in range(2)
    ]
    assert consts[0] == consts[1]
    assert not list((tmp_path / "cache").rglob("*.tmp"))


# ---- a real cluster losing a worker ------------------------------------------------------------

TINY_TRADEOFF = SMALL_OVERRIDES + [
    'tradeoff.variants=["water_refraction"]',
    "tradeoff.steps_grazing=[5.0]",
    "tradeoff.steps_steep=[3.0]",
    "tradeoff.loop_cap=[20]",
    "tradeoff.scales=[0.25,0.5,0.75,1.0,1.5,2.0]",
    "tradeoff.converged_scale=4.0",
    "tradeoff.gl_repeats=3",
    "fit.max_steps=5",
]


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_real_cluster_survives_a_killed_worker(tmp_path):
    """``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1; one worker killed with
    SIGKILL once the first rows are in: every point is in the table once, none failed, and the
    rows equal those of a LocalCluster run of the same sweep."""
    from study.sweep import read_table

    dask = str(Path(sys.executable).with_name("dask"))
    port = _free_port()
    env = {**os.environ, "STUDY_CACHE": str(tmp_path / "cache"), "PYTHONPATH": str(REPO)}
    procs = [
        subprocess.Popen(
            [dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    ]
    time.sleep(3)
    try:
        for _ in range(2):
            procs.append(
                subprocess.Popen(
                    [
                        dask,
                        "worker",
                        f"tcp://127.0.0.1:{port}",
                        "--nthreads",
                        "1",
                        "--no-dashboard",
                    ],
                    env=env,
                    cwd=tmp_path,
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                )
            )
        args = ["tradeoff", str(REPO / "experiments" / "default.toml"), "--search", "exhaustive"]
        args += sets(TINY_TRADEOFF)
        run = subprocess.Popen(
            STUDY
            + args
            + ["--out", str(tmp_path / "cluster"), "--scheduler", f"tcp://127.0.0.1:{port}"],
            env=env,
            cwd=tmp_path,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        table = tmp_path / "cluster" / "tradeoff.parquet"
        deadline = time.monotonic() + 900
        while time.monotonic() < deadline and run.poll() is None and not table.exists():
            time.sleep(0.2)
        procs[1].send_signal(signal.SIGKILL)
        log = run.communicate(timeout=1200)[0]
        assert run.returncode == 0, log[-3000:]
    finally:
        for p in procs:
            p.kill()
            p.wait()
    rows = read_table(table)
    assert len({r["key"] for r in rows}) == len(rows) and all(r["status"] == "ok" for r in rows)
    local = subprocess.run(
        STUDY + args + ["--out", str(tmp_path / "local"), "--workers", "2"],
        env=env,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=1200,
    )
    assert local.returncode == 0, local.stderr[-3000:]
    ref = {r["key"]: r for r in read_table(tmp_path / "local" / "tradeoff.parquet")}
    assert set(ref) == {r["key"] for r in rows}
    for r in rows:
        for k in ("flip", "fetches_mean", "loss"):
            if k in r:
                assert r[k] == ref[r["key"]][k], (r["key"], k)
    shutil.rmtree(tmp_path / "cache", ignore_errors=True)
