"""Milliseconds per frame of the shipped GLSL on the local OpenGL (headless EGL, e.g. llvmpipe).

Usage: .venv/bin/python benchmarks/bench_gl.py [--n 20] [--sizes 128x96,256x192,512x384]

Prints one row per (shader variant, resolution, loop cap): median and min ms per frame
(draw + glFinish, no read-back, after warm-up) and the ratio to the default-constants row.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from shaders_port import Constants  # noqa: E402
from shaders_port.gl.renderer import GLRenderer, time_glsl  # noqa: E402,F401
from helpers.synthetic import synthetic_inputs  # noqa: E402

VARIANTS = [("water_refraction", False), ("water_refraction", True), ("water_reflection", True)]
SCHEDULES = {
    "default (10,3,40)": Constants(),
    "fine (20,6,80)": Constants(steps_grazing=20.0, steps_steep=6.0, loop_cap=80),
    "coarse (5,2,20)": Constants(steps_grazing=5.0, steps_steep=2.0, loop_cap=20),
}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20, help="timed frames per row")
    ap.add_argument("--sizes", default="128x96,256x192,512x384")
    args = ap.parse_args(argv)
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    print(
        f"{'shader':<18} {'NOREFL':<6} {'size':>9} {'schedule':<18} {'median ms':>10} "
        f"{'min ms':>8} {'ratio':>6}"
    )
    for w, h in sizes:
        inputs = synthetic_inputs(width=w, height=h)
        for name, refl in VARIANTS:
            with GLRenderer(name, inputs, defines=() if refl else ("NOREFLECTION",)) as r:
                base = None
                for label, c in SCHEDULES.items():
                    t = r.time_frames(c, n=args.n)
                    med = statistics.median(t) * 1e3
                    base = base or med
                    print(
                        f"{name:<18} {str(not refl):<6} {f'{w}x{h}':>9} {label:<18} "
                        f"{med:10.3f} {min(t) * 1e3:8.3f} {med / base:6.2f}"
                    )
    import moderngl

    ctx = moderngl.create_context(standalone=True, backend="egl")
    print(f"\nGL: {ctx.info['GL_RENDERER']} ({ctx.info['GL_VERSION']})")
    ctx.release()


if __name__ == "__main__":
    main()
