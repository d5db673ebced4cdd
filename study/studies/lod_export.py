"""The chosen level-of-detail policy as one shader, drawn and scored at the experiment's
resolution: its seams, its cost with the blend margins, the GL check.

The policy of ``study.studies.lod.scene_policies`` is chosen from the maps of the points
measured in full, each band's constants those of its point. Here its bands' shaders, at those
constants, are rendered by the port at the experiment's resolution and mixed per pixel by the
weights the exported shader computes (``study.export.policy_shader.band_weights``), next to the
lowest-FLIP point and the single point the policy is weighed against (the cheapest within the
tradeoff's tolerance of the lowest FLIP):

* ``margin``: the blend's half-width, the narrowest of :data:`MARGIN_STEPS` whose strips show
  no seam (``margins_tried``: each with its worst seam and its fetches);
* ``flip``, ``fetches``: the policy's mean FLIP and texture fetches per water pixel, a pixel in
  a blend margin paying for both its bands; ``d_flip`` and ``se``: its FLIP above the single
  point's with the paired standard error of 4 x 4-pixel blocks; ``fetch_ratio``: its fetches
  over the single point's; ``reaches``: within one standard error at
  ``lod.TARGET_RATIO`` or less;
* ``seams``: FLIP in a strip :data:`STRIP` pixels wide each side of every boundary between
  bands, of the mixed image against the bands' own (each pixel's FLIP in its band's image,
  where no seam can be): ``ratio`` over :data:`SEAM_RATIO` is a seam a player may see;
* ``gl_check``: ``policy.frag`` (``study.export.policy_shader.compose``) run on OpenGL
  (llvmpipe) against the port's mixed image, with the GL check's thresholds; an outlier is
  explained where a band that shades the pixel explains it; ``hlsl_check``: the exported HLSL
  alike, compiled back by glslang and translated by SPIRV-Cross.

Written into the policy's folder: ``policy.frag`` and ``water.vert`` (the core files); the
engine targets of every export with their binding sheets (``study.export.targets``: GLSL ES
3.00, HLSL, Metal, SPIR-V, WGSL where Node.js and naga are set up); for an engine that switches
shaders itself, each band's own shader (``bands/b<k>.frag``, GL-checked alone) and
``BANDS.md``, their table; and ``policy.json`` (measure, bounds in the shader's unit, margin,
per band its configuration, variant, constants, share of the water, fetches and file; the
figures above; the targets' files and checks).
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
from scipy import ndimage

from shaders_port.gl.compare import compare_outputs, port_reasons
from shaders_port.gl.renderer import GLRenderer
from shaders_port.gl.round_trip import TranslatedRenderer
from shaders_port.glsl_text import compile_check, read_source
from shaders_port.spirv.tools import hlsl_round_trip
from shaders_port.inputs import Constants
from shaders_port.variants import get_variant

from .._metrics import flip_map
from ..calibration.frames import Frame
from ..calibration.scoring import Scorer
from ..calibration.shader import Shader
from ..export.gl_check import gl_renderer_of, verdict
from ..export.targets import resolve_targets, translate_targets
from ..export.policy_shader import SHADER_MEASURES, Band, band_source, band_weights, compose
from ..scene.mitsuba_scene import camera_view_proj
from ..sweep import load_scene
from .lod import TARGET_RATIO, band_measures, paired_difference

#: the blend's half-width in the log of each measure (footprint grows about as distance cubed)
MARGINS = {"distance": 0.05, "footprint": 0.15}
STRIP = 8  # pixels each side of a band boundary in the seam's strip
SEAM_RATIO = 1.1  # a strip's FLIP over the bands' own there above which a seam shows
# the margins tried, as shares of the widest (:func:`margin_for`): the narrowest without a seam
# is drawn (a pixel in a margin pays for both its bands)
MARGIN_STEPS = (1.0, 0.3, 0.1, 0.01)


def margin_for(measure: str, bounds) -> float:
    """The blend margin of a policy: :data:`MARGINS`, narrowed to 0.45 of the log of the
    closest adjacent bounds' ratio so that no two margins overlap."""
    b = np.log(np.asarray(bounds, np.float64))
    gap = float(np.diff(b).min()) if len(b) > 1 else np.inf
    return float(min(MARGINS[measure], 0.45 * gap))


def _to_shader(measure: str, width: int, height: int) -> float:
    """What turns ``band_measures``' ``measure`` at ``width`` x ``height`` into the policy
    shader's (``study.export.policy_shader.SHADER_MEASURES``): the footprint times the image's
    pixels, the distance as it is."""
    return float(width * height) if measure == "footprint" else 1.0


def shader_measure(measure: str, maps: dict, width: int, height: int) -> np.ndarray:
    """The policy shader's measure from ``band_measures`` maps at ``width`` x ``height``."""
    return maps[measure] * _to_shader(measure, width, height)


def shader_bounds(policy: dict) -> list[float]:
    """A policy's bounds (``lod`` records, the measure at its ``resolution``) in the shader's
    unit."""
    scale = _to_shader(policy["measure"], *policy["resolution"])
    return [float(b) * scale for b in policy["bounds"]]


def bands_of(policy: dict) -> list[Band]:
    """The policy's bands: each its point's variant with the point's fitted constants."""
    return [
        Band(p["variant"], Constants.from_dict(p["fitted"]), label)
        for p, label in zip(policy["band_points"], policy["bands"])
    ]


def _render(exp, spec, shaders: dict, mv: str, checked) -> tuple[dict, np.ndarray]:
    """(label -> (Band, Score, port output with diagnostics, inputs as uploaded) of each
    configuration of ``shaders`` (label -> Band) at the experiment's resolution, the port's
    output and the inputs only for the labels in ``checked`` (the bands the GL check mixes;
    None elsewhere), the reference image (H, W, 3) float32 linear RGB)."""
    _, ref, inputs = load_scene(spec, mv)
    out = {}
    for label, band in shaders.items():
        shader = Shader.of_table(exp, band.variant)
        frame = Frame.of(exp, ref, shader.with_inputs(exp, inputs, mv))
        score = Scorer(shader, [frame], mv)(0, band.constants)
        if label not in checked:
            out[label] = (band, score, None, None)
            continue
        variant = get_variant(band.variant)
        # the raycast ports' diagnostics give the GL check its reasons (colour bit-identical)
        kw = {"diagnose": True} if getattr(variant.port(), "GL_CHECK_DIAGNOSE", False) else {}
        port = variant.render(frame.inputs, band.constants, **kw).numpy()
        out[label] = (band, score, port, variant.prepare_inputs(frame.inputs))
    return out, ref.image


def merged_inputs(uploaded: list):
    """One ``ShaderInputs`` with every texture and vector the bands read (each band's inputs as
    its application uploads them). ValueError when the bands need the textures at different
    precisions (``textures = 'game'`` and float)."""
    first = uploaded[0]
    fields = {}
    for i in uploaded[1:]:
        if not np.array_equal(i.normal_map, first.normal_map) or not np.array_equal(
            i.refraction_texture, first.refraction_texture
        ):
            raise ValueError(
                "the policy's bands read the textures at different precisions (a 'game' "
                "textures band beside a float one): one shader cannot bind both"
            )
    for f in dataclasses.fields(first):  # the optional inputs: buffers, matrices, cube maps
        if getattr(first, f.name) is None:
            given = [getattr(i, f.name) for i in uploaded if getattr(i, f.name) is not None]
            if given:
                fields[f.name] = given[0]
    return dataclasses.replace(first, **fields)


def strips(band: np.ndarray, water: np.ndarray, width: int = STRIP) -> list[np.ndarray]:
    """Per boundary j (between bands j and j + 1 of the (H, W) int map ``band``), the water
    pixels ``width`` pixels either side of it: within ``width - 1`` pixels (Chebyshev) of a
    water pixel whose 4-neighbour on the water lies on the other side."""
    cross = ndimage.generate_binary_structure(2, 1)
    square = np.ones((2 * width - 1, 2 * width - 1), bool)
    out = []
    for j in range(int(band[water].max(initial=0))):
        below, above = water & (band <= j), water & (band > j)
        edge = (below & ndimage.binary_dilation(above, cross)) | (
            above & ndimage.binary_dilation(below, cross)
        )
        out.append(ndimage.binary_dilation(edge, square) & water)
    return out


def _mix(weights: np.ndarray, images: list) -> np.ndarray:
    """sum_k weights[k] * images[k] ((K, H, W) weights, (H, W, 3) images), NaN weights as 0."""
    w = np.nan_to_num(weights)
    return sum(w[k][..., None] * np.nan_to_num(img) for k, img in enumerate(images))


def gl_check_policy(
    src: str, weights: np.ndarray, ports: list[dict], uploaded: list, water: np.ndarray,
    hlsl: str | None = None,
) -> dict:  # fmt: skip
    """The figures of ``compare_port_gl`` (with ``gl_renderer``) of the policy's shader ``src``
    (:func:`~study.export.policy_shader.compose`) run on OpenGL with the bands' inputs
    (``uploaded``, as each band's application uploads them: :func:`merged_inputs`) against
    the port's mix of the bands' outputs (``ports``: ``ShaderOutput.numpy()`` dicts) by
    ``weights`` ((K, H, W), ``band_weights``) on ``water`` ((H, W) bool). ``hlsl``: run that
    HLSL instead, compiled back by glslang's HLSL front end and translated to GLSL by
    SPIRV-Cross, as every export's HLSL check. An outlier is explained where a band with
    weight there explains it (``shaders_port.gl.compare.port_reasons``)."""
    inputs = merged_inputs(uploaded)
    if hlsl is None:
        compile_check(src, "frag")
        renderer = GLRenderer("water_refraction", inputs, source=src)
    else:
        glsl, refl = hlsl_round_trip(hlsl, "frag", "hlsl/policy.frag.hlsl")
        renderer = TranslatedRenderer("water_refraction", inputs, glsl, refl)
    with renderer as r:
        rgba, gl_mask = r.render(None)
        gl = gl_renderer_of(r)
    masks = [p["mask"] > 0.5 for p in ports]
    reasons: dict = {}
    for k, (p, m) in enumerate(zip(ports, masks)):
        for name, why in port_reasons(p, m).items():
            reasons[name] = reasons.get(name, np.zeros_like(m)) | (why & (weights[k] > 0))
    mask = np.logical_and.reduce(masks) & water
    out = {"color": _mix(weights, [p["color"] for p in ports]), "mask": mask.astype(np.float32)}
    return {**compare_outputs(out, rgba, gl_mask & mask, reasons, {}), "gl_renderer": gl}


def _drawn(ref, scores: list, m: np.ndarray, bounds, margin: float, water: np.ndarray) -> dict:
    """The policy of ``scores`` (each band's ``Score``) drawn at ``margin``: ``weights``
    (K, H, W), ``flip`` and ``fetch`` maps ((H, W), NaN off ``water``; a pixel pays for every
    band with weight there), ``own`` (each pixel's FLIP in its band's own image), ``band``
    (each pixel's band without a margin) and ``seams`` (:func:`strips`' figures)."""
    weights = band_weights(m, bounds, margin)
    fmap = np.where(water, flip_map(ref, _mix(weights, [s.image for s in scores])), np.nan)
    own_maps = [np.where(water, s.flip_map, np.nan) for s in scores]
    band = np.minimum(np.searchsorted(np.asarray(bounds), np.nan_to_num(m), side="right"),
                      len(scores) - 1)  # fmt: skip
    own = np.choose(band, own_maps)
    shading = np.nan_to_num(weights) > 0
    fetch = sum(shading[k] * s.diagnostics.maps["fetches"] for k, s in enumerate(scores))
    seams = []
    for j, strip in enumerate(strips(band, water)):
        if strip.any():
            a, b = float(fmap[strip].mean()), float(own[strip].mean())
            seams.append({"boundary": j, "pixels": int(strip.sum()), "flip": a, "own_flip": b,
                          "ratio": a / b if b > 0 else None})  # fmt: skip
    worst = max((x["ratio"] for x in seams if x["ratio"] is not None), default=None)
    return {"weights": weights, "flip": fmap, "fetch": np.where(water, fetch, np.nan),
            "own": own, "band": band, "seams": seams, "seam_ratio": worst}  # fmt: skip


def _narrowest(ref, scores, m, bounds, measure: str, water) -> tuple[float, dict, list]:
    """(margin, :func:`_drawn` at it, every margin tried with its worst seam and fetches): the
    narrowest of :data:`MARGIN_STEPS` times the measure's margin (:func:`margin_for`) whose
    strips show no seam (:data:`SEAM_RATIO`), else the widest."""
    widest = margin_for(measure, bounds)
    tried, chosen = [], None
    for step in MARGIN_STEPS:
        d = _drawn(ref, scores, m, bounds, widest * step, water)
        tried.append({"margin": widest * step, "seam_ratio": d["seam_ratio"],
                      "fetches": float(np.nanmean(d["fetch"]))})  # fmt: skip
        if d["seam_ratio"] is None or d["seam_ratio"] <= SEAM_RATIO:
            chosen = (widest * step, d)
    if chosen is None:
        chosen = (widest, _drawn(ref, scores, m, bounds, widest, water))
    return chosen[0], chosen[1], tried


def measure_policy(exp, spec, lod: dict, mv: str) -> tuple[dict, dict]:
    """The figures of the module docstring for the chosen policy of ``lod`` (a
    ``scene_policies`` record with its ``policy``), and the files of its folder (relative path
    -> bytes: the core files, the engine targets, ``policy.json``)."""
    policy = {**lod["policy"], "resolution": lod["resolution"]}
    bands, bounds, measure = bands_of(policy), shader_bounds(policy), policy["measure"]
    configs = {b.label: b for b in bands}
    for key in ("best", "single"):
        p = lod[key]
        configs.setdefault(p["label"], Band(p["variant"], Constants.from_dict(p["fitted"]),
                                            p["label"]))  # fmt: skip
    drawn, ref = _render(exp, spec, configs, mv, {b.label for b in bands})
    w, h = exp.resolution
    maps = band_measures(camera_view_proj(exp, w, h), exp.section("camera")["position"], w, h)
    m = shader_measure(measure, maps, w, h)
    water = np.logical_and.reduce([drawn[c][1].mask for c in configs]) & np.isfinite(m)
    scores = [drawn[b.label][1] for b in bands]
    margin, d, tried = _narrowest(ref, scores, m, bounds, measure, water)
    single = drawn[lod["single"]["label"]][1]
    single_flip = np.where(water, single.flip_map, np.nan)
    best_flip = np.where(water, drawn[lod["best"]["label"]][1].flip_map, np.nan)
    d_flip, se = paired_difference(d["flip"], single_flip)
    src = compose(bands, measure, bounds, margin)
    check = ([drawn[b.label][2] for b in bands], [drawn[b.label][3] for b in bands], water)
    res = gl_check_policy(src, d["weights"], *check)
    own = np.ones((1, h, w))  # each band's own file, alone on the water, against its port
    band_checks = [
        verdict(gl_check_policy(band_source(b), own, [port], [up], water), f"band {k}'s shader")
        for k, (b, port, up) in enumerate(zip(bands, *check[:2]))
    ]
    n, fetches = int(water.sum()), float(np.nanmean(d["fetch"]))
    single_fetches = float(single.diagnostics.maps["fetches"][water].mean())

    def on_band(x, k):
        return float(np.nanmean(np.where(water & (d["band"] == k), x, np.nan)))

    record = {
        "measure": measure,
        "unit": SHADER_MEASURES[measure],
        "bounds": bounds,
        "margin": margin,
        "margins_tried": tried,
        "resolution": [w, h],
        "bands": [
            {
                "label": b.label,
                "variant": b.variant,
                "share": float((water & (d["band"] == k)).sum() / n),
                "shaded_share": float((water & (np.nan_to_num(d["weights"][k]) > 0)).sum() / n),
                "fetches": on_band(d["fetch"], k),
                "own_flip": on_band(d["own"], k),
                "single_flip": on_band(single_flip, k),
                "constants": b.constants.to_dict(),
                "file": f"bands/b{k}.frag",
                "gl_check": band_checks[k],
            }
            for k, b in enumerate(bands)
        ],
        "flip": float(np.nanmean(d["flip"])),
        "fetches": fetches,
        "best": {"label": lod["best"]["label"], "flip": float(np.nanmean(best_flip))},
        "single": {
            "label": lod["single"]["label"],
            "flip": float(np.nanmean(single_flip)),
            "fetches": single_fetches,
        },
        "d_flip": d_flip,
        "se": se,
        "within": bool(d_flip <= se),
        "fetch_ratio": fetches / single_fetches if single_fetches > 0 else None,
        "seams": d["seams"],
        "seam_ratio": d["seam_ratio"],
        "no_seam": d["seam_ratio"] is None or d["seam_ratio"] <= SEAM_RATIO,
        "gl_check": verdict(res, "the exported level-of-detail policy"),
    }
    ratio = record["fetch_ratio"]
    record["reaches"] = bool(record["within"] and ratio is not None and ratio <= TARGET_RATIO)
    core = {"policy.frag": src, "water.vert": read_source("water", "vert", "core")}
    files, manifest = translate_targets(core, resolve_targets(None), {}, SHEET_NOTE)
    record["engine_targets"] = manifest["targets"]
    hlsl = files["hlsl/policy.frag.hlsl"].decode()
    what = "the exported level-of-detail policy's HLSL (through glslang -D and SPIRV-Cross)"
    record["hlsl_check"] = verdict(gl_check_policy(src, d["weights"], *check, hlsl=hlsl), what)
    files.update({k: v.encode() for k, v in core.items()})
    files.update({f"bands/b{k}.frag": band_source(b).encode() for k, b in enumerate(bands)})
    files["BANDS.md"] = bands_sheet(record).encode()
    files["policy.json"] = (json.dumps(record, indent=1) + "\n").encode()
    return record, files


def bands_sheet(record: dict) -> str:
    """``BANDS.md``: the bands of a drawn policy (:func:`measure_policy`'s record) for an
    engine that switches shaders itself, nearest first."""
    unit, bounds, m = record["unit"], record["bounds"], record["margin"]
    edges = [None, *bounds, None]
    lines = [
        "# The bands of a level-of-detail policy",
        "",
        f"Measure: {record['measure']}, {unit}; `policyMeasure()` in `policy.frag` computes it. "
        f"Shade a pixel with the band whose range holds its measure; within a factor of "
        f"exp({m:.3g}) of a bound, `policy.frag` mixes the two bands by "
        f"`smoothstep(-{m:.3g}, {m:.3g}, log(measure / bound))`. Each band's file is its "
        "shader alone (its constants and defines written in), checked on OpenGL against the "
        "study's port like every export.",
        "",
        "| band | measure from | to | configuration | file | share of the water | fetches "
        "| FLIP on its pixels | GL check |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for k, b in enumerate(record["bands"]):
        lo = "" if edges[k] is None else f"{edges[k]:.4g}"
        hi = "" if edges[k + 1] is None else f"{edges[k + 1]:.4g}"
        gl = "passed" if b["gl_check"]["passed"] else f"FAILED: {b['gl_check']['reason']}"
        lines.append(
            f"| {k} | {lo} | {hi} | {b['label']} | `{b['file']}` | {100 * b['share']:.0f} % "
            f"| {b['fetches']:.3g} | {b['own_flip']:.4f} | {gl} |"
        )
    return "\n".join(lines) + "\n"


#: what the binding sheets of a policy say of its constants
SHEET_NOTE = [
    "The bands' constants are constants of `policy.frag` (names prefixed `b<k>_`, band k "
    "nearest first); `policy.json` lists each band's constants, the measure, bounds and margin.",
    "",
]


def export_policy(exp, spec, lod: dict, folder: Path, mv: str) -> dict:
    """:func:`measure_policy` of the scene's chosen policy, written into ``folder`` (module
    docstring) all or nothing: a new folder beside the old one, swapped in by renames. Returns
    the record ``policy.json`` holds."""
    record, files = measure_policy(exp, spec, lod, mv)
    folder = Path(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
    try:
        for rel, data in files.items():
            (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
            (tmp / rel).write_bytes(data)
        old = folder.with_name(f".{folder.name}.old")
        if folder.exists():
            os.replace(folder, old)
        os.replace(tmp, folder)
        shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return record


def export_policies(exps, specs, summary: dict, out: Path, mv: str, log) -> None:
    """Each scene's chosen policy (its summary's ``lod``) exported into ``policy[/<scene>]``
    (:func:`export_policy`); the record, with ``folder`` relative to ``out``, becomes the
    ``lod``'s ``export``. A policy that cannot be one shader (its bands read the textures at
    different precisions) gets ``{"error": why}`` instead. A scene without a policy keeps no
    policy folder of an earlier run."""
    for exp, spec in zip(exps, specs):
        lod = summary["scenes"][exp.name].get("lod")
        folder = out.joinpath("policy", *([] if len(exps) == 1 else [exp.name]))
        if not lod or not lod.get("policy"):
            shutil.rmtree(folder, ignore_errors=True)
            continue
        try:
            rec = export_policy(exp, spec, lod, folder, mv)
        except ValueError as e:
            log(f"tradeoff: {exp.name}: the level-of-detail policy is not exported: {e}")
            lod["export"] = {"error": str(e)}
            continue
        lod["export"] = {**rec, "folder": str(folder.relative_to(out))}
        gl = "passed" if rec["gl_check"]["passed"] else "FAILED"
        log(f"tradeoff: {exp.name}: exported the level-of-detail policy to {folder} "
            f"(FLIP {rec['flip']:.4f}, {rec['fetches']:.1f} fetches, GL check {gl})")  # fmt: skip
