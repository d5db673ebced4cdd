"""What the far (grazing) part of the pool is made of: the fitted shader's Fresnel terms against
the reference's, row band by row band.

For each fit (an output folder of ``study calibrate``: its ``constants.json`` names the shader
variant and holds the fitted constants) the refraction shader's colour is split into the terms
of its Fresnel combine (block [9]):

* ``F*sky``: ``FresnelCoeffs.g * vReflection`` without the highlight (the cube-map sky),
* ``F*spec``: ``FresnelCoeffs.g *`` the highlight (block [8]),
* ``T*refr``: ``FresnelCoeffs.r * vRefraction`` (the attenuated raycast refraction),

(checked to add up to the port's colour). The reference is split the same way by path tracing
the experiment's rows ``--rows`` again with the water's dielectric reduced to one term
(``study.scene.mitsuba_scene.build_scene(water_bsdf=...)``): ``reflected`` (specular
transmittance 0: every path that only reflects off the water), ``reflected, no sun`` (the same
with ``sun.radiance = 0``: sky and walls; the difference is the sun's glitter), ``transmitted``
(specular reflectance 0) and ``both`` = full - reflected - transmitted (paths that reflect *and*
transmit at the water: light under the water reflected off the surface's underside, including
total internal reflection, and reflected rays that meet the water again). A render of the full
scene with the same settings checks the split against the cached reference.

Prints (1) per row band and fit: water pixels, FLIP, mean (shader - reference) linear RGB; (2) per
band the reference's terms and each fit's terms. Pixels: the calibration's scored water mask
(the port's quad and the reference's water, eroded by one pixel). All images linear RGB.

    STUDY_CACHE=... .venv/bin/python benchmarks/bench_grazing.py FIT_DIR [FIT_DIR ...]
        [--experiment experiments/default.toml] [--rows 40 100] [--spp 256] [--set KEY=VALUE ...]

The README's figures: ``study calibrate experiments/default.toml --set
fit.shader=water_refraction_beer`` and ``--set fit.shader=water_refraction_beer_walls`` into two
folders, then this script on both (``--spp 256``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

BANDS_FAR = 10  # rows per band in the first table inside --rows


def port_blocks(variant, inputs, constants):
    """``(m, P, C, f)``: the Dr.Jit types, prepared inputs, resolved constants and blocks
    [1]-[6] (``water_refraction.refraction_blocks``) of a ``water_refraction`` variant with
    reflection, for splitting its colour into terms."""
    from shaders_port.pipeline.frame import resolve_constants
    from shaders_port.pipeline.raster import prepare
    from shaders_port.pipeline.texture import backend_types
    from shaders_port.ports import water_refraction as wr

    opts = wr.options_of(variant.defines) if variant.shader == "water_refraction" else None
    if opts is None or not opts.reflection:
        raise ValueError(
            f"{variant.name}: the term split covers the water_refraction shader with reflection"
        )
    m = backend_types("llvm")
    P = prepare(variant.prepare_inputs(inputs), m)
    P = wr.with_maps_of(m, P, opts)
    C = resolve_constants(m, constants, "replay")
    return m, P, C, wr.refraction_blocks(m, P, C, opts)


def shader_terms(variant, inputs, constants) -> dict:
    """(H, W, 3) float32 images of the Fresnel-combine terms of a ``water_refraction`` variant
    (see the module doc) and the port's colour; 0 off the water."""
    import drjit as dr

    from shaders_port.pipeline.texture import clamp
    from shaders_port.ports import water_refraction as wr
    from shaders_port.ports.box import box_reflection, box_state

    # the blocks of water_refraction._shade, the combine's two products kept apart
    m, P, C, f = port_blocks(variant, inputs, constants)
    opts = wr.options_of(variant.defines)
    R = dr.normalize(wr.reflect(m, -f.vEye, f.vBumpTexMore))
    R.y = dr.maximum(R.y, 0.001)
    if opts.reflection_map == "box":  # the local cube map (BOX_REFLECTION)
        probe = box_state(m, inputs, variant.name)
        sky = box_reflection(m, P, probe, C, R)
    elif opts.reflection_map == "cube":
        sky = wr.cubemap_reflection(m, P, R) * C.reflectColor
    else:
        raise ValueError(
            f"{variant.name}: the term split covers the sky and local cube maps' reflections, "
            f"not {opts.reflection_map!r}"
        )
    spec = wr.specular_highlight(
        m, P, m.Array4f(0.0), f.vBumpTex, f.vEye, f.vLight, C, opts.specular, f.slope_variance
    )
    NdotV = clamp(dr.dot(f.vEye, f.vBumpTex), 0.0, 1.0)
    FresnelCoeffs = P.fresnelLookup.sample(m, NdotV, m.Float(0.5))
    r = P.raster
    out = {}
    for name, v, k in (
        ("F*sky", sky, FresnelCoeffs[1]),
        ("F*spec", spec, FresnelCoeffs[1]),
        ("T*refr", f.vRefraction, FresnelCoeffs[0]),
    ):
        img = np.zeros((r.height * r.width, 3), np.float32)
        img[r.index] = np.stack([np.array(v[c] * k) for c in range(3)], -1)
        out[name] = img.reshape(r.height, r.width, 3)
    out["port"] = variant.render(inputs, constants).numpy()["color"]
    gap = np.abs(out["F*sky"] + out["F*spec"] + out["T*refr"] - out["port"]).max()
    if gap > 1e-4:
        raise RuntimeError(
            f"{variant.name}: the terms do not add up to the port's colour (max gap {gap:.2g})"
        )
    return out


def load_fit(folder, exp, inputs, reference):
    """A ``study calibrate`` output folder of ``exp``: ``(variant, constants, the scored water
    mask (H, W) bool, shader_terms)``; exits naming the folder when it fits another experiment."""
    from shaders_port.inputs import Constants
    from shaders_port.variants import get_variant
    from study.fit.model import ShaderModel

    d = json.loads((Path(folder) / "constants.json").read_text())
    if d.get("experiment") != exp["name"]:
        raise SystemExit(f"{folder} is a fit of {d.get('experiment')!r}, not of {exp['name']!r}")
    v = get_variant(d["shader"])
    c = Constants.from_dict(d["constants"])
    w, h = exp["resolution"]
    mask = ShaderModel.from_experiment(exp, inputs, reference, shader=v.name, resolution=(w, h))
    return v, c, mask.mask, shader_terms(v, inputs, c)


def reference_terms(exp_path, overrides, rows, spp: int) -> dict:
    """(r1 - r0, W, 3) float32 renders of the reference's rows ``[r0, r1)`` at ``spp``: 'full',
    'reflected', 'reflected, no sun', 'transmitted', 'both' (see the module doc)."""
    import mitsuba as mi

    from study.config.experiment import load_experiment
    from study.scene.mitsuba_scene import build_scene

    out = {}
    for name, bsdf, extra in (
        ("full", {}, []),
        ("reflected", {"specular_transmittance": 0.0}, []),
        ("reflected, no sun", {"specular_transmittance": 0.0}, ["sun.radiance=[0,0,0]"]),
        ("transmitted", {"specular_reflectance": 0.0}, []),
    ):
        exp = load_experiment(exp_path, list(overrides) + extra)
        t0 = time.perf_counter()
        scene = build_scene(exp, water_bsdf=bsdf, rows=rows)
        out[name] = np.array(mi.render(scene, spp=spp, seed=7919), np.float32)
        print(
            f"# reference term '{name}': rows {rows[0]}-{rows[1] - 1}, {spp} spp, "
            f"{time.perf_counter() - t0:.1f} s",
            file=sys.stderr,
            flush=True,
        )
    out["both"] = out["full"] - out["reflected"] - out["transmitted"]
    return out


def _rgb(x) -> str:
    return " ".join(f"{v:+.3f}" if v < 0 else f"{v:.3f}" for v in x)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("fits", nargs="+", help="study calibrate output folders (constants.json)")
    ap.add_argument("--experiment", default=str(REPO / "experiments" / "default.toml"))
    ap.add_argument(
        "--rows", nargs=2, type=int, default=(40, 100), help="far band: first row, end row"
    )
    ap.add_argument(
        "--spp", type=int, default=256, help="samples per pixel of the reference's term renders"
    )
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    a = ap.parse_args(argv)

    from study._backend import init_backend
    from study.calibration.frames import load_scene_data
    from study._metrics import flip_map
    from study.config.experiment import load_experiment

    exp = load_experiment(a.experiment, a.set)
    variant_name = init_backend(exp["variant"])
    ref, inputs, _ = load_scene_data(exp, variant_name)
    w, h = exp["resolution"]
    r0, r1 = a.rows
    if not 0 <= r0 < r1 <= h:
        raise SystemExit(f"--rows {r0} {r1}: need 0 <= first < end <= {h} (the image's rows)")
    fits = {}
    for folder in a.fits:
        v, c, mask, terms = load_fit(folder, exp, inputs, ref.image)
        fits[f"{v.name} ({Path(folder).name})"] = (terms, flip_map(ref.image, terms["port"]), mask)
    mask = np.logical_and.reduce([f[2] for f in fits.values()])  # pixels scored for every fit

    bands = [(b, min(b + BANDS_FAR, r1)) for b in range(r0, r1, BANDS_FAR)]
    bands += [(r0, r1), (r1, h), (0, h)]
    print(
        f"# {exp['name']}: reference {ref.spp} spp (noise {ref.noise:.3g}); FLIP and mean "
        f"(shader - reference), linear RGB, per row band [first, end)"
    )
    print("| rows | water px | " + " | ".join(f"{n}: FLIP, mean diff" for n in fits) + " |")
    print("|---|---|" + "---|" * len(fits))
    for b0, b1 in bands:
        mk = mask.copy()
        mk[:b0], mk[b1:] = False, False
        cells = [
            f"{fm[mk].mean():.4f}, {_rgb((t['port'][mk] - ref.image[mk]).mean(0))}"
            for t, fm, _ in fits.values()
        ]
        print(f"| {b0}-{b1 - 1} | {mk.sum()} | " + " | ".join(cells) + " |")

    rt = reference_terms(a.experiment, a.set, (r0, r1), a.spp)
    sub = mask[r0:r1]
    gap = np.abs((rt["full"] - ref.image[r0:r1])[sub].mean(0)).max()
    print(
        f"\n# reference terms ({a.spp} spp) in rows {r0}-{r1 - 1}; |mean(full re-render - cached "
        f"reference)| = {gap:.4f} (noise of the split)"
    )
    half = [(r0, (r0 + r1) // 2), ((r0 + r1) // 2, r1), (r0, r1)]
    print("| rows | term | " + " | ".join(["reference"] + list(fits)) + " |")
    print("|---|---|" + "---|" * (1 + len(fits)))
    for b0, b1 in half:
        mk = sub.copy()
        mk[: b0 - r0], mk[b1 - r0 :] = False, False
        rows = [
            (
                "sky / walls (reflected, no sun | F*sky)",
                rt["reflected, no sun"][mk].mean(0),
                "F*sky",
            ),
            (
                "sun (reflected - no sun | F*spec)",
                (rt["reflected"] - rt["reflected, no sun"])[mk].mean(0),
                "F*spec",
            ),
            (
                "refraction (transmitted + both | T*refr)",
                (rt["transmitted"] + rt["both"])[mk].mean(0),
                "T*refr",
            ),
        ]
        for label, rv, key in rows:
            cells = [
                f"{_rgb(t[key][r0:r1][mk].mean(0))} ({_rgb(t[key][r0:r1][mk].mean(0) - rv)})"
                for t, _, _ in fits.values()
            ]
            print(f"| {b0}-{b1 - 1} | {label} | {_rgb(rv)} | " + " | ".join(cells) + " |")
        print(
            f"| {b0}-{b1 - 1} | of which both | {_rgb(rt['both'][mk].mean(0))} |" + " |" * len(fits)
        )
    print("\n(shader cells: the term, and in brackets its excess over the reference's)")


if __name__ == "__main__":
    main()
