"""Sweep engine scaling and the time of the default tradeoff study.

Prints two tables:

1. jobs per minute of real tradeoff point jobs (refit + full-resolution FLIP + GL and port frame
   times) on the default experiment with 1 and 2 local Dask workers, cluster start-up timed apart;
2. wall time of ``study tradeoff experiments/default.toml`` with the shipped grid (reference and
   shader inputs cached beforehand; a fresh output folder, so nothing is resumed).

Usage: ``.venv/bin/python benchmarks/bench_sweep.py [--jobs 8] [--skip-study]``. The render cache
(``STUDY_CACHE``, default ``.cache/``) is shared with ``make run``.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
DEFAULT = REPO / "experiments" / "default.toml"


def scaling(n_jobs: int) -> list[dict]:
    from study.fit.model import constants_from_experiment
    from study.config.experiment import load_experiment
    from study.studies.tradeoff_jobs import point_job, schedules
    from study.sweep import run_sweep, scene_spec
    from study.sweep.cluster import open_client

    exp = load_experiment(DEFAULT)
    spec = scene_spec(DEFAULT)
    start = constants_from_experiment(exp).to_dict()
    sched = schedules(exp, "water_refraction")[:n_jobs]
    jobs = [
        {
            "scene": spec,
            "experiment": exp["name"],
            "variant": "water_refraction",
            "kind": s["kind"],
            "scale": s["scale"],
            "schedule": s["schedule"],
            "start": start,
        }
        for s in sched
    ]
    out = []
    for workers in (1, 2):
        tmp = Path(tempfile.mkdtemp(prefix="bench_sweep."))
        t0 = time.perf_counter()
        with open_client(workers=workers) as client:
            client.wait_for_workers(workers)
            t1 = time.perf_counter()
            rows = run_sweep(
                point_job, jobs, tmp / "t.parquet", client=client, label=f"{workers} worker(s)"
            )
            t2 = time.perf_counter()
        shutil.rmtree(tmp, ignore_errors=True)
        ok = sum(r["status"] == "ok" for r in rows)
        out.append(
            {
                "workers": workers,
                "startup_s": t1 - t0,
                "jobs": len(jobs),
                "ok": ok,
                "sweep_s": t2 - t1,
                "jobs_per_min": 60 * len(jobs) / (t2 - t1),
            }
        )
    return out


def prime_cache() -> None:
    """Render (or find) the default reference and shader inputs, outside the timings."""
    from study import init_backend, load_experiment
    from study.scene.reference import load_or_render
    from study.scene.shader_inputs import load_or_build_shader_inputs

    exp = load_experiment(DEFAULT)
    init_backend("llvm_ad_rgb")
    load_or_render(exp, "llvm_ad_rgb")
    load_or_build_shader_inputs(exp, "llvm_ad_rgb")


def study_time() -> dict:
    import subprocess
    import sys

    tmp = Path(tempfile.mkdtemp(prefix="bench_tradeoff."))
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "study.cli", "tradeoff", str(DEFAULT), "--out", str(tmp)],
        check=True,
        cwd=REPO,
    )
    seconds = time.perf_counter() - t0
    import json

    summary = json.loads((tmp / "summary.json").read_text())
    shutil.rmtree(tmp, ignore_errors=True)
    return {"seconds": seconds, "points": summary["n_points"], "failed": summary["n_failed"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=8)
    ap.add_argument("--skip-study", action="store_true")
    args = ap.parse_args()
    prime_cache()
    rows = scaling(args.jobs)
    print("\n| workers | cluster start s | jobs | ok | sweep s | jobs / min | speed-up |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['workers']} | {r['startup_s']:.1f} | {r['jobs']} | {r['ok']} | "
            f"{r['sweep_s']:.1f} | "
            f"{r['jobs_per_min']:.1f} | {r['jobs_per_min'] / rows[0]['jobs_per_min']:.2f}x |"
        )
    if not args.skip_study:
        s = study_time()
        print("\n| study | points | failed | wall s | wall min |")
        print("|---|---|---|---|---|")
        print(
            f"| study tradeoff experiments/default.toml | {s['points']} | {s['failed']} | "
            f"{s['seconds']:.0f} | {s['seconds'] / 60:.1f} |"
        )


if __name__ == "__main__":
    main()
