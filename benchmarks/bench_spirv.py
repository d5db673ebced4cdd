"""The SPIR-V executor against the hand ports: frame time and Jacobian time.

Run: ``.venv/bin/python benchmarks/bench_spirv.py [--size 128] [--n 5] [--threads 1]``. On the
tests/synthetic.py scene at size x size pixels, prints a table of median milliseconds (after
warm-up; port and executor timed in turn, so both see the same load) for each shader variant:
the hand port's render and the executor's (``spirv.translated``: tracing the SPIR-V included,
kernels cached by Dr.Jit), and ``render_with_jacobian`` in four constants both ways, with the
ratios executor / port against the goal 1.5.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

import drjit as dr

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from helpers.synthetic import synthetic_baseline_inputs, synthetic_inputs  # noqa: E402
from shaders_port import Constants  # noqa: E402
from shaders_port.spirv import translated as spirv_port  # noqa: E402
from shaders_port.variants import VARIANTS  # noqa: E402

_RAYCAST = ["attenuation_distance", "bumptex_mult", "steps_grazing", "refr_coeff"]
CASES = {
    "water_refraction": _RAYCAST,
    "water_refraction_secant": _RAYCAST,
    "water_reflection": [
        "attenuation_distance", "bumptex_mult", "refl_steps_grazing", "refr_coeff"
    ],
    "water_baseline": [
        "refraction_strength", "chromatic_dispersion", "reflect_distortion", "refraction_index"
    ],
}  # fmt: skip


def median_ms(fa, fb, n: int) -> tuple[float, float]:
    """Median milliseconds of ``fa`` and of ``fb`` (after two warm-up calls each), timed in
    turn so that both see the same load of the machine."""
    for f in (fa, fb, fa, fb):
        f()
    ta, tb = [], []
    for _ in range(n):
        for f, times in ((fa, ta), (fb, tb)):
            t0 = time.perf_counter()
            f()
            times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(ta), 1e3 * statistics.median(tb)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--n", type=int, default=5)
    ap.add_argument(
        "--threads", type=int, default=0,
        help="Dr.Jit LLVM worker threads (0: its default); 1 steadies times on a shared machine",
    )  # fmt: skip
    args = ap.parse_args()
    if args.threads:
        dr.set_thread_count(args.threads)
    warnings.simplefilter("ignore", RuntimeWarning)
    plain = synthetic_inputs(width=args.size, height=args.size)
    base = synthetic_baseline_inputs(width=args.size, height=args.size)
    c = Constants()
    threads = f", {args.threads} thread(s)" if args.threads else ""
    print(f"{args.size}x{args.size} pixels, median of {args.n} (ms){threads}")
    print("| variant | port frame | SPIR-V frame | ratio | port J(4) | SPIR-V J(4) | ratio |")
    print("|---|---|---|---|---|---|---|")
    for name, names in CASES.items():
        v = VARIANTS[name]
        inputs = base if v.inputs else plain
        spec = spirv_port.builtin_spec(v.shader, v.defines)
        pf, sf = median_ms(
            lambda: v.render(inputs, c).color.numpy(),
            lambda: spirv_port.render(inputs, c, spec=spec).color.numpy(),
            args.n,
        )
        pj, sj = median_ms(
            lambda: v.render_with_jacobian(inputs, c, names),
            lambda: spirv_port.render_with_jacobian(inputs, c, names, spec=spec),
            args.n,
        )
        cells = [f"{pf:.1f}", f"{sf:.1f}", f"{sf / pf:.2f}", f"{pj:.1f}", f"{sj:.1f}"]
        print(f"| {name} | " + " | ".join(cells) + f" | {sj / pj:.2f} |")


if __name__ == "__main__":
    main()
