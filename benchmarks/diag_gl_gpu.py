"""The GL check on whatever OpenGL headless EGL gives here (llvmpipe on the CPU, a GPU's own
driver on a GPU machine), for the port on each Dr.Jit backend: the verdict of
``study.export.gl_check.gl_check`` with its figures, the outliers with their reasons and
``GL_RENDERER``. docs/where-it-runs.md, "The GL check on a GPU", quotes it.

The frame: ``--frame F.npz`` (a saved ``ShaderInputs``, e.g. a device run's ``diag_frame.npz``),
else the shader inputs of ``--experiment`` (default ``experiments/default.toml``, raw lighting
and walls) built at ``--size`` on the first backend. Constants: the defaults and the constants the
256x256 ``cuda_ad_rgb`` pass of the 2026-12-04 H200 run fitted (``BENCH_CUDA_FITTED``), each
exported (core GLSL, as ``study calibrate`` writes it) and run once on OpenGL.

    .venv/bin/python benchmarks/diag_gl_gpu.py [--frame F.npz] [--size 256] \\
        [--backends cuda llvm] [--json OUT.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

BENCH_CUDA_FITTED = {  # the 256x256 cuda_ad_rgb pass of the 2026-12-04 device run (bench.json)
    "attenuation_distance": 4.938866220664048,
    "bumptex_mult": 0.9957570862077573,
    "water_color": (0.0, 0.14546989395207088, 0.316228876167043, 1.0),
    "specular_strength": 9.687030766983732,
    "specular_exponent": 310.56238319606246,
}
SHADER = "water_refraction"


def build_frame(experiment: str, size: int, backend: str, cache: Path):
    """The shader inputs of ``experiment`` at ``size`` x ``size`` (raw lighting and walls)."""
    from study.calibration.frames import load_scene_data, prepare

    overrides = [
        'reference.lighting_denoise="none"',
        'reference.wall_denoise="none"',
        f"resolution=[{size}, {size}]",
    ]
    variant = f"{backend}_ad_rgb"
    exp, variant, _ = prepare(experiment, cache / "out", overrides, variant)
    _, inputs, _ = load_scene_data(exp, variant, cache)
    return inputs


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frame", type=Path)
    ap.add_argument("--experiment", default=str(REPO / "experiments" / "default.toml"))
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--backends", nargs="+", default=["llvm"], choices=["llvm", "cuda"])
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)

    from study._backend import init_backend

    init_backend(f"{args.backends[0]}_ad_rgb")
    from shaders_port.inputs import Constants, ShaderInputs
    from shaders_port.pipeline.texture import set_default_backend
    from study.export.gl_check import gl_check
    from study.export.shaders import export_shaders

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if args.frame:
            frame = ShaderInputs.load(args.frame)
        else:
            frame = build_frame(args.experiment, args.size, args.backends[0], tmp / "cache")
        res = {"frame": str(args.frame or f"{args.experiment} at {args.size}"), "runs": {}}
        sets = {
            "default": Constants(),
            "bench_cuda_fitted": Constants().replace(**BENCH_CUDA_FITTED),
        }
        for name, constants in sets.items():
            shaders = tmp / f"shaders_{name}"
            export_shaders(constants, shaders, [SHADER], ())
            for be in args.backends:
                set_default_backend(be)
                t = time.perf_counter()
                v = gl_check(SHADER, frame, constants, shaders)
                v["seconds"] = round(time.perf_counter() - t, 2)
                res["runs"].setdefault(name, {})[be] = v
                print(
                    f"{name} / port on {be} / GL {v['gl_renderer']}: "
                    f"{'passed' if v['passed'] else 'FAILED: ' + v['reason']}; mean "
                    f"{v['mean_abs']:.3g}, p99.9 {v['p999']:.3g}, max {v['max_abs']:.3g}, "
                    f"{v['n_outliers']} outliers of {v['n_water']}, explained {v['explained']}",
                    flush=True,
                )
        res["seconds"] = round(time.perf_counter() - t0, 1)
    if args.json:
        args.json.write_text(json.dumps(res, indent=1, default=str) + "\n")
    return res


if __name__ == "__main__":
    out = main()
    sys.exit(0 if all(v["passed"] for r in out["runs"].values() for v in r.values()) else 1)
