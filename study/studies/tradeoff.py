"""``study tradeoff``: which shader and step schedule for a frame budget, and what each costs in
error, over one or several experiments.

:func:`run_tradeoff` chooses the points by one of two searches on the sweep engine:

* ``adaptive`` (default): the shader space (``shaders_port.space``) screened cheaply and only the
  survivors measured in full (``study.studies.search``);
* ``exhaustive``: every shader of ``tradeoff.variants`` (unset: the space, with the axes of
  ``tradeoff.fix`` pinned) at every schedule (``tradeoff_jobs``), in two phases (anchors at the
  original schedule, then every point warm-started from them).

Then it analyses the table (``tradeoff_analysis``):

* a Pareto front of error (FLIP on water pixels) against each cost measure, per scene, and a
  joint front on the error averaged over the scenes (configurations measured on every scene);
* the recommendation: the cheapest configuration (mean texture fetches per water pixel, the
  machine-independent cost) whose FLIP is within ``tolerance`` of the best, or with a budget
  the lowest FLIP within it; per scene its constants are exported like ``study calibrate``
  exports (compile-checked, GL-checked, every engine target);
* the best configuration at no more fetches per pixel than the original's (``water_refraction``
  at its schedule), the budget a game replacing the original shader already pays;
* what the scene needs (the simplest variant within tolerance, error floors, the smallest loop
  cap at which rays cross the floor, each halving of the original schedule) and, for the
  adaptive search, what each axis's choice buys at the recommendation;
* with ``fit.shader`` a GLSL file, the user's own shader measured in full beside the search's
  points (``tradeoff_user``), on the chart and the front like them, and where it stands;
* the level-of-detail policies (``study.studies.lod``): the water in bands by distance or
  footprint, each band one point measured in full, chosen from the points' per-pixel maps at
  the experiment's resolution, the cheapest reaching the best single point's FLIP
  (``lod.png``; the adaptive search measures the bands its screen's maps choose in full too),
  drawn as one shader with its seams and its GL check (``study.studies.lod_export``);
* on an animated experiment, the search and the fits on frame 0, then every point measured in
  full scored on every frame and on the temporal error, and whether motion changes the
  recommendation (``tradeoff_motion``).

Outputs in ``out``: ``tradeoff.parquet`` (a row per point measured in full), ``screen.parquet``
(adaptive) or ``anchors.parquet`` (exhaustive), ``user.parquet`` (a user's shader),
``frames.parquet``, ``motion.parquet`` and ``motion.png`` (an animated experiment),
``pareto.png``, ``images_<scene>.png`` (the reference beside the original shader at its own
constants, fitted, the best configuration within its fetch budget, the recommendation and the
user's shader; its panels kept as data in ``images_<scene>.exr`` and ``.json``,
``study.report.panels``), ``report.md``, ``summary.json``, and the recommendation calibrated as
``study calibrate`` writes a calibration (``study.studies.tradeoff_export``): ``recommended/``
(one experiment) or ``recommended/<name>/`` (several); a user's own shader that is not the
recommendation in ``yours/`` alike; the level-of-detail policy in ``policy/`` (one experiment)
or ``policy/<name>/``.
"""

from __future__ import annotations

import time
from pathlib import Path

from shaders_port import Constants
from shaders_port.space import configurations, name_of, parse_fix

from .._backend import init_backend
from .._io import write_json
from .._progress import log as _log
from ..config.experiment import load_experiments
from ..calibration.frames import Frame
from ..calibration.scoring import Scorer
from ..calibration.shader import Shader
from ..fit.model import constants_from_experiment
from ..report.lod import lod_figure
from ..report.panels import panels_figure, write_panels
from ..report.tradeoff import ORIGINAL_PANEL, pareto_figure, write_tradeoff_report
from ..report.tradeoff_motion import motion_figure
from ..scene.animation import is_animated
from ..scene.views import has_views, view_experiments, view_overrides
from ..sweep import load_scene, run_sweep, scene_spec
from .lod import full_points, policy_bands, scene_policies
from .lod_export import export_policies
from .search import Search
from .tradeoff_analysis import COSTS, analyse, constants_of
from .tradeoff_export import export_points, point_row
from .tradeoff_jobs import POINT_VERSION, SEED_SCHEDULE, anchor_job, point_job, schedules
from .tradeoff_motion import run_motion, still_overrides
from .tradeoff_user import user_jobs, user_point_job

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
        "tradeoff.search",
        "tradeoff.fix",
        "tradeoff.lod",
        "tradeoff.max_shaders",
        "tradeoff.max_full",
        "tradeoff.max_scheduled",
        "tradeoff.screen_factor",
        "tradeoff.noise_z",
    }
)


def plan_points(exps, specs, anchors: dict, variants: list) -> list[dict]:
    """Phase-2 jobs: every schedule of every variant of every experiment, started from the
    anchor's constants (``anchors[(scene index, variant)]``)."""
    jobs = []
    for i, (exp, spec) in enumerate(zip(exps, specs)):
        for v in variants:
            for s in schedules(exp, v):
                jobs.append(
                    {
                        "scene": spec,
                        "experiment": exp.name,
                        "variant": v,
                        "kind": s["kind"],
                        "scale": s["scale"],
                        "schedule": s["schedule"],
                        "start": anchors[(i, v)],
                        "point_version": POINT_VERSION,
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
    search: str | None = None,
    budget: dict | None = None,
) -> dict:
    """Run the study (see the module doc); returns the summary written to ``summary.json``.
    ``search``: 'adaptive' or 'exhaustive' (default: ``tradeoff.search``); ``budget``: cost
    measure -> limit (``fetches_mean``, ``gl_norm_ms_1080p``): recommend the lowest FLIP
    within it."""

    # an experiment with several views (camera.views) is one scene per view: the study judges
    # its shaders on every view, as on several scenes
    views = [
        (p, v, view_overrides(e, k) if has_views(e) else [])
        for p, e in zip(experiments, load_experiments(experiments, overrides))
        for k, v in enumerate(view_experiments(e))
    ]
    experiments, exps = [p for p, _, _ in views], [v for _, v, _ in views]
    names = [e.name for e in exps]
    tol = exps[0].tradeoff.tolerance if tolerance is None else float(tolerance)
    if tol < 0:
        raise ValueError(f"--tolerance must be >= 0, got {tol}")
    budget = check_budget(budget)
    mode = search or exps[0].tradeoff.search
    if mode not in ("adaptive", "exhaustive"):
        raise ValueError(f"search must be 'adaptive' or 'exhaustive', got {mode!r}")
    fix, chosen = parse_fix(exps[0].tradeoff.fix), exps[0].tradeoff.variants
    # the jobs' scenes leave out the keys that only shape the plan (which variants and schedules),
    # so that widening the plan resumes every point already measured
    # (an animated experiment's frame 0 as a still: the search and the fits run there)
    plain = [o for o in overrides or [] if o.split("=", 1)[0].strip() not in PLAN_KEYS]
    specs = [
        scene_spec(p, (still_overrides(plain) if is_animated(e) else plain) + extra)
        for p, e, (_, _, extra) in zip(experiments, exps, views)
    ]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    # local: distributed takes 0.65 s to import, paid only when a sweep runs
    from ..sweep.cluster import open_client

    with open_client(scheduler, workers, variant, log=log) as client:
        if mode == "exhaustive":
            shaders = chosen or [name_of(c) for c in configurations(fix)]
            rows = _exhaustive(exps, specs, client, out, log, shaders)
            searcher = None
        else:
            rows, searcher = _adaptive(exps, specs, client, out, log, fix, chosen, tol)
        rows = rows + _user_points(exps, specs, client, out, log)
        summary, recs = analyse(rows, names, tol, budget)
        run_motion(exps, experiments, plain, rows, recs, summary, client, out, log)
        summary["search"] = _search_summary(mode, searcher, rows, fix, time.perf_counter() - t0)
        if searcher is not None:
            for i, name in enumerate(names):
                # a point the search did not screen (a user's shader) has no marginals
                rec = summary["scenes"][name]["recommended"]
                summary["scenes"][name]["marginals"] = searcher.marginals_of(i, rec) if rec else []
        for i, name in enumerate(names):
            if exps[i].tradeoff.lod:
                found = scene_policies(exps[i], full_points(rows, name), tol)
                summary["scenes"][name]["lod"] = found
    summary["experiments"] = [str(p) for p in experiments]
    init_backend(variant)
    summary["exports"], summary["user_exports"] = export_points(
        exps, specs, summary, rows, out, variant, log
    )
    export_policies(exps, specs, summary, out, variant, log)
    summary["images"], summary["panels"] = side_by_side(exps, specs, summary, rows, out, variant)

    pareto_figure(out / "pareto.png", recs, summary)
    lod_figure(out / "lod.png", summary)
    motion_figure(out / "motion.png", summary)
    write_tradeoff_report(out, summary)
    write_json(out / "summary.json", summary)
    log(f"tradeoff: {summary['n_points']} points ({summary['n_failed']} failed); wrote {out}")
    return summary


BUDGETS = {"fetches": "fetches_mean", "gl_ms": "gl_norm_ms_1080p"}


def check_budget(budget: dict | None) -> dict:
    """``budget`` (``fetches`` / ``gl_ms`` or the cost names they stand for -> limit) with the
    cost names of :data:`COSTS`; a ValueError names a bad entry."""
    out = {}
    for k, v in (budget or {}).items():
        cost = BUDGETS.get(k, k)
        if cost not in COSTS:
            raise ValueError(f"--budget {k}: choose one of {', '.join(BUDGETS)}")
        if not (isinstance(v, (int, float)) and v > 0 and v == v):
            raise ValueError(f"--budget {k}={v}: the limit must be a positive number")
        out[cost] = float(v)
    return out


def _exhaustive(exps, specs, client, out, log, shaders: list) -> list[dict]:
    """Every configuration of ``shaders`` and every schedule in full: anchor fits at the
    original's schedule, then every point warm-started from its anchor."""
    names = [e.name for e in exps]
    anchor_jobs = [
        {
            "scene": spec,
            "experiment": exp.name,
            "variant": v,
            "start": constants_from_experiment(exp).replace(**SEED_SCHEDULE).to_dict(),
        }
        for exp, spec in zip(exps, specs)
        for v in shaders
    ]
    log(f"tradeoff: exhaustive over {len(shaders)} shaders x {len(exps)} scenes")
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
            anchors[(i, job["variant"])] = {**job["start"], **constants_of(row)}
        else:
            log(
                f"tradeoff: anchor fit of {job['variant']} on {job['experiment']} failed "
                f"({row['error']}); its points start from the experiment's constants"
            )
            anchors[(i, job["variant"])] = job["start"]
    points = plan_points(exps, specs, anchors, shaders)
    # rows of this plan only (a table written by an earlier plan keeps its other rows)
    return run_sweep(
        point_job,
        points,
        out / "tradeoff.parquet",
        client=client,
        label="tradeoff: points",
        log=log,
    )[: len(points)]


def _adaptive(exps, specs, client, out, log, fix: dict, chosen, tol: float):
    """The adaptive search (``study.studies.search``): walk, schedules, the joint rung, then
    the finalists in full (with the bands of the screen's level-of-detail policy at tolerance
    ``tol``). Returns (the full rung's rows, the ``Search``)."""
    searcher = Search(exps, specs, client, out, log, fix=fix, variants=chosen)
    finalists = []
    for i in range(len(exps)):
        front = searcher.walk(i)
        finalists += searcher.schedules(i, front)
        # the original shader and each source's technique alone at its own schedule: what
        # every finding compares with
        finalists += searcher.alone(i)
        # the configurations of the screen's level-of-detail policy, so that the full rung can
        # choose bands among them
        if exps[i].tradeoff.lod:
            finalists += policy_bands(exps[i], searcher.ok(i), tol)
    # several experiments: the shaders good on all of them, each at its schedules on every one
    finalists += searcher.joint(finalists)
    jobs = searcher.full_jobs(finalists)
    log(
        f"tradeoff: {len(searcher.screen)} screen points, {len(jobs)} measured in full "
        f"({len(finalists)} survivors)"
    )
    rows = run_sweep(
        point_job, jobs, out / "tradeoff.parquet", client=client, label="tradeoff: full", log=log
    )[: len(jobs)]
    return rows, searcher


def _user_points(exps, specs, client, out: Path, log) -> list[dict]:
    """The user's own shader of each experiment that has one, measured in full
    (``tradeoff_user``); no rows when none has."""
    jobs = user_jobs(exps, specs)
    if not jobs:
        return []
    log(f"tradeoff: your shader, fitted and measured on {len(jobs)} scene(s)")
    return run_sweep(
        user_point_job, jobs, out / "user.parquet", client=client, label="tradeoff: your shader",
        log=log,
    )[: len(jobs)]  # fmt: skip


def _search_summary(mode: str, searcher, rows: list, fix: dict, seconds: float) -> dict:
    out = {"mode": mode, "fix": fix, "points_in_full": len(rows), "seconds": seconds}
    if searcher is not None:
        out["screened"] = len(searcher.screen)
        out["shaders_screened"] = len({r["variant"] for r in searcher.screen})
        out["rounds"] = searcher.rounds
        out["descents"] = searcher.descents
        out["joint_screened"] = searcher.joint_screened
    return out


def side_by_side(exps, specs, summary: dict, rows: list, out: Path, variant: str) -> tuple:
    """Per scene, ``images_<scene>.png``: the reference | the original shader with the
    experiment's constants at its schedule (``ORIGINAL_PANEL``) | the original's configuration
    refitted | the best configuration within the original's fetch budget | the recommendation |
    the user's shader (duplicates left out), each at the experiment's resolution with its FLIP
    and RMSE on the water pixels.
    Returns ({scene: file name}, {scene: {panel title: {"flip", "rmse"}}}); the first panel's
    FLIP is the original shader at its own constants, the baseline of every "halves the
    original's error" claim."""

    result, scores = {}, {}
    for exp, spec in zip(exps, specs):
        f = summary["scenes"][exp.name]
        panels = [
            (
                ORIGINAL_PANEL,
                "water_refraction",
                constants_from_experiment(exp).replace(**SEED_SCHEDULE),
            )
        ]
        for title, key in (
            ("original shader, fitted", "seed"),
            ("best within the original's fetches", "best_within_seed_budget"),
            ("recommended", "recommended"),
        ):
            r = f.get(key)
            if r and r["label"] not in [p[0].split(": ", 1)[-1] for p in panels]:
                row = point_row(rows, exp.name, r["label"])
                panels.append((f"{title}: {r['label']}", r["variant"], row))
        for p in f.get("user") or []:
            if p["label"] not in [q[0].split(": ", 1)[-1] for q in panels]:
                panels.append((f"your shader: {p['label']}", p["label"], point_row(
                    rows, exp.name, p["label"])))  # fmt: skip
        images, errs, mask = {}, {}, None
        exp_s, ref, inputs = load_scene(spec, variant)
        for title, name, what in panels:
            shader = Shader.of_table(exp_s, name)
            frame = Frame.of(exp_s, ref, shader.with_inputs(exp_s, inputs, variant))
            c = what if isinstance(what, Constants) else shader.constants(constants_of(what))
            score = Scorer(shader, [frame], variant)(0, c)
            images.setdefault("reference", ref.image)
            images[title] = score.image
            errs[title] = score.errors
            mask = score.mask
        name = f"images_{exp.name}.png"
        # the panels kept as data (``images_<scene>.exr``/``.json``), the figure drawn from them
        write_panels(out / name, images, errs, mask, title=exp.name)
        panels_figure(out / name)
        result[exp.name] = name
        scores[exp.name] = {
            t: {"flip": float(e["flip"]), "rmse": float(e["rmse"])} for t, e in errs.items()
        }
    return result, scores
