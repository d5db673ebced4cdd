"""Fitted constants against how the lighting texture is made: raw path tracing at several spp
against fewer samples denoised by Intel Open Image Denoise (``reference.lighting_denoise``).

For each texture setting ``METHOD:SPP`` (``raw``, ``oidn`` or ``oidn_unmatched``: the values of
``reference.lighting_denoise``, ``raw`` for ``none``; lighting at
``reference.lighting_size`` texels, ``reference.texture_method = "lighting"``, all of it path
traced: ``reference.lighting_direct = "path"``) the shader inputs
are built (cached in ``--cache``, so a re-run only fits), the shader is fitted against the same
reference (the experiment's ``reference.spp``), and the script prints:

* the wall seconds of the shader-input build (``cached`` when it came from the cache),
* each fitted constant, and its distance in standard errors to the fit with the *best* texture
  (the highest raw spp of the list): ``(c - c_best) / SE_best``, SE the Gauss-Newton standard
  error at the solution,
* FLIP and RMSE of the fitted shader at full resolution against the reference (water pixels),
* the texture's mean per colour channel over the pool against the yardstick's (a denoiser's
  bias in brightness; the raw textures' means are unbiased),
* what the texture lost against the best one inside the pool: the RMS relative difference of
  the refraction texture, and the *detail kept*: the energy of its high-pass part (texture minus
  a Gaussian blur of 1.5 lighting texels) as a fraction of the best texture's (caustics and
  tile edges live there; a denoiser that blurs caustics lowers it, noise raises it).

A third field, ``METHOD:SPP:SEED``, renders the texture with ``reference.seed = SEED`` (other
samples: the spread from seed to seed shows what one row's distance means). Every row is fitted
against the same image, the reference of the experiment as given.

    .venv/bin/python benchmarks/bench_denoise.py [EXPERIMENT.toml] \
[--textures raw:2048 raw:256 oidn:32 ...]
        [--cache DIR] [--set KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


def _blur(a: np.ndarray, sigma: float) -> np.ndarray:
    """Separable Gaussian blur of a (n, n, 3) image (edges clamped)."""
    r = max(1, int(3 * sigma))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    k /= k.sum()
    p = np.pad(a, ((r, r), (0, 0), (0, 0)), mode="edge")
    a = sum(w * p[i : i + a.shape[0]] for i, w in enumerate(k))
    p = np.pad(a, ((0, 0), (r, r), (0, 0)), mode="edge")
    return sum(w * p[:, i : i + a.shape[1]] for i, w in enumerate(k))


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("experiment", nargs="?", default=str(REPO / "experiments" / "default.toml"))
    ap.add_argument(
        "--textures",
        nargs="+",
        default=[
            "raw:2048",
            "raw:256",
            "raw:64",
            "raw:32",
            "oidn:256",
            "oidn:64",
            "oidn:32",
            "oidn:16",
        ],
    )
    ap.add_argument("--cache", type=Path, default=REPO / ".bench_cache" / "denoise")
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    ap.add_argument("--json", type=Path, default=None, help="write the rows here")
    args = ap.parse_args()
    settings = []
    for item in args.textures:
        parts = item.split(":")
        if (
            len(parts) not in (2, 3)
            or parts[0] not in ("raw", "oidn", "oidn_unmatched")
            or not all(p.isdigit() for p in parts[1:])
        ):
            ap.error(
                f"--textures {item!r}: expected raw:SPP, oidn:SPP, "
                "oidn_unmatched:SPP or METHOD:SPP:SEED"
            )
        settings.append((parts[0], int(parts[1]), int(parts[2]) if len(parts) == 3 else None))
    raws = [s for s in settings if s[0] == "raw"]
    if not raws:
        ap.error("--textures needs at least one raw:SPP setting (the best one is the yardstick)")
    best = max(raws, key=lambda s: s[1])
    settings.sort(key=lambda s: s != best)  # the yardstick first

    args.cache.mkdir(parents=True, exist_ok=True)
    os.environ["STUDY_CACHE"] = str(args.cache)
    from study import init_backend, load_experiment
    from study._metrics import errors
    from study.fit.calibrate import calibrate_experiment
    from study.fit.model import ShaderModel
    from study.scene import lighting, shader_inputs as si, topdown as td
    from study.scene.reference import load_or_render

    init_backend("llvm_ad_rgb")
    times_path = args.cache / "input_seconds.json"
    times = json.loads(times_path.read_text()) if times_path.exists() else {}
    base = load_experiment(args.experiment, args.overrides)
    ref = load_or_render(base, "llvm_ad_rgb", cache=args.cache)
    ref_img = np.asarray(ref.image if hasattr(ref, "image") else ref, np.float32)
    extent = td.texture_extent(base)
    size = base["reference.texture_size"]
    world_y = td.top_down_world_y(base, extent, size)
    X, Z = lighting.texel_centres(extent, size)
    hx, hz = base["pool.half_extent"]
    inside = (np.abs(X) < hx) & (np.abs(Z) < hz) & (world_y < td.underwater_camera_height(base))
    sigma = 1.5 * size / min(base["reference.lighting_size"], size)
    print(
        f"# {base['name']}: reference {base['reference.spp']} spp, lighting "
        f"{base['reference.lighting_size']}^2 "
        f"texels, texture {size}^2; yardstick {best[0]}:{best[1]}",
        flush=True,
    )

    rows, yard = [], None
    for method, spp, seed in settings:
        label = f"{method}:{spp}" + (f" seed {seed}" if seed is not None else "")
        exp = load_experiment(
            args.experiment,
            args.overrides
            + [
                'reference.texture_method="lighting"',
                'reference.lighting_direct="path"',
                f"reference.texture_spp={spp}",
                f'reference.lighting_denoise="{"none" if method == "raw" else method}"',
            ]
            + ([f"reference.seed={seed}"] if seed is not None else []),
        )
        key = exp.inputs_hash()
        t0 = time.perf_counter()
        inputs = si.load_or_build_shader_inputs(
            exp, "llvm_ad_rgb", cache=args.cache, log=lambda m: None
        )
        dt = time.perf_counter() - t0
        if key not in times and dt > 1.0:
            times[key] = dt
            times_path.write_text(json.dumps(times))
        tex = np.asarray(inputs.refraction_texture, np.float64)
        model = ShaderModel.from_experiment(exp, inputs, ref_img)
        cal = calibrate_experiment(model, exp)
        w, h = exp["resolution"]
        full = ShaderModel.from_experiment(exp, inputs, ref_img, resolution=(w, h))
        img, _ = full.render(cal.fitted)
        e = errors(ref_img, img, full.mask)
        params = {
            n: (
                p["fitted"],
                abs(p["fitted"]) * p["rel_std_error"] if p.get("rel_std_error") else None,
                p["status"],
            )
            for n, p in cal.parameters.items()
        }
        hp = tex - _blur(tex, sigma)
        row = {
            "label": label,
            "seconds": times.get(key),
            "flip": e["flip"],
            "rmse": e["rmse"],
            "params": params,
            "hp_energy": float(np.mean(hp[inside] ** 2)),
            "tex": tex,
        }
        if yard is None:
            yard = row
        row["rel_diff"] = float(
            np.sqrt(np.mean(((tex - yard["tex"]) / np.maximum(yard["tex"], 1e-4))[inside] ** 2))
        )
        row["detail"] = row["hp_energy"] / yard["hp_energy"]
        row["mean_ratio"] = (tex[inside].mean(0) / yard["tex"][inside].mean(0)).tolist()
        rows.append(row)
        print(
            f"{label:>10}: FLIP {e['flip']:.4f} "
            + " ".join(f"{n}={_g(v)}" for n, (v, _, _) in params.items()),
            flush=True,
        )

    names = list(yard["params"])
    print(
        "\n| texture | input build s | FLIP | RMSE | texture RMS rel. diff | detail kept "
        "| mean R / G / B vs "
        "the yardstick's | " + " | ".join(names) + " |"
    )
    print("|---|---|---|---|---|---|---|" + "---|" * len(names))
    for r in rows:
        cells = []
        for n in names:
            v, _, st = r["params"][n]
            vb, seb, _ = yard["params"][n]
            z = (
                (v - vb) / seb
                if r is not yard and v is not None and vb is not None and seb
                else None
            )
            cells.append(
                f"{_g(v)}"
                + (f" ({z:+.2f} SE)" if z is not None else "")
                + ("" if st == "fitted" else f" {st}")
            )
        print(
            f"| {r['label']} | {_g(r['seconds'], 3) if r['seconds'] else 'cached'} "
            f"| {r['flip']:.4f} | "
            f"{r['rmse']:.4f} | {r['rel_diff']:.3f} | {r['detail']:.2f} | "
            + " / ".join(f"{m:.3f}" for m in r["mean_ratio"])
            + " | "
            + " | ".join(cells)
            + " |"
        )
    if args.json:
        args.json.write_text(
            json.dumps([{k: v for k, v in r.items() if k != "tex"} for r in rows], indent=1)
        )


def _g(x, p=4):
    return f"{x:.{p}g}" if isinstance(x, (int, float)) else "-"


if __name__ == "__main__":
    main()
