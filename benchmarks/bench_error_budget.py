"""What a fitted shader's remaining error is made of: each term of its Fresnel combine replaced by
the reference's (an oracle), and the sun's glitter drawn by better highlights than the shader's.

The fitted ``water_refraction`` variant's colour is split into ``F*sky`` (reflection without the
highlight: the sky cube map's or the local cube map's), ``F*spec`` (the highlight) and ``T*refr``
(the refraction), and the reference into the same terms by path tracing the whole image again with
the water's dielectric reduced to one term (``bench_grazing.shader_terms`` and
``reference_terms``: ``reflected, no sun`` is sky and walls, ``reflected`` minus it is the sun's
glitter, ``transmitted`` plus ``both`` the refraction). Printed, FLIP and RMSE on the
calibration's scored water pixels against the cached reference (what ``study calibrate`` and
``study tradeoff`` score):

1. **Oracles**: the shader with one, two or all three of its terms replaced by the reference's.
   What a term's oracle lowers FLIP by is the most any technique for that term can buy with the
   other terms as they are; all three replaced is a second reference, so its FLIP is the
   reference noise the other rows stand on.
2. **Where the error is**: the water pixels split by what the reference shows there (``glint``:
   the sun's term brighter than ``--glint`` in luminance; ``far wall``: the walls' share of the
   reflection, the reflected-without-sun term darker than the sky's cube map lookup by more
   than half; the rest), each class's share of the pixels and of the mean FLIP.
3. **Highlights**: the shader's own sky and refraction with its own highlight, (a) a Phong
   highlight (the Phong sibling of the shader's configuration), (b) that highlight averaged
   over ``--ss`` x ``--ss`` sub-pixel samples (what a filtered normal map's variance can at best
   stand for: Toksvig, LEAN, mip-mapped normals), (c) the exact reflection of the sun's disc
   (``sun.radius``, ``sun.radiance``) off the shader's own (scaled) normal, Fresnel weighted, at
   the pixel centre and averaged over the sub-pixel samples (a glint that follows the surface
   the shader's normal map describes, up to the sampling), (d) the same off the slope-blended
   normal of the shader's ``normals = "slopes"`` sibling (the normal of the layers' mean
   height), (e) the same off the reference surface's exact normal under the pixel's point on
   the water plane (what any normal map can at best give), (f) that normal where the pixel's
   eye ray meets the surface (the heights' parallax, which a normal map read on the plane
   does not have), (g) the disc off the normal of the shader's ``normals = "lean"`` sibling
   (the layers' mean slope over the pixel's footprint, from the mipmapped slope moments)
   widened by the variance of the slopes the pixel does not resolve as that shader widens it
   (``ports.highlight``: radius ``sqrt(r^2 + 16 variance)``, radiance times ``(r / r')^2``),
   one sample a pixel standing for the footprint, (h) the disc off the normal of the shader's
   ``parallax = "offset"`` sibling (the layers read where the eye ray meets the waves, shifted
   by their mean height: (f) as a normal map can give it, in one step). (a) and (b) are
   refitted in strength
   (least squares against the reference's sun term, the exponent from a grid), so neither
   keeps the fit's compromise.

    STUDY_CACHE=... .venv/bin/python benchmarks/bench_error_budget.py FIT_DIR
        [--experiment experiments/default.toml] [--spp 256] [--ss 4] [--json out.json]

``FIT_DIR``: a ``study calibrate`` output folder of a ``water_refraction`` variant on the
experiment (its ``constants.json``).
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

TERMS = ("F*spec", "F*sky", "T*refr")
LABEL = {"F*spec": "sun's glitter", "F*sky": "sky and walls reflected", "T*refr": "refraction"}
EXPONENTS = (16, 32, 64, 128, 256, 512, 1024, 2048, 4096)
LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)


def reference_split(rt: dict) -> dict:
    """The reference's renders of ``bench_grazing.reference_terms`` as the shader's terms."""
    return {
        "F*spec": rt["reflected"] - rt["reflected, no sun"],
        "F*sky": rt["reflected, no sun"],
        "T*refr": rt["transmitted"] + rt["both"],
    }


def supersampled(render, inputs, k: int) -> dict:
    """``render(inputs at k x the resolution)`` (a dict of (kH, kW, C) images) box-filtered back
    to the inputs' resolution, as the reference's box pixel filter averages its samples."""
    from study._metrics import downsample

    big = dataclasses.replace(inputs, width=inputs.width * k, height=inputs.height * k)
    return {n: downsample(v, k, k) for n, v in render(big).items()}


def surface_hits(eye: np.ndarray, plane: np.ndarray, waves, steps: int = 8) -> np.ndarray:
    """(N, 3) float64: where the eye rays through the water-plane points ``plane`` (N, 3, y = 0)
    meet the surface ``y = H(x, z)`` of ``waves`` (fixed-point iteration on the ray's length;
    the slopes are small)."""
    d = plane - eye
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    p = plane.copy()
    for _ in range(steps):
        h, _, _ = waves.height_and_gradient(p[:, 0], p[:, 2])
        p = eye + ((h - eye[1]) / d[:, 1])[:, None] * d
    return p


def glint_images(
    variant, inputs, constants, sun_dir, radius_deg, radiance, waves=None, displaced=False,
):  # fmt: skip
    """(H, W, 3) float32 at ``inputs``' resolution: ``disc``, the Fresnel-weighted radiance of
    the sun's disc reflected off the shader's scaled normal (``vBumpTexMore``) at each pixel
    centre (0 or the disc's radiance; a ``LEAN_NORMALS`` variant's disc widened by its
    unresolved slopes' variance, in the scaled normal's slopes, ``/ BumptexMult^2``), and ``F``,
    the Fresnel reflectance there. ``waves``
    (``height_and_gradient(x, z)``): the normal is instead that of this surface under the pixel
    centre's point on the water plane, exact (no normal map, no bump scale); ``displaced``: at
    the point where the pixel's eye ray meets that surface, seen from the eye there."""
    import drjit as dr
    from bench_grazing import port_blocks

    from shaders_port.pipeline.texture import clamp
    from shaders_port.ports import water_refraction as wr

    m, P, C, f = port_blocks(variant, inputs, constants)
    N, N_fresnel, vEye = f.vBumpTexMore, f.vBumpTex, f.vEye
    if waves is not None:
        p = np.asarray(P.raster.world, np.float64)
        if displaced:
            eye = np.asarray(inputs.viewpos, np.float64)
            p = surface_hits(eye, p, waves)
            e = (eye - p) / np.linalg.norm(eye - p, axis=-1, keepdims=True)
            vEye = m.Array3f(*e.T.astype(np.float32))
        _, gx, gz = waves.height_and_gradient(p[:, 0], p[:, 2])
        n = np.stack([-gx, np.ones_like(gx), -gz]) / np.sqrt(1.0 + gx * gx + gz * gz)
        N = N_fresnel = m.Array3f(*n.astype(np.float32))
    R = dr.normalize(wr.reflect(m, -vEye, N))
    cos_to_sun = R.x * sun_dir[0] + R.y * sun_dir[1] + R.z * sun_dir[2]
    if f.slope_variance is not None and waves is None:  # LEAN_NORMALS: the widened disc
        from shaders_port.ports.highlight import DEG2_PER_RAD2

        b = float(constants.bumptex_mult)
        wide2 = radius_deg**2 + 16.0 * DEG2_PER_RAD2 * f.slope_variance / (b * b)
        inside = dr.select(cos_to_sun >= dr.cos(dr.sqrt(wide2) * (np.pi / 180.0)), 1.0, 0.0)
        inside = inside * (radius_deg**2 / wide2)
    else:
        inside = dr.select(cos_to_sun >= np.cos(np.radians(radius_deg)), 1.0, 0.0)
    NdotV = clamp(dr.dot(vEye, N_fresnel), 0.0, 1.0)
    F = P.fresnelLookup.sample(m, NdotV, m.Float(0.5))[1]
    r = P.raster
    out = {}
    for name, v in (("disc", inside * F), ("F", F)):
        img = np.zeros((r.height * r.width, 3), np.float32)
        img[r.index] = np.array(v)[:, None] * (radiance if name == "disc" else 1.0)
        out[name] = img.reshape(r.height, r.width, 3)
    return out


def best_strength(spec: np.ndarray, target: np.ndarray, mask: np.ndarray) -> float:
    """Least-squares scale s >= 0 of ``spec`` towards ``target`` on ``mask``."""
    a, b = spec[mask].ravel(), target[mask].ravel()
    return max(0.0, float(a @ b / max(a @ a, 1e-30)))


def highlight_rows(variant, inputs, constants, terms, ref_sun, mask, score, k) -> list:
    """Rows (a), (b) of table 3 (see the module doc) on the Phong sibling of ``variant`` (its
    configuration with ``specular = phong``), after the fit's own highlight: ``(label, FLIP,
    RMSE, note)``."""
    from bench_grazing import shader_terms

    from shaders_port import space
    from shaders_port.variants import get_variant

    base = terms["F*sky"] + terms["T*refr"]
    rows = [("the fit's own highlight", *score(base + terms["F*spec"]), variant.name)]
    phong = get_variant(space.name_of({**space.choices_of(variant.name), "specular": "phong"}))
    s0 = float(constants.specular_strength)
    for label, kk in (("(a) Phong, refitted", 1), (f"(b) Phong over {k}x{k} samples", k)):
        best = None
        for e in EXPONENTS:
            c = constants.replace(specular_exponent=float(e))
            if kk == 1:
                spec = shader_terms(phong, inputs, c)["F*spec"]
            else:
                spec = supersampled(lambda i: shader_terms(phong, i, c), inputs, kk)["F*spec"]
            s = best_strength(spec, ref_sun, mask)
            fl, rm = score(base + s * spec)
            if best is None or fl < best[1]:
                best = (label, fl, rm, f"exponent {e}, strength {s * s0:.3g}")
        rows.append(best)
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("fit", help="a study calibrate output folder (constants.json)")
    ap.add_argument("--experiment", default=str(REPO / "experiments" / "default.toml"))
    ap.add_argument("--spp", type=int, default=256, help="samples per pixel of each term's render")
    ap.add_argument("--ss", type=int, default=4, help="sub-pixel samples per side, highlights")
    ap.add_argument("--glint", type=float, default=0.02, help="glint class: sun term luminance")
    ap.add_argument("--json", default=None)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    a = ap.parse_args(argv)

    from bench_grazing import load_fit, reference_terms

    from study._backend import init_backend
    from study._metrics import flip_map, rmse
    from study.calibration.frames import load_scene_data
    from study.scene.baseline_inputs import inputs_for_shader
    from study.config.experiment import load_experiment
    from shaders_port import space
    from shaders_port.variants import get_variant
    from study.scene.geometry import sun_direction
    from study.scene.mitsuba_scene import waves_of

    exp = load_experiment(a.experiment, a.set)
    ref, inputs, _ = load_scene_data(exp, init_backend(exp["variant"]))
    # what the fitted shader reads besides the sky cube map (the local cube map's box, ...)
    fitted = json.loads((Path(a.fit) / "constants.json").read_text())["shader"]
    inputs = inputs_for_shader(exp, inputs, fitted, exp["variant"])
    w, h = exp["resolution"]
    v, c, mask, terms = load_fit(a.fit, exp, inputs, ref.image)

    def score(img):
        return float(flip_map(ref.image, img)[mask].mean()), rmse(ref.image, img, mask)

    t0 = time.perf_counter()
    rt = reference_split(reference_terms(a.experiment, a.set, (0, h), a.spp))
    render_s = time.perf_counter() - t0
    out = {"experiment": exp["name"], "shader": v.name, "fit": Path(a.fit).name, "spp": a.spp}
    out["reference_spp"] = ref.spp
    out["terms_render_s"] = round(render_s, 1)

    # 1. oracles
    print(f"# {exp['name']}, {v.name} ({a.fit}); reference {ref.spp} spp, terms {a.spp} spp")
    print("| terms from the reference | FLIP | RMSE |\n|---|---|---|")
    oracles = []
    for n in range(4):
        for combo in itertools.combinations(TERMS, n):
            img = sum(rt[t] if t in combo else terms[t] for t in TERMS)
            fl, rm = score(img)
            label = ", ".join(LABEL[t] for t in combo) or "none (the fitted shader)"
            oracles.append({"oracle": list(combo), "label": label, "flip": fl, "rmse": rm})
            print(f"| {label} | {fl:.4f} | {rm:.4f} |")
    out["oracles"] = oracles

    # 2. where the error is
    fm = flip_map(ref.image, terms["F*sky"] + terms["F*spec"] + terms["T*refr"])
    sun_l = rt["F*spec"] @ LUMA
    sky_ratio = (rt["F*sky"] @ LUMA) / np.maximum(terms["F*sky"] @ LUMA, 1e-6)
    glint = mask & (sun_l > a.glint)
    wall = mask & ~glint & (sky_ratio < 0.5)
    rest = mask & ~glint & ~wall
    total = fm[mask].sum()
    print("\n| pixel class | share of water pixels | FLIP there | share of the mean FLIP |")
    print("|---|---|---|---|")
    classes = []
    for name, mk in (("glint", glint), ("far wall", wall), ("rest", rest)):
        row = {
            "class": name,
            "pixels": float(mk.sum() / mask.sum()),
            "flip": float(fm[mk].mean()) if mk.any() else float("nan"),
            "flip_share": float(fm[mk].sum() / total),
        }
        classes.append(row)
        print(f"| {name} | {row['pixels']:.3f} | {row['flip']:.4f} | {row['flip_share']:.3f} |")
    out["classes"] = classes

    # 3. highlights
    rows = highlight_rows(v, inputs, c, terms, rt["F*spec"], mask, score, a.ss)
    sun_dir = sun_direction(exp.sun.elevation, exp.sun.azimuth)
    radiance = np.asarray(exp.sun.radiance, np.float32)
    base = terms["F*sky"] + terms["T*refr"]
    choices = space.choices_of(v.name)
    slopes = get_variant(space.name_of({**choices, "normals": "slopes"}))
    lean = get_variant(space.name_of({**choices, "normals": "lean", "parallax": "off"}))
    normals = "average" if choices["normals"] == "lean" else choices["normals"]
    parallax = get_variant(space.name_of({**choices, "normals": normals, "parallax": "offset"}))
    surface = waves_of(exp)
    normals = (
        ("(c) the sun's disc off the shader's normal", v, None, False),
        ("(d) the sun's disc off the slope-blended normal", slopes, None, False),
        ("(e) the sun's disc off the surface's exact normal", v, surface, False),
        ("(f) the same where the eye ray meets the surface", v, surface, True),
        ("(g) the sun's disc widened by LEAN's unresolved slopes", lean, None, False),
        ("(h) the sun's disc off the parallax-shifted normal", parallax, None, False),
    )
    for what, shader, waves, displaced in normals:
        for kk in (1,) if shader is lean else (1, a.ss):
            g = supersampled(
                lambda i: glint_images(
                    shader, i, c, sun_dir, exp.sun.radius, radiance, waves, displaced
                ),
                inputs,
                kk,
            )
            label = f"{what}, {kk}x{kk} samples"
            rows.append((label, *score(base + g["disc"]), f"radius {exp.sun.radius} degrees"))
    rows.append(("the reference's sun term (oracle)", *score(base + rt["F*spec"]), ""))
    print("\n| highlight (the shader's sky and refraction) | FLIP | RMSE | |\n|---|---|---|---|")
    for label, fl, rm, note in rows:
        print(f"| {label} | {fl:.4f} | {rm:.4f} | {note} |")
    out["highlights"] = [dict(zip(("label", "flip", "rmse", "note"), r)) for r in rows]
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
