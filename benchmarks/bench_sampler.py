"""Is a reference sampler unbiased? Mitsuba's samplers side by side on one experiment.

Prints, per sampler (independent, stratified, multijitter):

* the mean correlation of sample dimension d with d+1 (12 dimensions, 4096 pixels at 36 spp):
  a path tracer assumes independent dimensions;
* the mean of the rendered water (linear RGB, over the water pixels) over ``--seeds`` references
  (each the study's ``N_SEEDS`` passes at ``--spp``), with the seed-to-seed SD of that mean and
  the measured per-pixel noise; with ``--grey SIGMA_T`` the same with the water's extinction made
  grey (every channel at ``SIGMA_T``).

A biased sampler shows as a water mean that differs from the independent sampler's by many of
their standard errors (the independent sampler is unbiased by construction).

    .venv/bin/python benchmarks/bench_sampler.py [EXPERIMENT.toml] [--size 128] [--spp 256]
        [--seeds 3] [--grey SIGMA_T]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
SAMPLERS = ("independent", "stratified", "multijitter")


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("experiment", nargs="?", default=str(REPO / "experiments" / "default.toml"))
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument(
        "--grey", type=float, metavar="SIGMA_T", help="every channel's water extinction"
    )
    args = ap.parse_args()

    from study._backend import init_backend
    from study.config.experiment import load_experiment
    from study.scene.mitsuba_scene import dimension_correlation
    from study.scene.reference import render_reference, water_mask

    variant = init_backend("llvm_ad_rgb")
    import mitsuba as mi

    base = load_experiment(args.experiment)
    sets = [
        f"resolution=[{args.size}, {args.size}]",
        f"fit.resolution=[{args.size}, {args.size}]",
        f"reference.spp={args.spp}",
    ]
    if args.grey is not None:
        g = args.grey
        sets.append(f"water.sigma_t=[{g}, {g}, {g}]")
    print(
        f"# bench_sampler: {base['name']}, {args.size}x{args.size}, {args.spp} spp, "
        f"seeds 0-{args.seeds - 1}"
        f"{f', grey water (sigma_t {args.grey})' if args.grey is not None else ''}\n"
    )
    print(
        "| sampler | dimension correlation (d, d+1) | water mean R / G / B | seed SD of "
        "the mean | RMS noise |"
    )
    print("|---|---|---|---|---|")
    for sampler in SAMPLERS:
        means, noise = [], []
        for seed in range(args.seeds):
            exp = load_experiment(
                args.experiment, sets + [f'reference.sampler="{sampler}"', f"reference.seed={seed}"]
            )
            ref = render_reference(exp, variant)
            mask = water_mask(exp, args.size, args.size)
            means.append(ref.image[mask].mean(0))
            noise.append(ref.noise)
        means = np.array(means)
        sd = means.std(0, ddof=1) if len(means) > 1 else np.full(3, np.nan)
        print(
            f"| {sampler} | {dimension_correlation(mi, sampler)[0]:+.4f} | "
            f"{' / '.join(f'{x:.5f}' for x in means.mean(0))} | "
            f"{' / '.join(f'{x:.5f}' for x in sd)} | "
            f"{np.mean(noise):.4f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
