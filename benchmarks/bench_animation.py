"""The animated calibration, cold and warm: wall and CPU seconds against the 3-minute target.

Runs ``study calibrate experiments/animated.toml`` (8 frames of the default scene) in a fresh
process on a fresh private ``STUDY_CACHE`` (cold: every frame's reference and shader inputs
made), then once more on the same cache (warm: every frame cached), and prints a table of the
wall seconds, the CPU seconds of the process (all threads: on a loaded machine CPU seconds
measure the work, wall seconds the wait) and the load average, then the job's own stage times
(``constants.json``'s ``timings``: references and inputs summed over the frames, fits,
evaluation, export, GL check, figures).

    .venv/bin/python benchmarks/bench_animation.py [--experiment experiments/animated.toml]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
TARGET_S = 180.0


def run(experiment: str, cache: Path, out: Path) -> dict:
    """One ``study calibrate`` in a fresh process: wall s, CPU s, load average, its timings."""
    env = {**os.environ, "STUDY_CACHE": str(cache)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(
        [str(REPO / ".venv" / "bin" / "study"), "calibrate", experiment, "--out", str(out)],
        env=env,
        check=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    timings = json.loads((out / "constants.json").read_text())["timings"]
    return {"wall": wall, "cpu": cpu, "load": os.getloadavg()[0], "timings": timings}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--experiment", default=str(REPO / "experiments" / "animated.toml"))
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        runs = {
            "cold": run(args.experiment, tmp / "cache", tmp / "cold"),
            "warm": run(args.experiment, tmp / "cache", tmp / "warm"),
        }
    print(f"| run | wall s | CPU s | load average | within {TARGET_S:.0f} s |")
    print("|---|---|---|---|---|")
    for name, r in runs.items():
        ok = "yes" if r["wall"] <= TARGET_S else "no"
        print(f"| {name} | {r['wall']:.1f} | {r['cpu']:.1f} | {r['load']:.2f} | {ok} |")
    print()
    stages = [k for k in runs["cold"]["timings"] if not k.startswith("frame")]
    print("| stage | cold s | warm s |")
    print("|---|---|---|")
    for k in stages:
        print(
            f"| {k} | {runs['cold']['timings'][k]:.1f} | "
            f"{runs['warm']['timings'].get(k, float('nan')):.1f} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
