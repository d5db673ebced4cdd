"""``study tradeoff``: which shader variant and step schedule for a frame budget, and what each
costs in error, over one or several experiments.

:func:`run_tradeoff` plans the jobs (``tradeoff_jobs``), runs them on the sweep engine in two
phases (anchors, then points warm-started from them), and analyses the table:

* a Pareto front of error (FLIP on water pixels) against each cost measure, per scene, and a
  joint front on the error averaged over the scenes (configurations measured on every scene);
* the recommendation: the cheapest configuration (mean texture fetches per water pixel, the
  machine-independent cost) whose FLIP is within ``tolerance`` of the best; per scene its
  constants are exported like ``study calibrate`` exports (compile-checked, GL-checked);
* the best configuration at no more fetches per pixel than the seed's (``water_refraction`` at
  the seed's schedule), the budget a game replacing the seed's shader already pays;
* what the scene needs: the simplest variant within tolerance (variants counted simplest first,
  in the order of ``tradeoff.variants``), what the sky reflection and the reflection raycast add,
  the smallest loop cap at which rays cross the floor, the error floor of each variant (its
  converged raymarch), and what each halving of the seed's schedule costs.

Outputs in ``out``: ``tradeoff.parquet`` (a row per point), ``anchors.parquet``, ``pareto.png``,
``images_<scene>.png`` (the reference beside the seed shader with the seed's constants, fitted,
the best configuration within the seed's fetch budget and the recommendation), ``report.md``,
``summary.json``, ``shaders/`` (one experiment) or ``shaders/<name>/`` (several).
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path

from .pareto import pareto_front, recommend
from .tradeoff_jobs import SEED_SCHEDULE, anchor_job, point_job, schedules

COST = "fetches_mean"
COSTS = {
    "fetches_mean": "texture fetches / water pixel (mean)",
    "gl_norm_ms_1080p": "llvmpipe ms / frame at 1920x1080 (normalised)",
    "port_ms_512": "Dr.Jit LLVM port ms / frame at 512x512",
}
ERROR = "flip"
# [tradeoff] keys that choose the jobs, never what one job computes
PLAN_KEYS = frozenset(
    {
        "tradeoff.variants",
        "tradeoff.steps_grazing",
        "tradeoff.steps_steep",
        "tradeoff.loop_cap",
        "tradeoff.scales",
        "tradeoff.converged_scale",
        "tradeoff.tolerance",
    }
)


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _constants_of(row: dict) -> dict:
    return {
        k[len("fitted.") :]: v for k, v in row.items() if k.startswith("fitted.") and v is not None
    }


def plan_points(exps, specs, anchors: dict) -> list[dict]:
    """Phase-2 jobs: every schedule of every variant of every experiment, started from the
    anchor's constants (``anchors[(scene index, variant)]``)."""
    jobs = []
    for i, (exp, spec) in enumerate(zip(exps, specs)):
        for v in exp["tradeoff.variants"]:
            for s in schedules(exp, v):
                jobs.append(
                    {
                        "scene": spec,
                        "experiment": exp["name"],
                        "variant": v,
                        "kind": s["kind"],
                        "scale": s["scale"],
                        "schedule": s["schedule"],
                        "start": anchors[(i, v)],
                    }
                )
    return jobs


def run_tradeoff(
    experiments: list,
    out,
    overrides=None,
    scheduler=None,
    workers=None,
    tolerance: float | None = None,
    variant: str = "llvm_ad_rgb",
    log=_log,
) -> dict:
    """Run the study (see the module doc); returns the summary written to ``summary.json``."""
    from .._io import write_json
    from ..fit.model import constants_from_experiment
    from ..scene.experiment import load_experiments
    from ..sweep import run_sweep, scene_spec
    from ..sweep.cluster import open_client

    exps = load_experiments(experiments, overrides)
    names = [e["name"] for e in exps]
    tol = exps[0]["tradeoff.tolerance"] if tolerance is None else float(tolerance)
    if tol < 0:
        raise ValueError(f"--tolerance must be >= 0, got {tol}")
    # the jobs' scenes leave out the keys that only shape the plan (which variants and schedules),
    # so that widening the plan resumes every point already measured
    specs = [
        scene_spec(p, [o for o in overrides or [] if o.split("=", 1)[0].strip() not in PLAN_KEYS])
        for p in experiments
    ]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    anchor_jobs = [
        {
            "scene": spec,
            "experiment": exp["name"],
            "variant": v,
            "start": constants_from_experiment(exp).replace(**SEED_SCHEDULE).to_dict(),
        }
        for exp, spec in zip(exps, specs)
        for v in exp["tradeoff.variants"]
    ]
    with open_client(scheduler, workers, variant, log=log) as client:
        arows = run_sweep(
            anchor_job,
            anchor_jobs,
            out / "anchors.parquet",
            client=client,
            label="tradeoff: anchor fits",
            log=log,
        )
        anchors = {}
        for job, row in zip(anchor_jobs, arows):
            i = names.index(job["experiment"])
            if row["status"] == "ok":
                anchors[(i, job["variant"])] = {**job["start"], **_constants_of(row)}
            else:
                log(
                    f"tradeoff: anchor fit of {job['variant']} on {job['experiment']} failed "
                    f"({row['error']}); its points start from the experiment's constants"
                )
                anchors[(i, job["variant"])] = job["start"]
        points = plan_points(exps, specs, anchors)
        # rows of this plan only (a table written by an earlier plan keeps its other rows)
        rows = run_sweep(
            point_job,
            points,
            out / "tradeoff.parquet",
            client=client,
            label="tradeoff: points",
            log=log,
        )[: len(points)]
    summary, recs = analyse(rows, names, tol)
    summary["experiments"] = [str(p) for p in experiments]
    summary["exports"] = export_recommended(exps, specs, summary, rows, out, variant, log)
    summary["images"] = side_by_side(exps, specs, summary, rows, out, variant)
    from ..report.tradeoff import pareto_figure, write_tradeoff_report

    pareto_figure(out / "pareto.png", recs, summary)
    write_tradeoff_report(out, summary)
    write_json(out / "summary.json", summary)
    log(f"tradeoff: {summary['n_points']} points ({summary['n_failed']} failed); wrote {out}")
    return summary


# ---- analysis ------------------------------------------------------------------------------


def point_record(row: dict) -> dict:
    """The figures of one table row the analysis uses (flat dict)."""
    rec = {
        "experiment": row.get("job.experiment"),
        "variant": row.get("job.variant"),
        "kind": row.get("job.kind"),
        "scale": row.get("job.scale"),
        "schedule": {
            k[len("job.schedule.") :]: row[k]
            for k in row
            if k.startswith("job.schedule.") and row[k] is not None
        },
        "status": row.get("status"),
        "error_message": row.get("error"),
    }
    for k in (
        "flip",
        "rmse",
        "fetches_mean",
        "fetches_p99",
        "iterations_mean",
        "iterations_p99",
        "not_crossed",
        "n_fitted",
        "bic",
        "gl_ms_512",
        "gl_ms_1080p",
        "gl_ratio_512",
        "gl_ratio_1080p",
        "port_ms_512",
        "gl_ref_ms_1080p",
    ):
        rec[k] = row.get(k)
    return rec


def config_label(rec: dict) -> str:
    s = rec["schedule"]
    if not s:
        return rec["variant"]
    sched = f"({s['steps_grazing']:g}, {s['steps_steep']:g}, {int(s['loop_cap'])})"
    if "refl_loop_cap" in s:
        sched += f" refl ({s['refl_steps_steep']:g}, {s['refl_steps_grazing']:g}, {int(s['refl_loop_cap'])})"
    return f"{rec['variant']} {sched}"


def _is_seed(rec: dict) -> bool:
    return rec["kind"] == "scale" and rec["scale"] == 1.0


def analyse(rows: list, names: list, tolerance: float) -> tuple[dict, list]:
    """Fronts, recommendations and findings of a finished sweep (see the module doc): the summary
    and the successful points (records with ``label`` and the normalised GL cost)."""
    recs = [point_record(r) for r in rows if r.get("job.experiment") in names]
    ok = [r for r in recs if r["status"] == "ok" and r["flip"] is not None]
    ref_ms = [r["gl_ref_ms_1080p"] for r in ok if r.get("gl_ref_ms_1080p")]
    norm = statistics.median(ref_ms) if ref_ms else None
    for r in ok:
        r["gl_norm_ms_1080p"] = (
            r["gl_ratio_1080p"] * norm if norm and r.get("gl_ratio_1080p") else None
        )
        r["label"] = config_label(r)
    scenes = {}
    for name in names:
        pts = [r for r in ok if r["experiment"] == name and r["kind"] != "converged"]
        scenes[name] = scene_findings(pts, [r for r in ok if r["experiment"] == name], tolerance)
    joint = joint_points(ok, names)
    summary = {
        "tolerance": tolerance,
        "cost": COST,
        "error": ERROR,
        "n_points": len(recs),
        "n_failed": sum(r["status"] != "ok" for r in recs),
        "gl_reference_ms_1080p": norm,
        "failures": [
            {k: r[k] for k in ("experiment", "variant", "kind", "error_message")}
            | {"schedule": r["schedule"]}
            for r in recs
            if r["status"] != "ok"
        ],
        "scenes": scenes,
    }
    if len(names) > 1:
        summary["joint"] = {
            "front": pareto_front(joint, COST, ERROR),
            "recommended": recommend(joint, COST, ERROR, tolerance),
        }
    return summary, ok


def joint_points(ok: list, names: list) -> list:
    """Configurations measured on every scene, with error and costs averaged over the scenes."""
    by = {}
    for r in ok:
        if r["kind"] != "converged":
            by.setdefault(r["label"], []).append(r)
    out = []
    for label, rs in by.items():
        if sorted(r["experiment"] for r in rs) != sorted(names):
            continue
        j = {
            "label": label,
            "variant": rs[0]["variant"],
            "schedule": rs[0]["schedule"],
            "kind": rs[0]["kind"],
            "scale": rs[0]["scale"],
        }
        for k in ("flip", "rmse", *COSTS):
            vals = [r.get(k) for r in rs]
            j[k] = statistics.mean(vals) if all(v is not None for v in vals) else None
        out.append(j)
    return out


def scene_findings(pts: list, all_pts: list, tolerance: float) -> dict:
    """Front, recommendation and what-the-scene-needs findings for one scene's points."""

    def brief(r):
        return (
            None
            if r is None
            else {
                k: r.get(k)
                for k in (
                    "label",
                    "variant",
                    "schedule",
                    "kind",
                    "scale",
                    "flip",
                    "rmse",
                    *COSTS,
                    "fetches_p99",
                    "gl_ms_1080p",
                    "not_crossed",
                )
            }
        )

    rec = recommend(pts, COST, ERROR, tolerance)
    seed = [r for r in pts if _is_seed(r) and r["variant"] == "water_refraction"]
    variants = list(dict.fromkeys(r["variant"] for r in all_pts))
    best_by_variant = {
        v: min((r["flip"] for r in pts if r["variant"] == v), default=None) for v in variants
    }
    best = min((x for x in best_by_variant.values() if x is not None), default=None)
    simplest = next(
        (
            v
            for v in variants
            if best_by_variant[v] is not None and best_by_variant[v] <= best * (1 + tolerance)
        ),
        None,
    )
    floor = {
        v: next(
            (r["flip"] for r in all_pts if r["variant"] == v and r["kind"] == "converged"), None
        )
        for v in variants
    }
    crossing = {}
    for v in variants:
        if not any(r["schedule"] for r in all_pts if r["variant"] == v):
            crossing[v] = "no raymarch"  # a loopless shader (the baselines)
            continue
        caps = sorted(
            {
                int(r["schedule"]["loop_cap"])
                for r in pts
                if r["variant"] == v
                and r["schedule"]
                and r.get("not_crossed") is not None
                and r["not_crossed"] < 0.01
            }
        )
        crossing[v] = caps[0] if caps else None
    halvings = sorted(
        (r for r in pts if r["kind"] == "scale"), key=lambda r: (r["variant"], r["scale"])
    )
    # parsimony: constants and BIC per variant at its seed's schedule (same reference, mask and
    # resolution within a scene, so BIC differences compare)
    at_seed = {r["variant"]: r for r in pts if (_is_seed(r) or r["kind"] == "fixed")}
    parsimony = {
        v: {"n_fitted": r.get("n_fitted"), "bic": r.get("bic"), "flip": r["flip"]}
        for v, r in at_seed.items()
    }
    budget = seed[0][COST] * (1 + 1e-3) if seed and seed[0].get(COST) is not None else None
    within = [
        r for r in pts if budget is not None and r.get(COST) is not None and r[COST] <= budget
    ]
    best_within = min(within, key=lambda r: r[ERROR], default=None)
    return {
        "front": [brief(r) for r in pareto_front(pts, COST, ERROR)],
        "fronts_by_cost": {c: [r["label"] for r in pareto_front(pts, c, ERROR)] for c in COSTS},
        "recommended": brief(rec),
        "seed": brief(seed[0]) if seed else None,
        "best_within_seed_budget": brief(best_within),
        "parsimony": parsimony,
        "best_flip_by_variant": best_by_variant,
        "simplest_variant_within_tolerance": simplest,
        "error_floor_by_variant": floor,
        "smallest_crossing_loop_cap": crossing,
        "halvings": [brief(r) for r in halvings],
    }


def export_recommended(
    exps, specs, summary: dict, rows: list, out: Path, variant: str, log
) -> dict:
    """Export each scene's recommended constants (``shaders/`` or ``shaders/<name>/``) and check
    the export on llvmpipe against the port."""
    from shaders_port import Constants

    from .._backend import init_backend
    from ..report.export import export_shaders
    from ..report.gl_check import gl_check, target_checks
    from ..sweep import load_scene

    init_backend(variant)
    result = {}
    for exp, spec in zip(exps, specs):
        rec = summary["scenes"][exp["name"]]["recommended"]
        if rec is None:
            log(f"tradeoff: no successful point on {exp['name']}; nothing exported")
            continue
        row = next(
            r
            for r in rows
            if r.get("job.experiment") == exp["name"]
            and r["status"] == "ok"
            and config_label(point_record(r)) == rec["label"]
            and r.get("job.kind") != "converged"
        )
        constants = Constants.from_dict(_constants_of(row))
        folder = out / "shaders" if len(exps) == 1 else out / "shaders" / exp["name"]
        export_shaders(constants, folder, [rec["variant"]], targets=None)
        from ..scene.baseline_inputs import inputs_for_shader

        exp_s, _, inputs = load_scene(spec, variant)
        inputs = inputs_for_shader(exp_s, inputs, rec["variant"], variant, log=log)
        gl = gl_check(rec["variant"], inputs, constants, folder)
        result[exp["name"]] = {
            "folder": str(folder),
            "variant": rec["variant"],
            "label": rec["label"],
            "constants": constants.to_dict(),
            "gl_check": gl,
            "engine_targets": target_checks(rec["variant"], inputs, constants, folder),
        }
        log(
            f"tradeoff: {exp['name']}: exported {rec['label']} to {folder} (GL check "
            f"{'passed' if gl['passed'] else 'FAILED'})"
        )
    return result


def _point_row(rows: list, scene: str, label: str) -> dict:
    return next(
        r
        for r in rows
        if r.get("job.experiment") == scene
        and r["status"] == "ok"
        and config_label(point_record(r)) == label
        and r.get("job.kind") != "converged"
    )


def side_by_side(exps, specs, summary: dict, rows: list, out: Path, variant: str) -> dict:
    """Per scene, ``images_<scene>.png``: the reference | the seed shader with the experiment's
    constants at the seed's schedule | the seed's configuration refitted | the best configuration
    within the seed's fetch budget | the recommendation (duplicates left out), each at the
    experiment's resolution with its FLIP and RMSE on the water pixels. Returns {scene: file name}."""
    from shaders_port import Constants

    from .._metrics import errors
    from ..fit.model import constants_from_experiment
    from ..report.calibration import comparison_figure
    from .tradeoff_jobs import job_model

    result = {}
    for exp, spec in zip(exps, specs):
        f = summary["scenes"][exp["name"]]
        panels = [
            (
                "seed shader, seed constants",
                "water_refraction",
                constants_from_experiment(exp).replace(**SEED_SCHEDULE),
            )
        ]
        for title, key in (
            ("seed shader, fitted", "seed"),
            ("best within the seed's fetches", "best_within_seed_budget"),
            ("recommended", "recommended"),
        ):
            r = f.get(key)
            if r and r["label"] not in [p[0].split(": ", 1)[-1] for p in panels]:
                row = _point_row(rows, exp["name"], r["label"])
                panels.append(
                    (
                        f"{title}: {r['label']}",
                        r["variant"],
                        Constants.from_dict(_constants_of(row)),
                    )
                )
        images, errs, mask = {}, {}, None
        for title, shader, constants in panels:
            _, ref, _, model = job_model(
                {"scene": spec, "variant": shader, "mitsuba_variant": variant},
                resolution=tuple(exp["resolution"]),
            )
            images.setdefault("reference", ref.image)
            img, _ = model.render(constants)
            images[title] = img
            errs[title] = errors(ref.image, img, model.mask)
            mask = model.mask
        name = f"images_{exp['name']}.png"
        comparison_figure(out / name, images, errs, mask, title=exp["name"])
        result[exp["name"]] = name
    return result
