"""The analysis of a ``study tradeoff`` table: the figures of each point, the Pareto fronts per
scene and over the scenes, the recommendation (the cheapest point within the tolerance of the
best FLIP, or the lowest FLIP within a budget) and what the scene needs (see
``study.studies.tradeoff``)."""

from __future__ import annotations

import statistics

from shaders_port import space as _space

from .pareto import pareto_front, recommend

COST = "fetches_mean"
COSTS = {
    "fetches_mean": "texture fetches / water pixel (mean)",
    "gl_norm_ms_1080p": "llvmpipe ms / frame at 1920x1080 (normalised)",
    "port_ms_512": "Dr.Jit port ms / frame at 512x512 (the run's backend)",
}
ERROR = "flip"
USER = "user:"  # the variant name of a user's own shader: USER + its file name


def is_user(variant) -> bool:
    """True for the variant name of a user's own shader (``study.studies.tradeoff_user``)."""
    return str(variant).startswith(USER)


def constants_of(row: dict) -> dict:
    return {
        k[len("fitted.") :]: v for k, v in row.items() if k.startswith("fitted.") and v is not None
    }


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
        sched += (
            f" refl ({s['refl_steps_steep']:g}, {s['refl_steps_grazing']:g}, "
            f"{int(s['refl_loop_cap'])})"
        )
    return f"{rec['variant']} {sched}"


def is_seed(rec: dict) -> bool:
    return rec["kind"] == "scale" and rec["scale"] == 1.0


def analyse(rows: list, names: list, tolerance: float, budget=None) -> tuple[dict, list]:
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
        scenes[name] = scene_findings(
            pts, [r for r in ok if r["experiment"] == name], tolerance, budget
        )
    joint = joint_points(ok, names)
    summary = {
        "tolerance": tolerance,
        "budget": dict(budget or {}),
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
        summary["joint"] = joint_findings(joint, tolerance, budget)
    return summary, ok


def recommended(pts: list, tolerance: float, budget=None) -> dict | None:
    """The recommendation among ``pts``: the cheapest within ``tolerance`` of the lowest FLIP
    or, with a ``budget`` (cost -> limit), the lowest FLIP within every limit."""
    if not budget:
        return recommend(pts, COST, ERROR, tolerance)
    fits = [r for r in pts if all(r.get(c) is not None and r[c] <= v for c, v in budget.items())]
    return min(fits, key=lambda r: r[ERROR], default=None)


def best_within_seed_budget(pts: list, seed: list) -> dict | None:
    """The lowest FLIP among ``pts`` costing no more fetches than ``seed`` (the original shader
    at its schedule, a list of it or empty)."""
    if not seed or seed[0].get(COST) is None:
        return None
    limit = seed[0][COST] * (1 + 1e-3)
    within = [r for r in pts if r.get(COST) is not None and r[COST] <= limit]
    return min(within, key=lambda r: r[ERROR], default=None)


def joint_findings(joint: list, tolerance: float, budget=None) -> dict:
    """The joint front's findings (``joint``: :func:`joint_points`): its front, the
    recommendation for all scenes, the original shader at its schedule and the best within its
    fetches (FLIP and fetches averaged over the scenes)."""
    seed = [r for r in joint if is_seed(r) and r["variant"] == "water_refraction"]
    return {
        "front": pareto_front(joint, COST, ERROR),
        "recommended": recommended(joint, tolerance, budget),
        "seed": seed[0] if seed else None,
        "best_within_seed_budget": best_within_seed_budget(joint, seed),
    }


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


def sources_alone(pts: list, brief) -> list[dict]:
    """Each source's technique alone (``shaders_port.space.ALONE``) among ``pts`` at its
    original schedule: ``brief`` of the point plus ``source`` (its label there)."""
    out = []
    for source, choices in _space.ALONE.items():
        try:
            name = _space.name_of(choices)
        except _space.Unrealisable:
            continue
        at = [r for r in pts if r["variant"] == name and (is_seed(r) or r["kind"] == "fixed")]
        if at:
            out.append({"source": source, **brief(at[0])})
    return out


def scene_findings(pts: list, all_pts: list, tolerance: float, budget=None) -> dict:
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

    rec = recommended(pts, tolerance, budget)
    seed = [r for r in pts if is_seed(r) and r["variant"] == "water_refraction"]
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
            # a loopless shader (the baselines), or a user's with loops of its own
            crossing[v] = "no schedule swept"
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
    at_seed = {r["variant"]: r for r in pts if (is_seed(r) or r["kind"] == "fixed")}
    parsimony = {
        v: {"n_fitted": r.get("n_fitted"), "bic": r.get("bic"), "flip": r["flip"]}
        for v, r in at_seed.items()
    }
    best_within = best_within_seed_budget(pts, seed)
    return {
        "front": [brief(r) for r in pareto_front(pts, COST, ERROR)],
        "sources_alone": sources_alone(pts, brief),
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
        "user": [placement(pts, r["label"]) for r in pts if is_user(r["variant"])],
    }


def placement(pts: list, label: str, cost: str = "fetches_mean") -> dict | None:
    """Where the point ``label`` stands among a scene's candidate points ``pts`` (records with
    ``label``, ``flip`` and ``cost``): ``on_front`` (no other point costs no more and errs less),
    ``dominated_by`` (those that do, cheapest first, with their FLIP and cost), ``best_within``
    (the lowest FLIP at no more than its cost, itself excluded) and ``rank`` (1 + the number of
    points with a lower FLIP); None when the point is not among them."""
    me = next((r for r in pts if r["label"] == label), None)
    if me is None or me.get(cost) is None:
        return None
    others = [r for r in pts if r is not me and r.get(cost) is not None]
    within = [r for r in others if r[cost] <= me[cost] * (1 + 1e-9)]
    better = sorted((r for r in within if r["flip"] < me["flip"]), key=lambda r: r[cost])

    def brief(r):
        return {"label": r["label"], "flip": r["flip"], cost: r[cost]}

    best = min(within, key=lambda r: r["flip"], default=None)
    return {
        "label": label,
        "flip": me["flip"],
        cost: me[cost],
        "on_front": not better,
        "dominated_by": [brief(r) for r in better],
        "best_within": brief(best) if best else None,
        "rank": 1 + sum(r["flip"] < me["flip"] for r in others),
        "of": len(pts),
    }
