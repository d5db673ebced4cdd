"""Worker side of the speed-versus-accuracy study: the schedules of a variant and the jobs that fit,
score and time one (scene, variant, schedule) point, as jobs of the sweep engine
(``study.studies.tradeoff`` plans and runs them).

Per experiment and variant (``[tradeoff]`` table of the experiment, ``docs/experiment-keys.md``):

* the *anchor*: the continuous constants fitted at the seed's schedule (10, 3, 40) from the
  experiment's start constants (phase 1, one job per scene and variant);
* the *points*: every schedule of the grid ``steps_grazing x steps_steep x loop_cap`` plus the
  seed's schedule times each of ``scales`` (for ``water_reflection`` its reflection schedule is
  scaled too), each refitted warm from the anchor (phase 2); and one *converged* raymarch (the
  seed's schedule times ``converged_scale``), the variant's own error floor, which separates what
  the schedule costs from what the model cannot do.

Each point is measured by :func:`point_job` in a worker: FLIP and RMSE on the water pixels at the
experiment's full resolution; texture fetches and loop iterations per water pixel (mean, p99)
from the port's diagnostics; frame time of the fitted shader on llvmpipe at 512x512 and
1920x1080 (draw + glFinish, median of ``gl_repeats`` frames after one warm-up) drawn frame by
frame in turn with a fixed reference shader (the seed's ``water_refraction`` with its own
constants) in the same job, so the ratio to it compares fairly on a loaded machine; and the
port's frame time (Dr.Jit on the run's backend, 512x512, median of 5). The converged raymarch
gets no frame times (it is the error floor, not a candidate). For parsimony each point also
carries its count of fitted constants (``n_fitted``: fitted or at a bound) and the AIC / BIC of
its fit residual at the fit resolution (``study._metrics``).
"""

from __future__ import annotations

import dataclasses
import itertools
import statistics
import time

import numpy as np

from shaders_port import Constants
from shaders_port.gl.renderer import alternate_frames
from shaders_port.variants import get_variant

from .._metrics import flip_map, information_criteria, rmse
from ..calibration.fitting import FitOptions, fit_frames
from ..calibration.frames import Frame
from ..calibration.scoring import Scorer
from ..calibration.shader import Shader
from ..sweep import load_scene

SEED_SCHEDULE = {"steps_grazing": 10.0, "steps_steep": 3.0, "loop_cap": 40}
SEED_REFL_SCHEDULE = {"refl_steps_steep": 0.5, "refl_steps_grazing": 4.0, "refl_loop_cap": 60}
GL_SIZES = {"512": (512, 512), "1080p": (1920, 1080)}
REFERENCE_SHADER = "water_refraction"


def scaled_schedule(variant, factor: float) -> dict:
    """The original shader's schedule times ``factor`` (its reflection schedule too where the
    variant raymarches the reflection); step counts and caps kept at least 0.5 and 1."""
    s = {
        "steps_grazing": SEED_SCHEDULE["steps_grazing"] * factor,
        "steps_steep": max(0.5, SEED_SCHEDULE["steps_steep"] * factor),
        "loop_cap": max(1, int(round(SEED_SCHEDULE["loop_cap"] * factor))),
    }
    if "refl_loop_cap" in variant.schedule:
        s.update(
            {
                "refl_steps_steep": SEED_REFL_SCHEDULE["refl_steps_steep"] * factor,
                "refl_steps_grazing": SEED_REFL_SCHEDULE["refl_steps_grazing"] * factor,
                "refl_loop_cap": max(1, int(round(SEED_REFL_SCHEDULE["refl_loop_cap"] * factor))),
            }
        )
    return s


FIXED = {"kind": "fixed", "scale": None, "schedule": {}}  # a shader without a raymarch


def original_schedule(variant_name: str) -> dict:
    """The original shader's schedule for a variant, as :func:`schedules` lists it (``scale
    1``; its only one, ``fixed``, if it has no raymarch)."""
    variant = get_variant(variant_name)
    if not {"steps_grazing", "steps_steep", "loop_cap"} <= set(variant.schedule):
        return dict(FIXED)
    return {"kind": "scale", "scale": 1.0, "schedule": scaled_schedule(variant, 1.0)}


def schedules(exp, variant_name: str) -> list[dict]:
    """The schedules of one variant: ``{"kind": grid|scale|converged, "scale": f|None,
    "schedule": {constant: value}}``, distinct, in a stable order (the seed's one is
    ``scale 1``)."""
    variant = get_variant(variant_name)
    if original_schedule(variant_name)["kind"] == "fixed":
        return [dict(FIXED)]
    out, seen = [], set()

    def add(kind, scale, sched):
        k = tuple(sorted(sched.items()))
        if k not in seen:
            seen.add(k)
            out.append({"kind": kind, "scale": scale, "schedule": sched})

    for f in sorted(exp.tradeoff.scales):
        add("scale", f, scaled_schedule(variant, f))
    for g, s, c in itertools.product(
        exp.tradeoff.steps_grazing, exp.tradeoff.steps_steep, exp.tradeoff.loop_cap
    ):
        sched = {"steps_grazing": float(g), "steps_steep": float(s), "loop_cap": int(round(c))}
        if "refl_loop_cap" in variant.schedule:
            sched.update(SEED_REFL_SCHEDULE)
        add("grid", None, sched)
    add(
        "converged",
        exp.tradeoff.converged_scale,
        scaled_schedule(variant, exp.tradeoff.converged_scale),
    )
    return out


# ---- worker side ------------------------------------------------------------------------------


def job_frame(job: dict):
    """The shader of ``job["variant"]`` (``Shader``) and the job's scene as a ``Frame`` with
    the inputs that shader reads (from the sweep's render cache)."""
    mv = job.get("mitsuba_variant", "llvm_ad_rgb")
    exp, ref, inputs = load_scene(job["scene"], mv)
    shader = Shader.of_table(exp, job["variant"])
    return shader, Frame.of(exp, ref, shader.with_inputs(exp, inputs, mv))


def job_options(exp, shader, resolution=None, screen: bool = False) -> FitOptions:
    """The fit options of a point of ``shader``: the experiment's, over the constants a point
    refits (``Shader.point_parameters``), at ``resolution`` (default ``fit.resolution``).
    ``screen``: the adaptive search's screen (:func:`screen_job`), without the basin scan,
    with one sample at each fit pixel's centre in place of ``fit.target_resolution``'s
    footprint and with the squared error alone, not FLIP from its solution (the points it sends
    on are fitted with all three)."""
    options = FitOptions.of(
        exp, parameters=shader.point_parameters(exp), resolution=resolution, basin_scan=not screen
    )
    if not screen:
        return options
    loss = "linear" if options.loss == "flip" else options.loss
    return dataclasses.replace(options, target_resolution=None, loss=loss)


def job_start(shader, job: dict):
    """The start constants of ``job``: its ``start`` with its ``schedule``; None (the shader's
    own start constants) for a job without one (a user's shader)."""
    start = job.get("start")
    return None if start is None else shader.constants(start, job.get("schedule"))


def job_fit(job: dict, resolution=None, screen: bool = False):
    """(shader, frame, ``Fit``, fit seconds) of ``job`` fitted from ``job["start"]`` with its
    schedule, through the calibration's one fit (``study.calibration.fitting``) with the options
    of :func:`job_options`."""
    mv = job.get("mitsuba_variant", "llvm_ad_rgb")
    shader, frame = job_frame(job)
    options = job_options(frame.exp, shader, resolution, screen)
    t0 = time.perf_counter()
    fit = fit_frames([frame], shader, mv, options, job_start(shader, job))
    return shader, frame, fit, time.perf_counter() - t0


def anchor_job(job: dict) -> dict:
    """Phase 1: fit the continuous constants at the seed's schedule; returns them and the fit."""
    _, _, fit, fit_s = job_fit({**job, "schedule": {}})
    cal = fit.calibration
    return {
        "fitted": cal.fitted.to_dict(),
        "fit_seconds": fit_s,
        "iterations": cal.fit_summary.get("iterations", 0),
        "status_of": {n: p["status"] for n, p in cal.parameters.items()},
    }


def point_job(job: dict) -> dict:
    """Phase 2: one (scene, variant, schedule) point, refitted warm from the anchor and measured
    (see the module doc). Returns flat figures plus the fitted constants and their statuses."""
    shader, frame, fit, fit_s = job_fit(job)
    cal, exp = fit.calibration, frame.exp
    fitted_names = [n for n, p in cal.parameters.items() if p["status"] in ("fitted", "bound")]
    ic = information_criteria(fit.models[0].residual(cal.fitted), len(fitted_names))
    score = Scorer(shader, [frame], job.get("mitsuba_variant", "llvm_ad_rgb"))(0, cal.fitted)
    out = {
        "flip": score.flip,
        "rmse": score.rmse,
        "fit_seconds": fit_s,
        "fit_iterations": cal.fit_summary.get("iterations", 0),
        "water_pixels": int(score.mask.sum()),
        "n_fitted": len(fitted_names),
        "aic": ic["aic"],
        "bic": ic["bic"],
        **score.per_pixel(),
    }
    if job["kind"] != "converged":  # the error floor is not a candidate: its frame time is moot
        out.update(frame_times(job["variant"], frame.inputs, cal.fitted, exp.tradeoff.gl_repeats))
        out.update(point_maps(score))
    out["fitted"] = cal.fitted.to_dict()
    out["status_of"] = {n: p["status"] for n, p in cal.parameters.items()}
    return out


# what a full point's row holds, part of its job (rows of an earlier version are measured
# again): 2, the per-pixel FLIP and fetch maps at the experiment's resolution
POINT_VERSION = 2


def point_maps(score) -> dict:
    """A ``Score``'s per-pixel FLIP and texture-fetch maps as a row keeps them (``flip_map``,
    ``fetch_map``: :func:`pack_map` bytes of ``map_shape`` (H, W), NaN off the scored water);
    {} for a shader without a fetch count. The level-of-detail policies
    (``study.studies.lod``) are chosen from them."""
    maps, m = score.diagnostics.maps, score.mask
    if "fetches" not in maps:
        return {}
    return {
        "flip_map": pack_map(np.where(m, score.flip_map, np.nan)),
        "fetch_map": pack_map(np.where(m, maps["fetches"], np.nan)),
        "map_shape": list(m.shape),
    }


SCREEN_BLOCK = 4  # pixels per side of the blocks the screen's FLIP map is averaged over
# what a screen row holds, part of its job (a table of an earlier version is screened again,
# while the points measured in full are kept): 2, the per-pixel FLIP and fetch maps
SCREEN_VERSION = 2


def screen_job(job: dict) -> dict:
    """One cheap point of the adaptive search: the continuous constants fitted from
    ``job["start"]`` at ``job["schedule"]`` at the screen resolution (``fit.resolution`` /
    ``job["factor"]``) without the basin scan, scored there against the box-downsampled
    reference. Returns FLIP and
    RMSE on the water pixels, texture fetches and loop iterations per water pixel, the share
    of rays not crossing the floor, ``flip_blocks`` (the FLIP map averaged over
    ``SCREEN_BLOCK`` x ``SCREEN_BLOCK`` pixel blocks, row-major, NaN where a block has no
    water: the paired noise estimate of ``study.studies.search``), the per-pixel FLIP and
    texture-fetch maps (``flip_map``, ``fetch_map``: :func:`pack_map` bytes of
    ``map_shape`` (H, W), NaN off the water; the level-of-detail policies of
    ``study.studies.lod`` are chosen from them) and the fitted constants."""

    exp, _, _ = load_scene(job["scene"], job.get("mitsuba_variant", "llvm_ad_rgb"))
    w, h = exp.fit.resolution
    f = int(job["factor"])
    if w % f or h % f:
        raise ValueError(f"fit.resolution {w}x{h} is not divisible by the screen factor {f}")
    # the screen ranks candidates: its fits skip the basin scan (which doubles a point's cost
    # and serves the exported constants), shade one sample a pixel (the footprint's samples
    # multiply a fit's cost) and stop at the squared error's solution (FLIP from there triples
    # it); the points it sends on are fitted with all three
    _, _, fit, fit_s = job_fit(job, resolution=(w // f, h // f), screen=True)
    model, cal = fit.models[0], fit.calibration
    img, diag = model.render(cal.fitted)
    m = model.mask
    fmap = np.where(m, flip_map(model.reference, img), np.nan)
    out = {
        "flip": float(np.nanmean(fmap)),
        "rmse": rmse(model.reference, img, m),
        "fit_seconds": fit_s,
        "water_pixels": int(m.sum()),
        "flip_blocks": block_means(fmap, SCREEN_BLOCK).ravel().tolist(),
    }
    for k in ("fetches", "iterations"):
        if k in diag.maps:
            out[f"{k}_mean"] = float(diag.maps[k][m].mean())
    if "fetches" in diag.maps:
        out["flip_map"] = pack_map(fmap)
        out["fetch_map"] = pack_map(np.where(m, diag.maps["fetches"], np.nan))
        out["map_shape"] = list(fmap.shape)
    if "crossed" in diag.maps:
        out["not_crossed"] = float(1.0 - diag.maps["crossed"][m].mean())
    out["fitted"] = cal.fitted.to_dict()
    return out


def pack_map(values: np.ndarray) -> bytes:
    """A per-pixel map (H, W) as little-endian float16 bytes, row-major (FLIP in [0, 1] keeps
    three significant digits, a fetch count is exact up to 2048; NaN stays NaN)."""
    return np.asarray(values, "<f2").tobytes()


def unpack_map(data: bytes, shape) -> np.ndarray:
    """:func:`pack_map`'s bytes back as a (H, W) float32 array."""
    return np.frombuffer(data, "<f2").reshape(tuple(int(n) for n in shape)).astype(np.float32)


def block_means(values: np.ndarray, block: int) -> np.ndarray:
    """(H // block, W // block) means of the finite entries of ``values`` (H, W) over
    ``block`` x ``block`` blocks; NaN where a block has none."""
    h, w = values.shape[0] // block * block, values.shape[1] // block * block
    v = values[:h, :w].reshape(h // block, block, w // block, block)
    finite = np.isfinite(v)
    n = finite.sum(axis=(1, 3))
    total = np.where(finite, v, 0.0).sum(axis=(1, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, total / np.maximum(n, 1), np.nan)


def frame_times(variant_name: str, inputs, constants, repeats: int) -> dict:
    """GL frame times (ms) of the variant at each ``GL_SIZES`` beside the fixed reference shader
    (run before and after it), their ratio, and the port's frame time at 512x512."""
    variant = get_variant(variant_name)
    return timed_frames(
        lambda frame: variant.gl_renderer(frame),
        constants,
        lambda frame: variant.render(frame, constants),
        inputs,
        repeats,
    )


def timed_frames(gl_renderer, constants, render, inputs, repeats: int) -> dict:
    """What :func:`frame_times` measures, of any shader: ``gl_renderer(inputs)`` a
    ``GLRenderer`` drawing it with ``constants`` (None: its source as written), ``render(inputs)``
    its Dr.Jit render (a ``ShaderOutput``)."""
    refv = get_variant(REFERENCE_SHADER)
    out = {}
    for label, (w, h) in GL_SIZES.items():
        frame = inputs.with_resolution(w, h)
        with refv.gl_renderer(frame) as ref, gl_renderer(frame) as shader:
            ref_s, shader_s = alternate_frames([(ref, Constants()), (shader, constants)], repeats)
        out[f"gl_ms_{label}"] = 1e3 * statistics.median(shader_s)
        out[f"gl_ref_ms_{label}"] = 1e3 * statistics.median(ref_s)
        out[f"gl_ratio_{label}"] = out[f"gl_ms_{label}"] / out[f"gl_ref_ms_{label}"]
    frame = inputs.with_resolution(512, 512)
    render(frame)  # compile / record the kernels
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        render(frame).numpy()
        times.append(time.perf_counter() - t0)
    out["port_ms_512"] = 1e3 * statistics.median(times)
    return out
