"""Noise in the shader's textures biases the fit; a decorrelated loss removes that bias.

The fitted constants meet the top-down texture's Monte Carlo noise inside the shader (errors in
the inputs), so least squares on a noisy texture is biased by about the noise's variance. The
shader is linear in its textures, so with two textures A and B rendered with independent seeds
the decorrelated loss ``0.5 * sum(r_A * r_B)`` (``r_X`` the port's residual with texture X) has
the expectation of the loss with the noise-free texture.

For one experiment and reference (by default the slow path's: 1024-spp independent samples,
cached under ``STUDY_CACHE``), prints the constants of

* the least-squares fit (``study.fit.calibrate``) on the mean texture ``(A + B) / 2``;
* the same constants refined on the decorrelated loss (L-BFGS-B from that fit, gradient
  ``0.5 * (J_A^T r_B + J_B^T r_A)`` from the port's forward-mode Jacobians);

for raw (not denoised) lighting textures of ``--spp`` samples each at ``--texels`` lighting
texels; ``--yardstick`` adds the least-squares fit on a colour texture at 2048 spp (10-15 min).

    .venv/bin/python benchmarks/bench_decorrelated.py [EXPERIMENT.toml] [--spp 16] [--texels 128]
        [--seeds 100 101] [--yardstick]
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
REFERENCE = ['reference.sampler="independent"', 'reference.spp="auto"', "reference.target_noise=0.01",
             "reference.max_spp=1024"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("experiment", nargs="?", default=str(REPO / "experiments" / "grazing.toml"))
    ap.add_argument("--spp", type=int, default=16, help="samples per texel of each lighting texture")
    ap.add_argument("--texels", type=int, default=128, help="reference.lighting_size")
    ap.add_argument("--seeds", type=int, nargs=2, default=[100, 101])
    ap.add_argument("--yardstick", action="store_true")
    args = ap.parse_args()

    from scipy.optimize import minimize

    from study._backend import drjit_backend, init_backend
    from study.fit.calibrate import calibrate_experiment
    from study.fit.model import ShaderModel, bounds, get_value, with_values
    from study.scene.experiment import load_experiment
    from study.scene.reference import load_or_render
    from study.scene.shader_inputs import load_or_build_shader_inputs

    variant = init_backend("llvm_ad_rgb")
    backend = drjit_backend(variant)
    quiet = lambda *_: None  # noqa: E731
    exp = load_experiment(args.experiment, REFERENCE)
    ref = load_or_render(exp, variant, log=quiet)

    def inputs(sets):
        return load_or_build_shader_inputs(load_experiment(args.experiment, REFERENCE + sets), variant, log=quiet)

    raw = ['reference.lighting_denoise="none"', f"reference.texture_spp={args.spp}",
           f"reference.lighting_size={args.texels}"]
    a, b = (inputs(raw + [f"reference.seed={s}"]) for s in args.seeds)
    mean = dataclasses.replace(a, refraction_texture=0.5 * (a.refraction_texture + b.refraction_texture),
                               refl_texture=0.5 * (a.refl_texture + b.refl_texture))
    model_a, model_b, model_mean = (ShaderModel.from_experiment(exp, i, ref.image, backend=backend)
                                    for i in (a, b, mean))
    with contextlib.redirect_stderr(io.StringIO()):
        cal = calibrate_experiment(model_mean, exp)
    names = [n for n, p in cal.parameters.items() if p["status"] == "fitted"]
    x0 = np.array([get_value(cal.fitted, n) for n in names])
    scale = np.abs(x0) + 1e-3

    def loss_and_grad(z):
        c = with_values(cal.fitted, dict(zip(names, map(float, z * scale))))
        r_a, j_a = model_a.residual_and_jacobian(c, names)
        r_b, j_b = model_b.residual_and_jacobian(c, names)
        return 0.5 * float(r_a @ r_b), 0.5 * (j_a.T @ r_b + j_b.T @ r_a) * scale

    opt = minimize(loss_and_grad, x0 / scale, jac=True, method="L-BFGS-B",
                   bounds=[(lo / s, hi / s) for (lo, hi), s in zip(map(bounds, names), scale)],
                   options={"maxiter": 200, "ftol": 1e-12, "gtol": 1e-9})
    cols = {"least squares, mean texture": x0, "decorrelated": opt.x * scale}
    if args.yardstick:
        clean = inputs(['reference.texture_method="colour"', "reference.texture_spp=2048"])
        with contextlib.redirect_stderr(io.StringIO()):
            c = calibrate_experiment(ShaderModel.from_experiment(exp, clean, ref.image, backend=backend), exp)
        cols["colour 2048 spp"] = np.array([get_value(c.fitted, n) for n in names])
    print(f"# bench_decorrelated: {exp['name']}, raw lighting 2 x {args.spp} spp at {args.texels} texels, "
          f"seeds {args.seeds}, reference {ref.spp} spp; L-BFGS-B: {opt.message} ({opt.nit} steps)\n")
    print("| constant | " + " | ".join(cols) + " | Gauss-Newton SE (mean texture) |")
    print("|---|" + "---|" * (len(cols) + 1))
    for i, n in enumerate(names):
        se = cal.parameters[n].get("rel_std_error")
        se_txt = f"{se * abs(x0[i]):.3g}" if se else "-"
        print(f"| {n} | " + " | ".join(f"{v[i]:.4g}" for v in cols.values()) + f" | {se_txt} |")


if __name__ == "__main__":
    main()
