"""Port (Dr.Jit LLVM) vs GLSL (Mesa llvmpipe) frame times, and the Jacobian's cost.

Run: ``.venv/bin/python benchmarks/bench_port.py [--size 512] [--n 7]``. On the
tests/synthetic.py scene at size x size pixels (textures 256^2), prints a table of median
milliseconds per frame (after warm-up) for each shader variant: the port's forward pass
(render + evaluation of colour and diagnostics, no read-back), the core GLSL on llvmpipe
(draw + glFinish, no read-back), and ``render_with_jacobian`` for k constants, with its cost
in forward passes against the goal 1 + k/2. Goals: port fps >= llvmpipe fps.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

import drjit as dr  # noqa: E402

from helpers.synthetic import synthetic_inputs  # noqa: E402
from shaders_port import Constants  # noqa: E402
from shaders_port.ports import water_reflection, water_refraction  # noqa: E402

JAC_NAMES = {
    2: ["attenuation_distance", "bumptex_mult"],
    4: ["attenuation_distance", "bumptex_mult", "steps_grazing", "steps_steep"],
    9: [
        "attenuation_distance",
        "bumptex_mult",
        "steps_grazing",
        "steps_steep",
        "refr_coeff",
        "specular_strength",
        "specular_exponent",
        "water_color[1]",
        "reflect_color[0]",
    ],
}


def median_time(fn, n: int, warmup: int = 2) -> float:
    for _ in range(warmup):
        fn()
    ts = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--n", type=int, default=15, help="timed repetitions (median)")
    args = ap.parse_args()
    inputs = synthetic_inputs(width=args.size, height=args.size, tex=256)
    C = Constants()
    variants = [("water_refraction", True), ("water_refraction", False), ("water_reflection", True)]
    print(
        f"{args.size}x{args.size}, synthetic scene, median of {args.n} after warm-up "
        f"(Dr.Jit {dr.__version__}, LLVM backend)"
    )
    head = f"{'shader':<28}{'port ms':>9}{'port fps':>9}{'GL ms':>9}{'GL fps':>8}{'port/GL':>9}"
    print(head)
    print("-" * len(head))
    fwd = {}
    for shader, refl in variants:
        mod = water_refraction if shader == "water_refraction" else water_reflection
        defines = () if refl else ("NOREFLECTION",)

        def port_frame():
            out = mod.render(inputs, C, defines=defines)
            dr.eval(out.color, out.diagnostics)
            dr.sync_thread()

        t_port = median_time(port_frame, args.n)
        fwd[(shader, refl)] = t_port
        try:
            from shaders_port.gl.renderer import GLRenderer

            with GLRenderer(shader, inputs, defines=defines) as g:
                t_gl = statistics.median(g.time_frames(C, n=args.n, warmup=2))
        except Exception as exc:  # no headless GL on this machine
            print(f"  (GL unavailable: {exc})")
            t_gl = float("nan")
        name = shader + ("" if refl else " NOREFLECTION")
        print(
            f"{name:<28}{1e3 * t_port:>9.1f}{1 / t_port:>9.2f}{1e3 * t_gl:>9.1f}{1 / t_gl:>8.2f}"
            f"{t_gl / t_port:>9.2f}"
        )
    print()
    head = f"{'shader':<28}{'k':>3}{'Jacobian ms':>13}{'forward passes':>16}{'goal 1+k/2':>12}"
    print(head)
    print("-" * len(head))
    for shader, refl in (("water_refraction", True), ("water_reflection", True)):
        mod = water_refraction if shader == "water_refraction" else water_reflection
        for k, names in JAC_NAMES.items():
            t = median_time(
                lambda: mod.render_with_jacobian(inputs, C, names), max(3, args.n // 2), 1
            )
            print(
                f"{shader:<28}{k:>3}{1e3 * t:>13.1f}"
                f"{t / fwd[(shader, refl)]:>16.2f}{1 + k / 2:>12.1f}"
            )


if __name__ == "__main__":
    main()
