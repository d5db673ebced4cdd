"""The floor's direct light through the waves: ray traced (study.scene.direct_light) against
Mitsuba's path tracer estimating the same term, side by side in one run.

For each experiment and each term (the sun, the sky without the sun), on the texture's texels
over the pool (GL order, linear RGB radiance of the floor; the path tracer's ``max_depth = 3``
render lit by that part of the envmap alone, corrected for the under-water camera ray's
absorption as the lighting texture is), prints:

* seconds per estimate (median of ``--repeats``, kernels compiled before timing);
* the mean over the pool per colour channel of each estimator (mean of ``--estimates``
  independent estimates) and their ratio with its standard error, which checks that both
  estimate the same thing;
* the RMS per-texel standard error of one estimate relative to the term's mean (its noise), and
  the *efficiency* ratio: path-traced variance x time over traced variance x time (how many
  times longer the path tracer would take to be as quiet).

The path tracer runs at ``--spp`` (default: the shipped lighting render's 32 spp), the traced
estimators at the shipped settings (``reference.sun_photons``, ``reference.sky_directions``). Not
a test: ratios, not thresholds.

    .venv/bin/python benchmarks/bench_direct_light.py experiments/default.toml
        experiments/grazing.toml
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _timed(fn, repeats: int):
    fn()  # compile
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, statistics.median(times)


def run(exp, spp: int, n_est: int, repeats: int) -> list[dict]:
    import mitsuba as mi

    from study.scene import direct_light, lighting, sun_photons
    from study.scene.topdown import (
        ortho_sensor,
        to_gl_order,
        camera_ray_optical_depth,
        texture_extent,
        top_down_world_y,
        underwater_camera_height,
    )
    from study.scene.user_scene import reference_sky_parts

    size = exp["reference.texture_size"]
    extent = texture_extent(exp)
    y_cam = underwater_camera_height(exp)
    sky, sun = reference_sky_parts(exp)
    world_y = top_down_world_y(exp, extent, size)
    gain = np.exp(camera_ray_optical_depth(exp, y_cam, world_y))
    X, Z = lighting.texel_centres(extent, size)
    hx, hz = exp["pool.half_extent"]
    inside = (np.abs(X) < hx - 0.1) & (np.abs(Z) < hz - 0.1) & (world_y < y_cam)
    geo, medium = lighting.lighting_scene(exp, True)
    seeds = iter(range(10_000))
    rows = []
    for term, env in (("sun", sun), ("sky", sky)):
        if env.max() <= 0.0:
            continue
        scene, _ = lighting._top_down_scene(
            mi,
            exp,
            water=True,
            sky=env,
            medium=medium,
            integrator=lighting._albedo_aov(exp, True, max_depth=3),
        )
        sensor = ortho_sensor(mi, extent, size, spp, 0, y_cam=y_cam, medium=medium)

        def path_traced():
            img = to_gl_order(
                mi,
                sensor,
                np.array(mi.render(scene, sensor=sensor, spp=spp, seed=next(seeds)), np.float32),
                extent,
            )
            return img[..., :3] * gain

        if term == "sun":
            n = exp["reference.sun_photons"] * size * size

            def traced():
                return sun_photons.sun_direct(
                    mi, geo, exp, sun, extent, size, n, [next(seeds)], y_cam
                )[0][0]
        else:
            nd = exp["reference.sky_directions"]
            albedo = lighting.render_dry(exp, extent, size, exp["reference.wall_spp"], 0)[1]

            def traced():  # as shipped: the mean of two halves, undenoised here
                return albedo * np.mean(
                    [
                        direct_light.sky_direct(
                            mi, geo, exp, sky, extent, size, nd, next(seeds), y_cam
                        )
                        for _ in range(2)
                    ],
                    axis=0,
                )

        row = {"experiment": exp["name"], "term": term}
        for name, fn in (("path", path_traced), ("traced", traced)):
            _, seconds = _timed(fn, repeats)
            est = np.stack([fn() for _ in range(n_est)])[:, inside]  # (n_est, texels, 3)
            mean = est.mean((0, 1))
            rel_se = np.sqrt(est.var(0, ddof=1).mean(0)) / mean
            row[name] = {
                "seconds": seconds,
                "mean": mean,
                "mean_se": est.mean(1).std(0, ddof=1) / np.sqrt(n_est),
                "rel_se": rel_se,
            }
        p, t = row["path"], row["traced"]
        row["ratio"] = t["mean"] / p["mean"]
        row["ratio_se"] = row["ratio"] * np.sqrt(
            (p["mean_se"] / p["mean"]) ** 2 + (t["mean_se"] / t["mean"]) ** 2
        )
        row["efficiency"] = (p["rel_se"] ** 2 * p["seconds"]) / (t["rel_se"] ** 2 * t["seconds"])
        rows.append(row)
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("experiments", nargs="+")
    ap.add_argument(
        "--spp", type=int, default=32, help="samples per texel of the path tracer's estimate"
    )
    ap.add_argument("--estimates", type=int, default=4, help="independent estimates per estimator")
    ap.add_argument("--repeats", type=int, default=3, help="timed runs per estimator (median)")
    args = ap.parse_args(argv)
    from study import init_backend, load_experiment

    init_backend()
    print(
        "| experiment | term | path tracer s / traced s | mean traced / path tracer (R, G, B) | "
        "texel noise, path tracer (R, G, B) | texel noise, traced | efficiency (R, G, B) |"
    )
    print("|---|---|---|---|---|---|---|")

    def f3(a):
        return " / ".join(f"{v:.3f}" for v in a)

    for path in args.experiments:
        for r in run(load_experiment(path), args.spp, args.estimates, args.repeats):
            print(
                f"| {r['experiment']} | {r['term']} | {r['path']['seconds']:.2f} / "
                f"{r['traced']['seconds']:.2f} | "
                f"{f3(r['ratio'])} (+- {f3(r['ratio_se'])}) | {f3(r['path']['rel_se'])} | "
                f"{f3(r['traced']['rel_se'])} | "
                + " / ".join(f"{v:.0f}" for v in r["efficiency"])
                + " |",
                flush=True,
            )


if __name__ == "__main__":
    main()
