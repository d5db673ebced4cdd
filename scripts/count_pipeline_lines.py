"""Count the lines of the command layer and of the sweeps' copies of the calibration's work, at
a commit and in the working tree: ``study/commands/``, the tradeoff's export paths and the
studies that fitted, scored and exported on their own (``tradeoff``, ``tradeoff_user``,
``tradeoff_jobs``, ``stability_jobs``, ``tradeoff_motion``), beside the pipeline that now does
that work once (``study/calibration/``) and the tradeoff's export through it.

Usage::

    python scripts/count_pipeline_lines.py --rev f59da82   # a commit against the working tree
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LISTED = ["study/commands/"] + [
    f"study/studies/{n}.py"
    for n in ("tradeoff", "tradeoff_user", "tradeoff_jobs", "stability_jobs", "tradeoff_motion")
]
PIPELINE = ["study/calibration/", "study/studies/tradeoff_export.py"]


def lines(rev: str | None, prefixes: list[str]) -> dict[str, int]:
    """{file: line count} of the ``.py`` files under ``prefixes`` at ``rev`` (None: the tree)."""
    if rev is None:
        files = [
            p
            for pre in prefixes
            for p in sorted(ROOT.glob(pre + ("**/*.py" if pre.endswith("/") else "")))
        ]
        return {str(p.relative_to(ROOT)): len(p.read_text().splitlines()) for p in files}
    names = subprocess.run(["git", "ls-tree", "-r", "--name-only", rev, *prefixes], cwd=ROOT,
                           capture_output=True, text=True, check=True).stdout.split()  # fmt: skip
    out = {}
    for n in names:
        if n.endswith(".py"):
            text = subprocess.run(["git", "show", f"{rev}:{n}"], cwd=ROOT, capture_output=True,
                                  text=True, check=True).stdout  # fmt: skip
            out[n] = len(text.splitlines())
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rev", default="f59da82", help="the commit to compare with")
    args = ap.parse_args(argv)
    before, after = lines(args.rev, LISTED), lines(None, LISTED)
    pipe_before, pipe_after = lines(args.rev, PIPELINE), lines(None, PIPELINE)
    for f in sorted(set(before) | set(after)):
        print(f"{f:45s} {before.get(f, 0):5d} -> {after.get(f, 0):5d}")
    b, a = sum(before.values()), sum(after.values())
    print(f"{'listed files':45s} {b:5d} -> {a:5d} ({a - b:+d})")
    pb, pa = sum(pipe_before.values()), sum(pipe_after.values())
    print(f"{'the pipeline (study/calibration, tradeoff_export)':45s} {pb:5d} -> {pa:5d}")
    print(f"{'together':45s} {b + pb:5d} -> {a + pa:5d} ({a + pa - b - pb:+d})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
