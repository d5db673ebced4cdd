"""Soak: the README's two commands on fresh clones, N times, each test run in another random order.

Each round clones the repository (the committed ``HEAD``) into a new temporary folder, runs
``make run`` and then ``make test`` there with ``pytest-randomly``'s seed set to the round's
seed, and records pass / fail and seconds. Prints one table; the clones are removed unless
``--keep``. Rounds run one after another (the suite uses every core)::

    .venv/bin/python benchmarks/soak.py [--rounds 3] [--seed 1] [--keep]

A clone shares nothing with this checkout but the pip / apt caches and Dr.Jit's kernel cache
(``~/.drjit``, content-addressed), as a user's second clone would.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def _run(cmd: list[str], cwd: Path, env: dict, log: Path) -> tuple[int, float, str]:
    t0 = time.perf_counter()
    with open(log, "w") as f:
        rc = subprocess.run(cmd, cwd=cwd, env=env, stdout=f, stderr=subprocess.STDOUT).returncode
    text = log.read_text(errors="replace")
    return rc, time.perf_counter() - t0, text


def _summary(text: str) -> str:
    lines = [ln for ln in text.splitlines() if re.search(r"\d+ (passed|failed)", ln)]
    return lines[-1].strip("= ") if lines else "no pytest summary"


def _warnings(text: str) -> list[str]:
    """The lines of pytest's warnings summary that name a warning (not the test ids)."""
    if "warnings summary" not in text:
        return []
    block = text.split("warnings summary", 1)[1].split("-- Docs", 1)[0]
    return [ln.strip() for ln in block.splitlines() if "Warning" in ln]


def main() -> None:
    import os

    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1, help="random order seed of the first round")
    ap.add_argument("--keep", action="store_true", help="keep the clones (their logs are in them)")
    args = ap.parse_args()
    head = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    rows = []
    for k in range(args.rounds):
        seed = args.seed + k
        root = Path(tempfile.mkdtemp(prefix=f"soak{k}-"))
        clone = root / "repo"
        subprocess.run(["git", "clone", "-q", str(REPO), str(clone)], check=True)
        env = {key: v for key, v in os.environ.items() if key not in ("STUDY_CACHE", "VIRTUAL_ENV")}
        env["PYTEST_ADDOPTS"] = f"-p randomly -p no:cacheprovider --randomly-seed={seed}"
        rc_run, t_run, _ = _run(["make", "run"], clone, env, root / "run.log")
        rc_test, t_test, text = _run(["make", "test"], clone, env, root / "test.log")
        warn = text.count("frozen function has been recorded") + text.count("FrozenReplayWarning")
        rows.append((k + 1, seed, rc_run, t_run, rc_test, t_test, _summary(text), warn, root))
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=clone, capture_output=True, text=True
        ).stdout.strip()
        print(
            f"round {k + 1} ({commit}): make run rc {rc_run} ({t_run:.0f} s), make test rc "
            f"{rc_test} ({t_test:.0f} s): {_summary(text)}",
            flush=True,
        )
        for line in _warnings(text):
            print(f"    warning: {line}", flush=True)
        if not args.keep and rc_run == 0 and rc_test == 0:
            shutil.rmtree(root, ignore_errors=True)
    print(f"\nsoak of {head}: {args.rounds} fresh clones, make run then make test (random order)")
    print("| round | seed | make run | s | make test | s | pytest | frozen warnings |")
    print("|------:|-----:|---------:|--:|----------:|--:|--------|----------------:|")
    for r, seed, rc1, t1, rc2, t2, summ, warn, root in rows:
        print(
            f"| {r} | {seed} | {'pass' if rc1 == 0 else 'FAIL'} | {t1:.0f} | "
            f"{'pass' if rc2 == 0 else 'FAIL'} | {t2:.0f} | {summ} | {warn} |"
        )
    failed = [str(r[8]) for r in rows if r[2] or r[4]]
    if failed:
        print("logs of the failed rounds:", *failed, sep="\n  ")


if __name__ == "__main__":
    main()
