"""``study tradeoff`` on an animated experiment (``animation.frames`` > 1): every point measured in
full is scored on every frame and on the temporal error, and the report says whether motion
changes the recommendation.

The search and the full points run on frame 0 (the still experiment: the constants are fitted
there, as on any still scene). Then, for each point measured in full (the converged raymarch
included), :func:`motion_job` renders its constants on every frame at ``resolution`` against
that frame's reference (``study.scene.frame_data``: references and inputs cached per frame,
built once by :func:`prepare_frames_job` before the points run) and measures:

* FLIP per frame, their mean (``flip_frames_mean``) and spread (``flip_frames_spread``, the
  standard deviation over frames);
* the temporal error of ``study._metrics.temporal_errors`` on the pixels that are water in every
  frame: ``trmse`` (RMS of the shader's frame-to-frame change minus the reference's),
  ``trmse_excess`` (beyond the reference's own noise), ``change_ratio``, and the per-pair mean
  squares ``pair_ms`` that paired comparisons take their standard error from.

:func:`motion_findings` then ranks the points on motion: the recommendation by the same rule on
the error over time (the cheapest point whose mean FLIP over the frames and whose temporal RMSE
are both within the tolerance of the best), against the still recommendation; and for every
point with a raymarch, its temporal error against the same constants rendered with the raymarch
converged (``tradeoff.converged_scale`` times the original's schedule: the same shader without
step artefacts), paired over the frame pairs: a schedule whose temporal error exceeds that by
more than ``tradeoff.noise_z`` standard errors and by more than the tolerance *bands in motion*.
"""

from __future__ import annotations

import functools
import json
import math

import numpy as np

from shaders_port.variants import get_variant

from .._metrics import temporal_errors
from ..calibration.frames import Frame
from ..calibration.scoring import Scorer
from ..calibration.shader import Shader
from ..config.experiment import load_experiment
from ..scene.frame_data import load_frames
from ..scene.frames import is_animated
from ..sweep import run_sweep, scene_spec
from .tradeoff_analysis import COST, config_label, constants_of, point_record
from .tradeoff_jobs import scaled_schedule

MOTION = "animation.frames"


def still_overrides(overrides) -> list[str]:
    """``overrides`` with frame 0 as a still experiment (``animation.frames = 1``)."""
    return [*(overrides or []), f"{MOTION}=1"]


def prepare_frames_job(job: dict) -> dict:
    """Render (or find cached) every frame's reference and shader inputs of the animated
    ``job["scene"]``, and each frame's extra buffers for the shaders of ``job["variants"]``;
    returns the frame count and the stage seconds of ``load_frames``."""
    mv = job.get("mitsuba_variant", "llvm_ad_rgb")
    _, data = _frames(json.dumps(job["scene"], sort_keys=True), mv)
    for v in job["variants"]:
        for e, base in zip(data["frames"], data["base"]):
            Shader.of_table(e, v).with_inputs(e, base, mv)
    return {"frames": len(data["frames"]), **data["timings"]}


@functools.lru_cache(maxsize=1)
def _frames(text: str, mv: str):
    spec = json.loads(text)
    exp = load_experiment(spec["experiment"], spec.get("overrides") or [])
    return exp, load_frames(exp, mv)


def _scored_frames(job: dict, data: dict, mv: str, schedules: tuple = (None,)) -> list:
    """The point's constants scored on every frame at the experiment's resolution, once per
    entry of ``schedules`` (None: its own schedule; else a schedule in place of it; a user's
    shader has none of the study's and keeps its own): [[``Score`` per frame] per schedule]."""
    out = [[] for _ in schedules]
    for e, base, ref in zip(data["frames"], data["base"], data["refs"]):
        shader = Shader.of_table(e, job["variant"])
        score = Scorer(shader, [Frame.of(e, ref, shader.with_inputs(e, base, mv))], mv)
        for per, sched in zip(out, schedules):
            per.append(score(0, shader.constants(job["constants"], sched)))
    return out


def motion_job(job: dict) -> dict:
    """One point on every frame (module doc): ``job`` has the animated ``scene``, the
    ``variant`` and its fitted ``constants``. Returns flat figures and per-frame lists."""
    mv = job.get("mitsuba_variant", "llvm_ad_rgb")
    _, data = _frames(json.dumps(job["scene"], sort_keys=True), mv)
    refs = data["refs"]
    conv_schedule = job.get("converged_schedule")  # the same constants, the raymarch converged
    schedules = (None, conv_schedule) if conv_schedule else (None,)
    scores = _scored_frames(job, data, mv, schedules)
    images = [s.image for s in scores[0]]
    flips = np.array([s.flip for s in scores[0]])
    mask = np.logical_and.reduce([s.mask for s in scores[0]])
    t = temporal_errors(
        [r.image for r in refs], images, mask, [r.stderr for r in refs], [r.passes for r in refs]
    )
    out = {
        "frames": len(refs),
        "flip_frames": flips.tolist(),
        "flip_frames_mean": float(flips.mean()),
        "flip_frames_spread": float(flips.std(ddof=1)),
        "trmse": t["trmse"],
        "trmse_excess": t.get("trmse_excess"),
        "noise": t.get("noise"),
        "change_ratio": t["change_ratio"],
        "shader_change": t["shader_change"],
        "reference_change_excess": t.get("reference_change_excess"),
        "pair_ms": [p * p for p in t["per_pair"]],
        "mask_pixels": int(mask.sum()),
    }
    if conv_schedule:
        c = temporal_errors([r.image for r in refs], [s.image for s in scores[1]], mask)
        out["converged_trmse"] = c["trmse"]
        out["converged_pair_ms"] = [p * p for p in c["per_pair"]]  # on the same pixels
    return out


def paired(a: list, b: list) -> tuple[float, float]:
    """Mean and standard error of the per-pair differences ``a - b`` (mean squares of the same
    frame pairs); the standard error is inf with fewer than two pairs."""
    d = np.asarray(a, np.float64) - np.asarray(b, np.float64)
    if d.size < 2:
        return float(d.mean()) if d.size else math.nan, math.inf
    return float(d.mean()), float(d.std(ddof=1) / math.sqrt(d.size))


def _banding(pts: list, z: float, tolerance: float) -> list[dict]:
    """Each raymarch schedule's temporal error against the same constants with the raymarch
    converged (``converged_schedule`` of :func:`motion_job`), paired over the frame pairs:
    ``d_ms`` +- ``se_ms`` (mean squares), ``rel`` (its temporal RMSE over the converged one's,
    minus 1) and ``bands``: larger by more than ``z`` standard errors *and* by more than
    ``tolerance`` (relative; a difference the paired test detects but no one would see does not
    band)."""
    out = []
    for r in sorted(pts, key=lambda r: (r["variant"], r.get(COST) or 0.0)):
        if not r.get("converged_pair_ms"):
            continue
        mine, conv = r["pair_ms"], r["converged_pair_ms"]
        d, se = paired(mine, conv)
        rel = math.sqrt(float(np.mean(mine)) / float(np.mean(conv))) - 1.0
        out.append(
            {
                "label": r["label"],
                "variant": r["variant"],
                COST: r.get(COST),
                "trmse": r["trmse"],
                "floor_trmse": r["converged_trmse"],
                "d_ms": d,
                "se_ms": se if math.isfinite(se) else None,  # None: one frame pair
                "rel": rel,
                "bands": bool(d > 0 and d > z * se and rel > tolerance),
            }
        )
    return out


def motion_findings(pts: list, still_rec: dict | None, tolerance: float, z: float) -> dict:
    """What motion says of one scene's points (records with ``label``, ``variant``, ``kind``,
    the cost and the :func:`motion_job` figures): ``points`` (each, cheapest first),
    ``recommended`` (module doc), ``still`` (the still recommendation's label), ``changes``
    (whether they differ), ``banding`` (:func:`_banding`) and ``why`` (a sentence)."""
    keys = ("label", "variant", "kind", COST, "flip", "flip_frames_mean", "flip_frames_spread",
            "trmse", "trmse_excess", "change_ratio", "noise")  # fmt: skip
    scored = [r for r in pts if r.get("trmse") is not None]
    cands = [r for r in scored if r["kind"] != "converged" and r.get(COST) is not None]
    rec = None
    if cands:
        best_f = min(r["flip_frames_mean"] for r in cands)
        best_t = min(r["trmse"] for r in cands)
        within = [r for r in cands if r["flip_frames_mean"] <= best_f * (1 + tolerance)
                  and r["trmse"] <= best_t * (1 + tolerance)]  # fmt: skip
        rec = min(within, key=lambda r: (r[COST], r["flip_frames_mean"]), default=None)
    banding = _banding(scored, z, tolerance)
    still = still_rec["label"] if still_rec else None
    changes = rec is not None and still is not None and rec["label"] != still
    bands = [b for b in banding if b["bands"]]
    if rec is None:
        why = "no point was scored on every frame"
    elif not changes:
        why = "motion does not change the recommendation"
    else:
        s = next(r for r in cands if r["label"] == still) if any(
            r["label"] == still for r in cands) else None  # fmt: skip
        why = (
            f"motion changes the recommendation: {still} has mean FLIP "
            f"{s['flip_frames_mean']:.4f} and temporal RMSE {s['trmse']:.5f} over the frames, "
            f"{rec['label']} {rec['flip_frames_mean']:.4f} and {rec['trmse']:.5f}"
            if s
            else f"motion changes the recommendation to {rec['label']}"
        )
    return {
        "points": [
            {k: r.get(k) for k in keys}
            for r in sorted(scored, key=lambda r: (r.get(COST) is None, r.get(COST) or 0.0))
        ],  # fmt: skip
        "recommended": {k: rec.get(k) for k in keys} if rec else None,
        "still": still,
        "changes": changes,
        "banding": banding,
        "bands": [b["label"] for b in bands],
        "why": why,
        "frames": scored[0]["frames"] if scored else None,
    }


def _converged(exp, row: dict) -> dict | None:
    """The converged raymarch's schedule (``tradeoff.converged_scale`` times the original's) for
    a full point of a shader with a raymarch; None for a point without a schedule of the study's
    (``kind`` fixed: a loopless shader, a user's shader) and the converged point itself."""

    v = row["job.variant"]
    if row["job.kind"] in ("converged", "fixed"):  # no schedule: a loopless or user's shader
        return None
    return scaled_schedule(get_variant(v), exp.tradeoff.converged_scale)


def run_motion(exps, experiments, overrides, rows, recs, summary, client, out, log) -> None:
    """The motion rung of ``run_tradeoff`` for each animated experiment (module doc): its
    frames prepared, every successful full point scored on them (``motion.parquet``), and
    ``summary["scenes"][name]["motion"]`` (:func:`motion_findings`) and ``summary["motion"]``
    (frames, seconds) set. Nothing for still experiments."""
    import time

    animated = [(e, scene_spec(p, overrides)) for e, p in zip(exps, experiments) if is_animated(e)]
    if not animated:
        return
    t0 = time.perf_counter()
    ok = [r for r in rows if r["status"] == "ok"]
    prep = [{"scene": spec, "variants": sorted({r["job.variant"] for r in ok
             if r["job.experiment"] == e.name})} for e, spec in animated]  # fmt: skip
    log(f"tradeoff: motion: the frames of {len(prep)} animated scene(s)")
    run_sweep(prepare_frames_job, prep, out / "frames.parquet", client=client,
              label="tradeoff: frames", log=log)  # fmt: skip
    jobs = [
        {"scene": spec, "experiment": e.name, "variant": r["job.variant"],
         "kind": r["job.kind"], "label": config_label(point_record(r)),
         "constants": constants_of(r), "converged_schedule": _converged(e, r)}
        for e, spec in animated for r in ok if r["job.experiment"] == e.name
    ]  # fmt: skip
    mrows = run_sweep(motion_job, jobs, out / "motion.parquet", client=client,
                      label="tradeoff: motion", log=log)[: len(jobs)]  # fmt: skip
    by = {(m["job.experiment"], m["job.label"], m["job.kind"]): m for m in mrows
          if m["status"] == "ok"}  # fmt: skip
    fields = ("frames", "flip_frames", "flip_frames_mean", "flip_frames_spread", "trmse",
              "trmse_excess", "noise", "change_ratio", "pair_ms", "converged_trmse",
              "converged_pair_ms")  # fmt: skip
    for e, _ in animated:
        pts = []
        for r in recs:
            m = by.get((r["experiment"], r["label"], r["kind"]))
            if r["experiment"] == e.name and m is not None:
                pts.append({**r, **{k: m.get(k) for k in fields}})
        scene = summary["scenes"][e.name]
        scene["motion"] = motion_findings(
            pts, scene["recommended"], summary["tolerance"], e.tradeoff.noise_z
        )
        log(f"tradeoff: {e.name} in motion ({e.animation.frames} frames): "
            f"{scene['motion']['why']}")  # fmt: skip
    failed = [m for m in mrows if m["status"] != "ok"]
    for m in failed:
        log(f"tradeoff: motion of {m['job.label']} on {m['job.experiment']} failed: {m['error']}")
    summary["motion"] = {
        "seconds": time.perf_counter() - t0,
        "points": len(mrows),
        "failed": [f"{m['job.label']}: {m.get('error')}" for m in failed],
    }
