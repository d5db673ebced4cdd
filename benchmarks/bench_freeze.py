"""What ``dr.freeze`` buys: the default experiment's fit and its renders, frozen and traced.

Runs the same calibration (``calibrate_experiment`` on the cached reference) and a loop of
plain renders / Jacobian passes with ``shaders_port.pipeline.frame.USE_FROZEN`` on and off, in one
process, interleaved ``--repeats`` times, and prints median seconds and the ratio. The
reference and shader inputs must be cached (``make run`` first)::

    .venv/bin/python benchmarks/bench_freeze.py [EXPERIMENT.toml] [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
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
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--renders", type=int, default=20)
    args = ap.parse_args()

    from study import init_backend, load_experiment

    init_backend("llvm_ad_rgb")
    from shaders_port.pipeline import frame as _frame
    from study.calibration.frames import load_scene_data
    from study.fit.calibrate import calibrate_experiment
    from study.fit.model import ShaderModel, constants_from_experiment

    exp = load_experiment(args.experiment)
    ref, inputs, _ = load_scene_data(exp, "llvm_ad_rgb", None)
    model = ShaderModel.from_experiment(
        exp, inputs, ref.image, backend="llvm", stderr_full=ref.stderr
    )
    start = constants_from_experiment(exp)

    def fit():
        calibrate_experiment(model, exp)

    def renders():
        for i in range(args.renders):
            model.render(start.replace(bumptex_mult=start.bumptex_mult * (1 + 0.01 * i)))

    def jacobians():
        for i in range(args.renders):
            model.residual_and_jacobian(
                start.replace(bumptex_mult=start.bumptex_mult * (1 + 0.01 * i)),
                ["bumptex_mult", "attenuation_distance"],
            )

    w, h = exp["fit.resolution"]
    other = ShaderModel.from_experiment(
        exp, inputs, ref.image, backend="llvm", resolution=(w // 2, h // 2)
    )

    def alternating():  # a joint fit's pattern: two frames, one after the other
        for i in range(args.renders):
            (model if i % 2 else other).residual_and_jacobian(
                start.replace(bumptex_mult=start.bumptex_mult * (1 + 0.01 * i)),
                ["bumptex_mult", "attenuation_distance"],
            )

    rows = {}
    for label, fn in [
        ("fit (calibrate_experiment)", fit),
        (f"{args.renders} renders", renders),
        (f"{args.renders} Jacobians (2 constants)", jacobians),
        (f"{args.renders} Jacobians, 2 frames alternating", alternating),
    ]:
        times = {True: [], False: []}
        for frozen in (True, False):  # warm-up: compile and record once each
            _frame.USE_FROZEN = frozen
            fn()
        for _ in range(args.repeats):
            for frozen in (True, False):
                _frame.USE_FROZEN = frozen
                t = time.perf_counter()
                fn()
                times[frozen].append(time.perf_counter() - t)
        rows[label] = (statistics.median(times[True]), statistics.median(times[False]))
    _frame.USE_FROZEN = True
    print(
        f"{exp['name']}: fit at {exp['fit.resolution'][0]}x{exp['fit.resolution'][1]}, "
        f"median of {args.repeats}"
    )
    print(f"| {'what':40s} | frozen s | traced s | traced / frozen |")
    print(f"|{'-' * 42}|---------:|---------:|----------------:|")
    for label, (a, b) in rows.items():
        print(f"| {label:40s} | {a:8.3f} | {b:8.3f} | {b / a:15.2f} |")
    print(
        "recordings per frozen function:", sorted(f.n_recordings for f in _frame._FROZEN.values())
    )


if __name__ == "__main__":
    main()
