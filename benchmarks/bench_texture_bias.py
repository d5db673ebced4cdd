"""Fitted constants vs reference spp and vs how the top-down refraction texture is made.

Renders (once, kept in ``--passes DIR``) independent 64-spp passes of the experiment's reference
and of its top-down textures at ``reference.texture_size`` (the under-water render, the dry
render for the walls, and the floor albedo), then fits the shader with textures assembled from
``k`` of those passes:

* ``colour k``: the colour render at ``64 k`` spp per texel (today's method);
* ``lighting N k``: the same samples as lighting (radiance / albedo, under-water absorption
  divided out), box-averaged to N x N lighting texels (each is then a ``64 k (size / N)^2``-spp
  lighting texel, exactly what a lighting render at N texels and 64 k spp gives), bilinearly
  interpolated and multiplied by the texel albedo (``reference.texture_method = "lighting"``);

and with references of ``64 j`` spp. Every fit uses the experiment's parameters and solver.
Prints each fitted constant with its relative standard error, the distance to the best
estimate in standard errors, FLIP and RMSE against the full reference. The best estimate of
the texture-noise-free constants is the errors-in-variables extrapolation ``c(s) = c_inf + b / s``
over the colour fits (noise in the texture biases the fit in proportion to its variance, 1 / s).

    .venv/bin/python benchmarks/bench_texture_bias.py [--passes DIR] [--render-wet N] \
[--render-ref N]
        [--colour K ...] [--lighting N:K ...] [--ref J ...] [--ref-sets A:B ...] [--ref-passes J]
        [--set KEY=VALUE ...]

The figures in the README came from 8 under-water passes and 8 reference passes:
``--render-wet 8 --render-ref 8``, then ``--colour 1 4 8 --lighting 128:1 128:4 128:8 64:8
--ref-passes 3`` and ``--colour --lighting --ref 2 8 --ref-sets 0:2 2:4 4:6 6:8 0:4 4:8``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


def _render(exp, kind: str, folder: Path, n: int, spp: int = 64) -> None:
    """Passes ``<kind>64_<i>.npy`` (GL order for textures) up to ``n``, skipping existing ones."""
    import mitsuba as mi

    from study.scene import lighting, topdown as td
    from study.scene.mitsuba_scene import build_scene

    have = len(list(folder.glob(f"{kind}[0-9]*_*.npy")))
    todo = list(range(have, n))
    if not todo:
        return
    extent = td.texture_extent(exp)
    size = exp["reference.texture_size"]
    if kind == "ref":
        scene = build_scene(exp)
        render = lambda i: np.array(mi.render(scene, spp=spp, seed=5000 + i), np.float32)  # noqa: E731
    else:
        water = kind == "wet"
        y_cam = td.underwater_camera_height(exp) if water else 100.0
        scene, medium = lighting._top_down_scene(
            mi, exp, water=water, integrator=lighting._transport(exp, water)
        )
        sensor = td.ortho_sensor(mi, extent, size, spp, 0, y_cam=y_cam, medium=medium)

        def render(i):
            return td.to_gl_order(
                mi,
                sensor,
                np.array(mi.render(scene, sensor=sensor, spp=spp, seed=7000 + i), np.float32),
                extent,
            )

    for i in todo:
        t0 = time.perf_counter()
        np.save(folder / f"{kind}{spp}_{i:02d}.npy", render(i))
        print(
            f"rendered {kind} pass {i} ({spp} spp) in {time.perf_counter() - t0:.1f} s", flush=True
        )


def _load(folder: Path, kind: str, k: int | None = None) -> np.ndarray:
    files = sorted(folder.glob(f"{kind}[0-9]*_*.npy"))[:k]
    if not files:
        raise SystemExit(f"no {kind} passes in {folder}; render them with --render-{kind} N")
    return np.stack([np.load(f) for f in files])


def _box(a: np.ndarray, f: int) -> np.ndarray:
    n = a.shape[0] // f
    return a[: n * f, : n * f].reshape(n, f, n, f, *a.shape[2:]).sum((1, 3))


def lighting_texture(wet_mean, albedo, gain, inside, dry, n_light: int) -> np.ndarray:
    """Colour from lighting box-averaged to ``n_light`` texels (over the texture's extent, only
    pool texels counted), interpolated bilinearly between lighting texel centres."""
    size = wet_mean.shape[0]
    f = size // n_light
    w = inside[..., None].astype(np.float64)
    num = _box(wet_mean * gain * w, f)
    den = _box(albedo * w, f)
    cnt = _box(w, f)
    light = np.where(den > 0, num / np.maximum(den, 1e-12), 0.0)
    # normalised bilinear interpolation over the valid lighting texels (centres at (i + .5) f - .5)
    u = (np.arange(size) + 0.5) / f - 0.5
    i0 = np.clip(np.floor(u).astype(int), 0, n_light - 2)
    fu = np.clip(u - i0, 0.0, 1.0)
    valid = (cnt > 0).astype(np.float64)
    acc = np.zeros((size, size, 3))
    wsum = np.zeros((size, size, 1))
    for dj, wj in ((0, 1 - fu), (1, fu)):
        for di, wi in ((0, 1 - fu), (1, fu)):
            ww = (wj[:, None] * wi[None, :])[..., None] * valid[
                (i0 + dj)[:, None], (i0 + di)[None, :]
            ]
            acc += ww * light[(i0 + dj)[:, None], (i0 + di)[None, :]]
            wsum += ww
    light_up = acc / np.maximum(wsum, 1e-12)
    return np.where(inside[..., None], light_up * albedo, dry).astype(np.float32)


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("experiment", nargs="?", default=str(REPO / "experiments" / "default.toml"))
    ap.add_argument("--passes", type=Path, default=REPO / ".bench_cache")
    ap.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        help="experiment override KEY=VALUE (e.g. fit.max_steps=400)",
    )
    ap.add_argument("--render-wet", type=int, default=0)
    ap.add_argument("--render-ref", type=int, default=0)
    ap.add_argument("--colour", type=int, nargs="*", default=[1, 4, 8])
    ap.add_argument("--lighting", nargs="*", default=["128:1", "128:2", "128:8", "64:1", "64:8"])
    ap.add_argument(
        "--ref", type=int, nargs="*", default=[1, 2, 4], help="reference passes (64 spp each)"
    )
    ap.add_argument(
        "--ref-passes",
        type=int,
        default=None,
        help="passes of the reference the texture fits use (default: all)",
    )
    ap.add_argument(
        "--ref-sets",
        nargs="*",
        default=[],
        help="disjoint reference pass ranges START:STOP "
        "(the spread of their fitted constants measures the reference noise's effect)",
    )
    args = ap.parse_args()

    from study import init_backend, load_experiment
    from study._metrics import errors
    from study.fit.calibrate import calibrate_experiment
    from study.fit.model import ShaderModel
    from study.scene import lighting, shader_inputs as si, topdown as td

    init_backend("llvm_ad_rgb")
    exp = load_experiment(args.experiment, ['reference.texture_method="colour"'] + args.overrides)
    args.passes.mkdir(parents=True, exist_ok=True)
    _render(exp, "wet", args.passes, args.render_wet)
    _render(exp, "ref", args.passes, args.render_ref)
    _render(exp, "dry", args.passes, 2)
    size = exp["reference.texture_size"]
    extent = td.texture_extent(exp)
    alb_path = args.passes / "albedo.npy"
    if not alb_path.exists():
        np.save(alb_path, lighting.render_dry(exp, extent, size, lighting.ALBEDO_SPP, 0)[1])
    albedo = np.load(alb_path).astype(np.float64)
    world_y = td.top_down_world_y(exp, extent, size)
    y_cam = td.underwater_camera_height(exp)
    X, Z = lighting.texel_centres(extent, size)
    hx, hz = exp["pool.half_extent"]
    inside = (np.abs(X) < hx) & (np.abs(Z) < hz) & (world_y < y_cam)
    gain = np.exp(np.asarray(exp["water.sigma_t"]) * np.maximum(y_cam - world_y, 0.0)[..., None])
    wet, dry = _load(args.passes, "wet"), _load(args.passes, "dry").mean(0)
    refs = _load(args.passes, "ref")
    print(
        f"# {exp['name']}: {len(wet)} wet passes, {len(refs)} reference passes of 64 "
        f"spp; texture {size}^2"
    )

    orig = si.top_down_colour
    si.top_down_colour = lambda *a, **k: np.zeros((size, size, 3), np.float32)
    base = si.build_shader_inputs(exp)
    si.top_down_colour = orig
    full_ref = refs[: args.ref_passes].mean(0)

    def with_colour(colour):
        above = world_y > 0.0
        return dataclasses.replace(
            base,
            refraction_texture=colour,
            refl_texture=np.where(above[..., None], colour, 0.0).astype(np.float32),
        )

    def fit(label, colour, ref_img):
        t0 = time.perf_counter()
        inputs = with_colour(colour)
        model = ShaderModel.from_experiment(exp, inputs, ref_img)
        cal = calibrate_experiment(model, exp)
        w, h = exp["resolution"]
        full = ShaderModel.from_experiment(exp, inputs, full_ref, resolution=(w, h))
        img, _ = full.render(cal.fitted)
        e = errors(full_ref, img, full.mask)
        row = {
            "label": label,
            "flip": e["flip"],
            "rmse": e["rmse"],
            "seconds": time.perf_counter() - t0,
            "params": {
                n: (p["fitted"], p.get("rel_std_error"), p["status"])
                for n, p in cal.parameters.items()
            },
        }
        print(
            f"{label:>18}: FLIP {e['flip']:.4f} RMSE {e['rmse']:.4f} "
            + " ".join(f"{n}={_g(v)}(±{_g(se)})" for n, (v, se, _) in row["params"].items()),
            flush=True,
        )
        return row

    rows = []

    def colour_of(k):
        return np.where(inside[..., None], wet[:k].mean(0) * gain, dry).astype(np.float32)

    best_tex = colour_of(len(wet))
    for k in args.colour:
        rows.append(fit(f"colour {64 * k}", colour_of(k), full_ref))
    for item in args.lighting:
        n, k = map(int, item.split(":"))
        rows.append(
            fit(
                f"lighting {n} {64 * k}",
                lighting_texture(wet[:k].mean(0), albedo, gain, inside, dry, n),
                full_ref,
            )
        )
    refs = _load(args.passes, "ref")  # again: more passes may have been rendered meanwhile
    for j in args.ref:
        if j <= len(refs):
            rows.append(fit(f"ref {64 * j} tex {64 * len(wet)}", best_tex, refs[:j].mean(0)))
    for item in args.ref_sets:
        a, b = map(int, item.split(":"))
        if b <= len(refs):
            rows.append(
                fit(f"ref passes {a}-{b - 1} ({64 * (b - a)} spp)", best_tex, refs[a:b].mean(0))
            )
    if not rows:
        return
    # errors-in-variables extrapolation over the colour fits with the full reference
    col = [r for r in rows if r["label"].startswith("colour")]
    spp = np.array([float(r["label"].split()[1]) for r in col])
    names = list(rows[0]["params"])
    print("\n| texture / reference | FLIP | " + " | ".join(names) + " |")
    print("|---|---|" + "---|" * len(names))
    inf = {}
    for n in names if len(col) >= 2 else []:
        v = np.array([r["params"][n][0] if r["params"][n][0] is not None else np.nan for r in col])
        if np.all(np.isfinite(v)) and len(v) >= 2:
            A = np.stack([np.ones_like(spp), 1.0 / spp], 1)
            inf[n] = float(np.linalg.lstsq(A, v, rcond=None)[0][0])
    for r in rows:
        cells = []
        for n, (v, se, st) in r["params"].items():
            z = (v - inf[n]) / (se * abs(v)) if n in inf and v is not None and se else None
            cells.append(f"{_g(v)} ({_g(z, 2)} SE)" if z is not None else _g(v))
        print(f"| {r['label']} | {r['flip']:.4f} | " + " | ".join(cells) + " |")
    print("| extrapolated c_inf | | " + " | ".join(_g(inf.get(n)) for n in names) + " |")


def _g(x, p=4):
    return f"{x:.{p}g}" if isinstance(x, (int, float)) else "-"


if __name__ == "__main__":
    main()
