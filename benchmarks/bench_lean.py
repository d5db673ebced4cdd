"""What LEAN mapping (``normals = "lean"``) makes of a pixel's footprint on an experiment's scene:
the variance of the unresolved slopes it reads against the variance of the slopes a pixel
holds, its one-sample highlight against the pixel's mean highlight, and the fits.

1. **Variance.** At the fit resolution, the per-axis variance of the layers' mean slope over
   each water pixel, from ``--ss`` x ``--ss`` point samples of the slope-blended normal (the
   pixel's truth), against LEAN's: at llvmpipe's level of detail (what the shader reads: the
   footprint's longer axis, ``pipeline.normal_maps``) and, as a what-if, at the level of detail of
   the footprint's area (``0.5 log2 |det J|``, texels) plus a bias.
2. **Highlight.** The sun's disc (the scene's sun) added by each: mean |error| on the water
   pixels against the ``--ss`` x ``--ss`` mean of the sharp disc off the slope-blended normal.
3. **Fits** (unless ``--no-fit``): ``study calibrate`` of the experiment's
   ``--shader`` (a ``normals = "lean"`` shader) with ``fit.loss = "linear"``, as shipped and
   with each what-if level of detail (the port's ``with_lean`` replaced; the GL check, which
   runs the shipped GLSL, then fails and is not read), FLIP and RMSE as the run reports them.

    .venv/bin/python benchmarks/bench_lean.py [--experiment experiments/default.toml]
        [--shader water_refraction_beer_disc_walls_lean] [--ss 8] [--bias -0.5 --bias -1]
        [--json docs/results/lean/footprint.json] [--no-fit]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


def area_lod(P, bias: float) -> tuple:
    """Each layer's level of detail of the footprint's area (float32 per lane) plus ``bias``."""
    from shaders_port.pipeline.normal_maps import texcoord_gradients

    S = P.slopeMoments.width
    out = []
    for g in texcoord_gradients(P.inputs, P.raster):
        det = np.abs(g[:, 0] * g[:, 3] - g[:, 1] * g[:, 2]) * S * S
        out.append((0.5 * np.log2(np.maximum(det, 1e-30)) + bias).astype(np.float32))
    return tuple(out)


def with_lod(m, P, lods):
    """``P`` (prepared with ``with_lean``) reading the moments at ``lods`` (NumPy per layer)."""
    return dataclasses.replace(P, slopeLod=tuple(m.Float(x) for x in lods))


def image(P, values) -> np.ndarray:
    """(H, W, ...) of per-lane ``values`` (N, ...), NaN off the water."""
    r = P.raster
    a = np.asarray(values, np.float64)
    out = np.full((r.height * r.width,) + a.shape[1:], np.nan)
    out[r.index] = a
    return out.reshape((r.height, r.width) + a.shape[1:])


def highlight(m, P, C, defines) -> np.ndarray:
    """(H, W) the sun's disc's contribution (RGB summed) of ``water_refraction`` with
    ``defines`` (the disc's and the shader's other switches) on the prepared frame ``P``."""
    from shaders_port.ports import water_refraction as wr

    def shade(d):
        colour, _ = wr._shade(m, P, C, False, wr.options_of(d), None)
        return image(P, np.stack([np.array(colour[i].numpy()) for i in range(3)], -1))

    off = tuple("NO_SPECULAR" if d == "SUN_DISC_SPECULAR" else d for d in defines)
    return (shade(defines) - shade(off)).sum(-1)


def footprint_rows(exp, inputs, shader: str, ss: int, biases) -> dict:
    """Sections 1 and 2 of the module doc at the experiment's fit resolution."""
    from shaders_port import Constants
    from shaders_port.pipeline.frame import resolve_constants
    from shaders_port.pipeline.normal_maps import with_lean
    from shaders_port.pipeline.raster import prepare
    from shaders_port.pipeline.texture import backend_types
    from shaders_port.ports.normals import lean_blend, normal_map_block
    from shaders_port.variants import get_variant

    m = backend_types("llvm")
    w, h = exp["fit.resolution"]
    coarse = dataclasses.replace(inputs, width=w, height=h)
    fine = dataclasses.replace(inputs, width=w * ss, height=h * ss)
    layers = 4
    # the pixel's truth: the slope-blended normal's slopes at ss x ss points
    Pf = prepare(fine, m)
    n, _, _ = normal_map_block(m, Pf, 1.0, layers, "slopes")
    n = np.array(n.numpy()).T
    slopes = image(Pf, -n[:, [0, 2]] / n[:, 1:2]).reshape(h, ss, w, ss, 2)
    truth = 0.5 * slopes.var(axis=(1, 3)).sum(-1)
    Pc = with_lean(m, prepare(coarse, m))
    lods = {"llvmpipe (the shader)": tuple(np.array(x.numpy()) for x in Pc.slopeLod)}
    for b in biases:
        lods[f"footprint area {b:+g}"] = area_lod(Pc, b)
    C = Constants().replace(
        sun_disc_radius=float(exp.sun.radius), sun_disc_radiance=float(np.max(exp.sun.radiance))
    )
    Cr = resolve_constants(m, C)
    disc = tuple(d for d in get_variant(shader).defines if d != "LEAN_NORMALS")
    fine_hl = highlight(m, Pf, Cr, disc + ("SLOPE_NORMALS",))
    mean_hl = fine_hl.reshape(h, ss, w, ss).mean((1, 3))
    sharp = highlight(m, prepare(coarse, m), Cr, disc + ("SLOPE_NORMALS",))
    water = np.isfinite(truth) & np.isfinite(mean_hl) & np.isfinite(sharp)
    rows = [{"what": "one sharp sample (slopes)", "highlight_error": _err(sharp, mean_hl, water)}]
    for label, lod in lods.items():
        P = with_lod(m, Pc, lod)
        _, var = lean_blend(m, P, layers)
        v = image(P, np.array(var.numpy()))
        ok = water & np.isfinite(v)
        hl = highlight(m, P, Cr, disc + ("LEAN_NORMALS",))
        rows.append({
            "what": f"LEAN at the level of detail of {label}",
            "lod_median": float(np.median(lod[0])),
            "variance_ratio_mean": float(v[ok].mean() / truth[ok].mean()),
            "variance_ratio_median": float(np.median(v[ok] / np.maximum(truth[ok], 1e-12))),
            "highlight_error": _err(hl, mean_hl, ok),
        })  # fmt: skip
    return {"fit_resolution": [w, h], "ss": ss, "sun_radius_deg": float(exp.sun.radius),
            "truth_variance_median": float(np.median(truth[water])), "rows": rows}  # fmt: skip


def _err(x, ref, mask) -> float:
    return float(np.abs(x - ref)[mask].mean())


def fit_rows(experiment: str, shader: str, biases, sets) -> list:
    """Section 3 of the module doc: one calibration per level of detail."""
    from shaders_port.pipeline import normal_maps
    from study.cli import main

    shipped = normal_maps.with_lean
    rows = []
    for bias in (None, *biases):

        def patched(m, P, bias=bias):
            Q = shipped(m, P)
            return Q if bias is None else with_lod(m, Q, area_lod(Q, bias))

        normal_maps.with_lean = patched
        with tempfile.TemporaryDirectory() as tmp:
            args = ["calibrate", experiment, "--set", f'fit.shader="{shader}"',
                    "--set", 'fit.loss="linear"', "--out", tmp, *sets]  # fmt: skip
            t0 = time.perf_counter()
            main(args)
            c = json.loads((Path(tmp) / "constants.json").read_text())
        label = "llvmpipe (the shader)" if bias is None else f"footprint area {bias:+g}"
        rows.append({"level_of_detail": label, "flip": c["error"]["flip"]["fitted"],
                     "rmse": c["error"]["rmse"]["fitted"], "seconds": time.perf_counter() - t0,
                     "constants": c["fit"]["constants"]})  # fmt: skip
    normal_maps.with_lean = shipped
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--experiment", default=str(REPO / "experiments" / "default.toml"))
    ap.add_argument("--shader", default="water_refraction_beer_disc_walls_lean")
    ap.add_argument("--ss", type=int, default=8, help="point samples per pixel side (truth)")
    ap.add_argument("--bias", type=float, action="append", default=None)
    ap.add_argument("--json", default=None)
    ap.add_argument("--no-fit", action="store_true")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    a = ap.parse_args(argv)
    biases = a.bias if a.bias is not None else [0.0, -0.5, -1.0]

    from study._backend import init_backend
    from study.calibration.frames import load_scene_data
    from study.config.experiment import load_experiment

    exp = load_experiment(a.experiment, a.set)
    _, inputs, _ = load_scene_data(exp, init_backend(exp["variant"]))
    out = {"experiment": exp["name"], "shader": a.shader}
    out.update(footprint_rows(exp, inputs, a.shader, a.ss, biases))
    print(f"# {exp['name']}: LEAN's variance and highlight against {a.ss}x{a.ss} samples")
    print("| what | LOD (median) | variance / truth (mean, median) | highlight mean abs error |")
    print("|---|---|---|---|")
    for r in out["rows"]:
        v = (f"{r['variance_ratio_mean']:.2f}, {r['variance_ratio_median']:.2f}"
             if "variance_ratio_mean" in r else "-")  # fmt: skip
        lod = f"{r['lod_median']:.2f}" if "lod_median" in r else "-"
        print(f"| {r['what']} | {lod} | {v} | {r['highlight_error']:.4f} |")
    if not a.no_fit:
        sets = [x for kv in a.set for x in ("--set", kv)]
        out["fits"] = fit_rows(a.experiment, a.shader, [b for b in biases if b != 0.0], sets)
        print("\n| LEAN's level of detail | fitted FLIP | RMSE |\n|---|---|---|")
        for r in out["fits"]:
            print(f"| {r['level_of_detail']} | {r['flip']:.4f} | {r['rmse']:.4f} |")
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
