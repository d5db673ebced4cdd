"""Noise in the shader's textures biases the fit; the decorrelated loss removes that bias.

The fitted constants meet the top-down texture's Monte Carlo noise inside the shader (errors in
the inputs), so least squares on a noisy texture is biased by about the noise's variance. The
shader is affine in its textures, so with the texture's two independent halves A and B the
decorrelated loss ``0.5 * sum(r_A * r_B)`` has the expectation of the loss with the noise-free
texture (``study.fit.decorrelated``, ``fit.input_noise = "decorrelate"``).

For one experiment and one reference (by default the slow path's: 1024-spp independent samples,
cached under ``STUDY_CACHE``), and the lighting texture made with the experiment's settings and
``--set`` overrides at each of ``--seeds`` seeds, fits the same inputs twice, side by side:

* ``least squares``: ``fit.input_noise = "ignore"`` on the texture as built;
* ``decorrelated``: the same, then refined on the decorrelated loss over the texture's halves;

and prints each constant's mean and SD over the seeds, with the mean's distance to
``--yardstick`` values (a ``constants.json`` of a clean fit, e.g. ``study calibrate`` with a
2048-spp colour texture) in that file's Gauss-Newton standard errors.

    .venv/bin/python benchmarks/bench_decorrelated.py [EXPERIMENT.toml] [--seeds 3]
        [--set reference.lighting_size=256 ...] [--yardstick constants.json]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
REFERENCE = [
    'reference.sampler="independent"',
    'reference.spp="auto"',
    "reference.target_noise=0.01",
    "reference.max_spp=1024",
]


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("experiment", nargs="?", default=str(REPO / "experiments" / "grazing.toml"))
    ap.add_argument(
        "--seeds", type=int, default=3, help="lighting textures with reference.seed = 0 .. N-1"
    )
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    ap.add_argument(
        "--yardstick", type=Path, help="constants.json of a clean fit of the same experiment"
    )
    args = ap.parse_args()

    from study._backend import drjit_backend, init_backend
    from study.fit.calibrate import calibrate_experiment
    from study.fit.decorrelated import half_models
    from study.fit.model import ShaderModel, get_value
    from study.config.experiment import load_experiment
    from study.scene.reference import load_or_render
    from study.scene.shader_inputs import load_or_build_shader_inputs

    variant = init_backend("llvm_ad_rgb")
    backend = drjit_backend(variant)
    quiet = lambda *_: None  # noqa: E731
    sets = args.overrides + ['fit.input_noise="decorrelate"']
    ref = load_or_render(load_experiment(args.experiment, REFERENCE + sets), variant, log=quiet)
    rows: dict[str, dict[str, list]] = {"least squares": {}, "decorrelated": {}}
    seconds = {"least squares": [], "decorrelated": []}
    for seed in range(args.seeds):
        exp = load_experiment(args.experiment, sets + [f"reference.seed={seed}"])
        inputs = load_or_build_shader_inputs(exp, variant, log=quiet)
        model = ShaderModel.from_experiment(exp, inputs, ref.image, backend=backend)
        halves = half_models(
            exp, inputs, lambda h: ShaderModel.from_experiment(exp, h, ref.image, backend=backend)
        )
        for key, h in (("least squares", None), ("decorrelated", halves)):
            t0 = time.perf_counter()
            with contextlib.redirect_stderr(io.StringIO()):
                cal = calibrate_experiment(model, exp, halves=h)
            seconds[key].append(time.perf_counter() - t0)
            for n, p in cal.parameters.items():
                if p["fitted"] is not None:
                    rows[key].setdefault(n, []).append(get_value(cal.fitted, n))
            if h is not None:
                info = cal.fit_summary.get("input_noise", {})
                print(
                    f"seed {seed}: decorrelated {info.get('message')} in {info.get('steps')} steps",
                    flush=True,
                )
    yard = {}
    if args.yardstick:
        y = json.loads(args.yardstick.read_text())["parameters"]
        yard = {
            n: (p["fitted"], (p.get("rel_std_error") or 0) * abs(p["fitted"] or 0))
            for n, p in y.items()
        }
    print(
        f"\n# bench_decorrelated: {Path(args.experiment).stem}, {args.seeds} "
        "lighting seed(s), overrides "
        f"{args.overrides or 'none'}, reference {ref.spp} spp; fit s (median): least squares "
        f"{np.median(seconds['least squares']):.1f}, decorrelated "
        f"{np.median(seconds['decorrelated']):.1f}\n"
    )
    head = "| constant | least squares, mean +- SD | decorrelated, mean +- SD |"
    if yard:
        head += " yardstick (SE) | least squares - yardstick, SE | decorrelated - yardstick, SE |"
    print(head)
    print("|---" * (head.count("|") - 1) + "|")
    for n in rows["least squares"]:
        cells = []
        for key in rows:
            v = np.array(rows[key].get(n, [np.nan]))
            cells.append(f"{v.mean():.4g} +- {v.std(ddof=1) if len(v) > 1 else 0:.2g}")
        line = f"| {n} | " + " | ".join(cells) + " |"
        if yard:
            y, se = yard.get(n, (None, 0))
            if y is None or not se:
                line += " - | - | - |"
            else:
                d = [(np.mean(rows[k][n]) - y) / se for k in rows]
                line += f" {y:.4g} ({se:.2g}) | {d[0]:+.1f} | {d[1]:+.1f} |"
        print(line)


if __name__ == "__main__":
    main()
