"""Adaptive against exhaustive ``study tradeoff``: time, points measured, recommendation, FLIP.

Runs both searches on the same experiments, the same shader space (``tradeoff.fix`` pins axes
so that the exhaustive grid stays affordable) and the same schedule grid, one after the other
on the same local cluster size, and prints one table; ``--json`` writes the figures (what
``scripts/build_docs.py`` turns into ``docs/results/search/report.md``). Agreement: the same
shader configuration, a schedule within one grid step (each step count within a factor of 2),
FLIP within 1 %.

    .venv/bin/python benchmarks/bench_search.py experiments/default.toml --out out/bench_search \\
        --json docs/results/search/bench.json

Add ``--set KEY=VALUE`` for the experiments (repeatable); the defaults pin the axes given by
``--fix`` (default: textures=float, layers=4, refine=linear, specular=phong) and use the grid
``--grid`` (default: the seed's schedule scaled by 0.5, 1, 2 and the 2 x 2 x 2 grid).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

FIX = ["textures=float", "layers=4", "refine=linear", "specular=phong"]
GRID = [
    "tradeoff.scales=[0.5, 1.0, 2.0]",
    "tradeoff.steps_grazing=[5.0, 20.0]",
    "tradeoff.steps_steep=[1.5, 6.0]",
    "tradeoff.loop_cap=[20, 40]",
]


def within_a_step(a: dict, b: dict) -> bool:
    """Every step count of the two schedules within a factor of 2 (loopless: both empty)."""
    if not a or not b:
        return not a and not b
    return all(max(a[k], b[k]) <= 2.0 * min(a[k], b[k]) for k in a if k in b)


def run(mode: str, experiments, out: Path, overrides, workers: int) -> dict:
    from study.studies.tradeoff import run_tradeoff

    t0 = time.perf_counter()
    summary = run_tradeoff(
        experiments, out / mode, overrides, workers=workers, search=mode, log=lambda m: None
    )
    seconds = time.perf_counter() - t0
    scenes = {}
    for name, f in summary["scenes"].items():
        rec = f["recommended"]
        scenes[name] = {
            "recommended": rec["label"] if rec else None,
            "variant": rec["variant"] if rec else None,
            "schedule": rec["schedule"] if rec else None,
            "flip": rec["flip"] if rec else None,
            "fetches": rec["fetches_mean"] if rec else None,
            "seed_flip": (f.get("seed") or {}).get("flip"),
        }
    s = summary["search"]
    return {
        "mode": mode,
        "seconds": seconds,
        "screen_points": s.get("screened", 0),
        "full_points": s["points_in_full"],
        "scenes": scenes,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("experiments", nargs="*", default=[str(REPO / "experiments/default.toml")])
    ap.add_argument("--out", default="out/bench_search")
    ap.add_argument("--fix", nargs="*", default=FIX)
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", default=None, help="write the figures here")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(REPO))
    overrides = GRID + [f"tradeoff.fix={json.dumps(args.fix)}"] + args.overrides
    out = Path(args.out)
    results = [
        run(m, args.experiments, out, overrides, args.workers) for m in ("adaptive", "exhaustive")
    ]
    ada, exh = results
    agree = {}
    for name, a in ada["scenes"].items():
        e = exh["scenes"][name]
        agree[name] = {
            "same_shader": a["variant"] == e["variant"],
            "schedule_within_a_step": within_a_step(a["schedule"] or {}, e["schedule"] or {}),
            "flip_within_1_percent": abs(a["flip"] - e["flip"]) <= 0.01 * e["flip"],
        }
    head = f"{'search':<11}{'seconds':>9}{'screen':>8}{'full':>6}"
    print(head + "  scene: recommendation (FLIP, fetches)")
    for r in results:
        recs = "; ".join(
            f"{n}: {s['recommended']} ({s['flip']:.4f}, {s['fetches']:.1f})"
            for n, s in r["scenes"].items()
        )
        cells = f"{r['mode']:<11}{r['seconds']:>9.0f}{r['screen_points']:>8}"
        print(f"{cells}{r['full_points']:>6}  {recs}")
    print(f"time ratio adaptive / exhaustive: {ada['seconds'] / exh['seconds']:.3f}")
    for name, a in agree.items():
        print(f"{name}: " + ", ".join(f"{k} {v}" for k, v in a.items()))
    if args.json:
        payload = {
            "command": "python benchmarks/bench_search.py "
            + " ".join(sys.argv[1:] if argv is None else argv),
            "fix": args.fix,
            "grid": GRID,
            "results": results,
            "agreement": agree,
            "time_ratio": ada["seconds"] / exh["seconds"],
        }
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(payload, indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
