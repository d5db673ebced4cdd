"""The GL check of a user's shader in each dialect: which text ran on which context, and the
mean and 99.9th percentile of |llvmpipe - executor| (max over channels, linear RGB).

Runs ``study.export.gl_check.gl_check_user`` at the start values on the synthetic inputs of the
tests (``tests/helpers/synthetic.py``) for the dialect test files of ``tests/shaders/`` (the
study's vertex shader) and the four engine pairs of ``experiments/`` (their own vertex shaders),
and prints one line each: the text (as written or the translation), the context, the figures,
the verdict and, on OpenGL ES, the file at its own precision qualifiers.

    .venv/bin/python benchmarks/bench_gl_dialects.py [--size 160 120]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO), str(REPO / "tests")]

DIALECT_FILES = ("compat_builtins_110", "schlick_fog_120", "schlick_fog_webgl1",
                 "schlick_fog_es300", "water_es310")  # fmt: skip
PAIRS = ("webgl_mirror_water", "dudv_depth_water", "fog_cube_water", "zup_water")


def _line(name: str, r: dict) -> str:
    if not r.get("ran"):
        return f"{name}: not run ({r.get('why')})"
    how = "as written" if r["text"].startswith("your file") else "translation"
    ctx = r["context"].split(", llvmpipe")[0]
    own = r.get("own_precision")
    extra = f"; own precision mean {own['mean_abs']:.2g}, p99.9 {own['p999']:.2g}" if own else ""
    return (f"{name}: {how} on {ctx}: mean {r['mean_abs']:.2g}, p99.9 {r['p999']:.2g}, "
            f"{'passed' if r['passed'] else 'FAILED'}{extra}")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, nargs=2, default=(160, 120), metavar=("W", "H"))
    args = ap.parse_args()
    from helpers.synthetic import synthetic_baseline_inputs, synthetic_inputs

    from shaders_port.spirv.user_shader import UserShader
    from study import load_experiment
    from study.config.user_shader import load_user_shader
    from study.export.gl_check import gl_check_user

    w, h = args.size
    shaders = REPO / "tests" / "shaders"
    inputs = synthetic_inputs(width=w, height=h)
    for name in DIALECT_FILES:
        kw = {}
        if name == "schlick_fog_120":
            kw = {"defines": ["WATER_FOG=1"], "include_paths": [shaders / "include"]}
        shader = UserShader.from_file(shaders / f"{name}.frag", **kw).check()
        ours = shader.render(inputs).numpy()
        print(_line(name, gl_check_user(shader, inputs, shader.defaults(), ours)), flush=True)
    inputs = synthetic_baseline_inputs(w, h)
    for name in PAIRS:
        exp = load_experiment(REPO / "experiments" / f"{name}.toml")
        shader = load_user_shader(exp.values)
        ours = shader.render(inputs).numpy()
        r = gl_check_user(shader, inputs, shader.defaults(), ours)
        print(_line(f"{name} (pair)", r), flush=True)


if __name__ == "__main__":
    main()
