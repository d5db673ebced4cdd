"""Reference cost and noise on an experiment (default: experiments/default.toml).

Prints, in one run: render seconds and the measured noise (RMS standard error on water
pixels, linear RGB, from 4 independent seeds) at 64 / 256 / 1024 spp, the noise x sqrt(spp)
product (constant if the estimate is sound and the sampler independent; it falls with spp for the
multi-jittered sampler, ``--set reference.sampler='"independent"'`` compares), \
and the spp the automatic
choice picks. A jittered sampler's spp are rounded up to its grid per pass.

    .venv/bin/python benchmarks/bench_reference.py [EXPERIMENT.toml] [--set KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("experiment", nargs="?", default=str(REPO / "experiments" / "default.toml"))
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    ap.add_argument("--spp", type=int, nargs="+", default=[64, 256, 1024])
    args = ap.parse_args()

    from study import init_backend, load_experiment
    from study.scene.reference import (
        N_SEEDS,
        choose_spp,
        noise_of,
        pass_spp,
        render_passes,
        water_mask,
    )

    init_backend("llvm_ad_rgb")
    exp = load_experiment(args.experiment, args.overrides)
    w, h = exp["resolution"]
    mask = water_mask(exp, w, h)
    print(
        f"experiment {exp['name']}: {w}x{h}, {int(mask.sum())} water pixels, "
        f"{N_SEEDS} independent seeds per estimate, {exp['reference.sampler']} sampler"
    )
    print(f"{'spp':>6} {'seconds':>9} {'noise':>10} {'noise*sqrt(spp)':>16} {'mean':>8}")
    for asked in args.spp:
        t0 = time.perf_counter()
        per_pass = pass_spp(exp, asked)
        spp = per_pass * N_SEEDS
        passes = render_passes(exp, per_pass, N_SEEDS, seed0=1000 + asked)
        sec = time.perf_counter() - t0
        _, noise = noise_of(passes, mask)
        print(
            f"{spp:>6} {sec:>9.2f} {noise:>10.4g} {noise * math.sqrt(spp):>16.4g} "
            f"{passes.mean(0)[mask].mean():>8.4f}",
            flush=True,
        )
    t0 = time.perf_counter()
    spp, info = choose_spp(exp)
    print(
        f"auto spp for target noise {exp['reference.target_noise']}: {spp} "
        f"(predicted need {info['predicted_spp']:.0f}, capped: {info['capped']}, "
        f"pilot {info['pilot_spp']} spp noise {info['pilot_noise']:.4g}, "
        f"{time.perf_counter() - t0:.1f} s)"
    )


if __name__ == "__main__":
    main()
