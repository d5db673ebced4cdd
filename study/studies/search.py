"""The adaptive search of ``study tradeoff``: the shader space walked cheaply, then only what is
not clearly beaten measured in full.

Three rungs, each a sweep of :func:`~study.studies.tradeoff_jobs.screen_job` points at the
screen resolution (``fit.resolution`` divided by ``tradeoff.screen_factor``) except the last:

1. **Walk** (shader configurations, at the original schedule): start from the original shader,
   one representative of every source and the original's one-axis neighbours
   (``shaders_port.space.neighbours``); after each round keep the configurations no other
   one clearly dominates (:func:`survivors`) and add their unseen neighbours, the lowest-FLIP
   survivors' first (:func:`best_first`); stop when a round adds none or
   ``tradeoff.max_shaders`` have been screened (the cut drops the worst survivors'
   neighbours). A shader-LOD system's greedy walk along the front, with a noise margin. Then a
   descent from the configuration the recommendation's rule picks among the screened ones (the
   cheapest within ``tradeoff.tolerance`` of the lowest FLIP, :func:`descent_origin`): its
   unseen one-axis neighbours, and again from the pick after them while it moves (at most
   :data:`DESCENT_MOVES` moves), so a best shader more choices from the original than the cut
   reaches is still found, and found where it costs least (:func:`descent_round`).
   The ``tradeoff.max_scheduled`` survivors with a raymarch closest to the front go on.
2. **Schedules**: every step schedule of ``tradeoff_jobs.schedules`` for each surviving
   configuration with a raymarch, warm-started from its screen fit; the dominated
   (configuration, schedule) points are dropped the same way, and of the rest the
   ``tradeoff.max_full`` closest to the front (:func:`margin`) go on.
3. **Joint** (several experiments, e.g. the views of one): rungs 1-2 run on each experiment
   alone, so a shader good on every view may be screened at one schedule on one view only. The
   joint rung screens the configurations of every experiment's survivors at their original
   schedule on every experiment, keeps the ``tradeoff.max_scheduled`` closest to the joint
   front (FLIP and fetches averaged over the experiments, :func:`joint_screen`), screens their
   step schedules on every experiment, and adds the ``tradeoff.max_full`` joint points closest
   to the joint front to the survivors (:meth:`Search.joint`).
4. **Full**: the surviving points measured as the exhaustive study measures every point
   (``point_job``: fit at ``fit.resolution``, FLIP at ``resolution``, GL frame times), each on
   every experiment.

"Clearly dominated": another point costs no more texture fetches per water pixel and its FLIP
is lower by more than ``tradeoff.noise_z`` standard errors of the paired difference. The
standard error comes from the two points' FLIP maps over the same pixels, averaged over
4 x 4-pixel blocks (neighbouring pixels' errors are correlated; blocks are nearly
independent): ``sd(d_b) / sqrt(n_b)`` over the blocks holding water in both.

The marginal table (what each axis's choice buys at the recommendation) comes from screen points
of the recommendation's one-axis neighbours at its schedule, measured if the walk did not.
"""

from __future__ import annotations

import math

import numpy as np

from shaders_port import space as _space

from ..fit.model import constants_from_experiment
from ..sweep import run_sweep
from .tradeoff_jobs import (
    POINT_VERSION,
    SCREEN_VERSION,
    SEED_SCHEDULE,
    original_schedule,
    schedules,
    screen_job,
    unpack_map,
)

# representatives of every source's technique screened in the first round: each alone
# (``space.ALONE``), 000's refraction alone, 002-004 and 001 + 004 (flat water)
SOURCE_STARTS = (
    *_space.ALONE.values(),
    {"reflection": "none", "specular": "none"},
    {"refraction": "distorted", "reflection": "planar_distorted"},
    {"refraction": "planar", "reflection": "planar"},
)


def paired_se(a: list, b: list) -> float:
    """Standard error of mean(a) - mean(b) from block means ``a``, ``b`` of the same blocks
    (NaN where a block holds no water); inf with fewer than 4 common blocks."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    both = np.isfinite(a) & np.isfinite(b)
    n = int(both.sum())
    if n < 4:
        return math.inf
    d = a[both] - b[both]
    return float(d.std(ddof=1) / math.sqrt(n))


def clearly_dominates(y: dict, x: dict, z: float, cost: str = "fetches_mean") -> bool:
    """``y`` costs no more than ``x`` and its FLIP is lower by more than ``z`` paired standard
    errors (``flip_blocks`` of both: see the module doc)."""
    if y is x or y.get(cost) is None or x.get(cost) is None:
        return False
    if y[cost] > x[cost] * (1 + 1e-9):
        return False
    gap = x["flip"] - y["flip"]
    return gap > 0 and gap > z * paired_se(x["flip_blocks"], y["flip_blocks"])


def survivors(points: list, z: float, cost: str = "fetches_mean") -> list:
    """The points no other point clearly dominates, in their order."""
    return [x for x in points if not any(clearly_dominates(y, x, z, cost) for y in points)]


def margin(x: dict, points: list, cost: str = "fetches_mean") -> float:
    """How far ``x`` is from being dominated, in paired standard errors: the smallest
    ``(flip_y - flip_x) / se`` over the points ``y`` costing no more (negative: some cheaper
    point is better; a point on the front has a positive margin, inf if none is cheaper)."""
    out = math.inf
    for y in points:
        if y is x or y.get(cost) is None or x.get(cost) is None:
            continue
        if y[cost] <= x[cost] * (1 + 1e-9):
            se = paired_se(x["flip_blocks"], y["flip_blocks"])
            out = min(out, (y["flip"] - x["flip"]) / max(se, 1e-12))
    return out


def closest_to_front(points: list, k: int, cost: str = "fetches_mean") -> list:
    """The ``k`` points with the largest :func:`margin` (those on the front first), in their
    order: the successive-halving cut between the screen and the full measurement."""
    if len(points) <= k:
        return list(points)
    ranked = sorted(points, key=lambda x: -margin(x, points, cost))[:k]
    return [p for p in points if any(p is r for r in ranked)]


def to_schedule(points: list, z: float, k: int, cost: str = "fetches_mean") -> list:
    """The surviving points with a raymarch (kind not ``fixed``) closest to the front, at most
    ``k``: the shaders rung 2 screens the schedules of. A screen-space shader has no schedule,
    so it takes no place (rung 2 keeps it among its survivors all the same)."""
    marching = [r for r in survivors(points, z, cost) if r["kind"] != "fixed"]
    return closest_to_front(marching, k, cost)


def first_round(fix: dict | None) -> list[dict]:
    """The walk's first configurations: the original, each source's representative and the
    original's one-axis neighbours, those realisable with ``fix`` (axis -> pinned choice)."""
    start = _space.checked(fix or {})
    out = [start]
    for s in SOURCE_STARTS:
        c = {**start, **s}
        if any(fix and a in fix and c[a] != fix[a] for a in c):
            continue
        _try_add(out, c)
    for n in _space.neighbours(start, fix):
        _try_add(out, n)
    return out


def _try_add(out: list, c: dict) -> None:
    try:
        _space.realise(c)
    except _space.Unrealisable:
        return
    c = _space.checked(c)
    if c not in out:
        out.append(c)


#: moves of the descent after the walk (each screens the pick's unseen neighbours)
DESCENT_MOVES = 4


def descent_origin(points: list[dict], tol: float, cost: str = "fetches_mean") -> dict:
    """Of ``points`` (screen points), the cheapest whose FLIP is within the fraction ``tol`` of
    the lowest (the recommendation's rule): where the descent goes on from."""
    low = best_first(points)[0]["flip"]
    near = [r for r in points if r["flip"] <= low * (1 + tol) and r.get(cost) is not None]
    return min(near, key=lambda r: (r[cost], r["flip"])) if near else best_first(points)[0]


def descent_round(points: list[dict], seen: list[dict], fix: dict | None, tol: float) -> list:
    """The unseen one-axis neighbours of :func:`descent_origin` of ``points`` (screen points
    with ``choices``): the descent's next configurations."""
    return next_round([descent_origin(points, tol)["choices"]], seen, fix)


def best_first(points: list[dict]) -> list[dict]:
    """``points`` by FLIP, lowest first: the walk expands the best shaders' neighbours first, so
    the ``tradeoff.max_shaders`` cut drops the neighbours of the worst."""
    return sorted(points, key=lambda r: r["flip"])


def next_round(front: list[dict], seen: list[dict], fix: dict | None) -> list[dict]:
    """The unseen one-axis neighbours of the configurations on the front, in the front's
    order."""
    out = []
    for c in front:
        for n in _space.neighbours(c, fix):
            if n not in seen and n not in out:
                out.append(n)
    return out


def marginals(base: dict, neighbours: list[dict]) -> list[dict]:
    """What each axis's choice buys at ``base`` (a screen point with ``choices``): for each
    screen point of a one-axis neighbour (at the matching schedule), its FLIP and fetches minus
    ``base``'s with the paired standard error, at the screen resolution. The axis is the one
    changed (refraction or reflection where a coupled axis moved with it)."""
    out = []
    for p in neighbours:
        diff = [a for a in _space.AXES if p["choices"][a] != base["choices"][a]]
        axis = next((a for a in ("refraction", "reflection") if a in diff), diff[0])
        out.append(
            {
                "axis": axis,
                "choice": p["choices"][axis],
                "variant": p["variant"],
                "d_flip": p["flip"] - base["flip"],
                "d_fetches": (p.get("fetches_mean") or 0.0) - (base.get("fetches_mean") or 0.0),
                "se": paired_se(p["flip_blocks"], base["flip_blocks"]),
            }
        )
    return sorted(out, key=lambda r: (list(_space.AXES).index(r["axis"]), r["d_flip"]))


def joint_screen(points: list[list[dict]], cost: str = "fetches_mean") -> list[dict]:
    """The (variant, schedule) screen points measured on every experiment, one record each:
    ``points[i]`` the screen points of experiment ``i``. FLIP, RMSE and ``cost`` are the means
    over the experiments (``cost`` None where one lacks it); ``flip_blocks`` the experiments'
    block means in turn, so the paired standard error pools the blocks of every experiment;
    ``per_experiment`` the experiments' own records."""
    by: dict = {}
    for i, pts in enumerate(points):
        for r in pts:
            by.setdefault((r["variant"], _key(r["schedule"])), {}).setdefault(i, r)
    out = []
    for per in by.values():
        if len(per) < len(points):
            continue
        rs = [per[i] for i in range(len(points))]
        rec = {k: rs[0][k] for k in ("variant", "choices", "kind", "scale", "schedule")}
        for k in ("flip", "rmse", cost):
            vals = [r.get(k) for r in rs]
            rec[k] = float(np.mean(vals)) if all(v is not None for v in vals) else None
        rec["flip_blocks"] = np.concatenate(
            [np.asarray(r["flip_blocks"], np.float64) for r in rs]
        ).tolist()
        rec["per_experiment"] = rs
        out.append(rec)
    return out


# ---- the driver ------------------------------------------------------------------------------


def screen_record(job: dict, row: dict) -> dict:
    """The figures of one screen row the search uses, with its configuration's choices."""
    rec = {
        "experiment": job["experiment"],
        "variant": job["variant"],
        "choices": _space.choices_of(job["variant"]),
        "kind": job["kind"],
        "scale": job["scale"],
        "schedule": job["schedule"],
        "status": row.get("status"),
        "error_message": row.get("error"),
    }
    for k in ("flip", "rmse", "fetches_mean", "iterations_mean", "not_crossed", "flip_blocks"):
        rec[k] = row.get(k)
    if row.get("flip_map") is not None and row.get("fetch_map") is not None:
        rec["flip_map"] = unpack_map(row["flip_map"], row["map_shape"])
        rec["fetch_map"] = unpack_map(row["fetch_map"], row["map_shape"])
    rec["fitted"] = {
        k[len("fitted.") :]: v for k, v in row.items() if k.startswith("fitted.") and v is not None
    }
    return rec


def screen_records(rows: list[dict]) -> list[dict]:
    """:func:`screen_record` of every row of a screen table (``screen.parquet``, read with
    ``study.sweep.read_table``), its job rebuilt from the row's ``job.*`` columns."""
    out = []
    for r in rows:
        job = {k: r[f"job.{k}"] for k in ("experiment", "variant", "kind", "scale")}
        job["schedule"] = {k[len("job.schedule.") :]: v for k, v in r.items()
                           if k.startswith("job.schedule.") and v is not None}  # fmt: skip
        out.append(screen_record(job, r))
    return out


class Search:
    """The adaptive search over one sweep client (see the module doc): ``walk`` per experiment,
    ``schedules`` for the survivors, ``full_jobs`` for the final rung, ``marginals_of`` for the
    recommendation. Screen rows accumulate in ``out/screen.parquet`` (a re-run resumes)."""

    def __init__(self, exps, specs, client, out, log, fix=None, variants=None):
        self.exps, self.specs, self.client, self.out, self.log = exps, specs, client, out, log
        self.fix, self.variants = fix or {}, variants
        self.start = [constants_from_experiment(e).replace(**SEED_SCHEDULE).to_dict() for e in exps]
        self.screen: list[dict] = []
        self.rounds: dict[str, int] = {}
        self.descents: dict[str, int] = {}
        self.joint_screened = 0

    def _run(self, jobs: list, label: str) -> list[dict]:
        if not jobs:
            return []
        rows = run_sweep(
            screen_job,
            jobs,
            self.out / "screen.parquet",
            client=self.client,
            label=label,
            log=self.log,
        )[: len(jobs)]
        recs = [screen_record(j, r) for j, r in zip(jobs, rows)]
        for r in recs:
            if r["status"] != "ok":
                self.log(f"tradeoff: screen of {r['variant']} failed: {r['error_message']}")
        self.screen += recs
        return recs

    def _job(self, i: int, variant: str, sched: dict, start: dict) -> dict:
        exp = self.exps[i]
        return {
            "scene": self.specs[i],
            "experiment": exp.name,
            "variant": variant,
            "kind": sched["kind"],
            "scale": sched["scale"],
            "schedule": sched["schedule"],
            "start": start,
            "factor": exp.tradeoff.screen_factor,
            "screen_version": SCREEN_VERSION,
        }

    def ok(self, i: int) -> list[dict]:
        name = self.exps[i].name
        return [
            r
            for r in self.screen
            if r["experiment"] == name and r["status"] == "ok" and r["flip"] is not None
        ]

    def walk(self, i: int) -> list[dict]:
        """Rung 1 on experiment ``i``: the surviving configurations' screen points."""
        exp = self.exps[i]
        z, cap = exp.tradeoff.noise_z, exp.tradeoff.max_shaders
        if self.variants:
            todo = [_space.choices_of(v) for v in self.variants]
        else:
            todo = first_round(self.fix)
        seen: list[dict] = []
        for k in range(1, 100):
            todo = todo[: max(cap - len(seen), 0)]
            if not todo:
                break
            self._screen_original(i, todo, f"tradeoff: {exp.name} screen round {k}")
            seen += todo
            self.rounds[exp.name] = k
            front = best_first(survivors(self.ok(i), z))
            if self.variants:
                break
            todo = next_round([r["choices"] for r in front], seen, self.fix)
        if not self.variants:
            self._descend(i, seen)
        return to_schedule(self.ok(i), z, exp.tradeoff.max_scheduled)

    def _screen_original(self, i: int, configs: list[dict], label: str) -> None:
        """Screen ``configs`` (choices) on experiment ``i`` at their original schedules."""
        jobs = []
        for c in configs:
            v = _space.name_of(c)
            jobs.append(self._job(i, v, original_schedule(v), self.start[i]))
        self._run(jobs, label)

    def _descend(self, i: int, seen: list[dict]) -> None:
        """The descent after the walk on experiment ``i`` (module doc): screens the unseen
        neighbours of the recommendation rule's pick until the pick stays."""
        exp = self.exps[i]
        tol = exp.tradeoff.tolerance
        for k in range(1, DESCENT_MOVES + 1):
            before = descent_origin(self.ok(i), tol)["variant"]
            todo = descent_round(self.ok(i), seen, self.fix, tol)
            if not todo:
                break
            self._screen_original(i, todo, f"tradeoff: {exp.name} descent {k}")
            seen += todo
            self.descents[exp.name] = k
            if descent_origin(self.ok(i), tol)["variant"] == before:
                break

    def alone(self, i: int) -> list[dict]:
        """The screen points of each source's technique alone (``space.ALONE``) at its
        original schedule on experiment ``i``: measured in full so every front has their rows."""
        names = set()
        for c in _space.ALONE.values():
            if any(self.fix.get(a, v) != v for a, v in c.items()):
                continue  # an axis the user pinned
            try:
                names.add(_space.name_of({**self.fix, **c}))
            except _space.Unrealisable:
                continue
        return [r for r in self.ok(i) if r["variant"] in names and _at_original(r)]

    def schedules(self, i: int, front: list[dict]) -> list[dict]:
        """Rung 2 on experiment ``i``: the step schedules of the front's raymarch shaders,
        warm-started from their screen fits; returns the surviving screen points."""
        exp = self.exps[i]
        jobs = []
        for r in front:
            jobs += self._schedule_jobs(i, r, {_key(r["schedule"])})
        self._run(jobs, f"tradeoff: {exp.name} screen schedules")
        kept = survivors(self.ok(i), exp.tradeoff.noise_z)
        return closest_to_front(kept, exp.tradeoff.max_full)

    def joint(self, finalists: list[dict]) -> list[dict]:
        """Rung 3 over several experiments (module doc): ``finalists`` the experiments' own
        survivors; returns the joint screen points (:func:`joint_screen`) closest to the joint
        front, at most ``tradeoff.max_full``; none with one experiment."""
        if len(self.exps) < 2:
            return []
        first = self.exps[0].tradeoff
        variants = list(dict.fromkeys(r["variant"] for r in finalists))
        jobs = []
        for i in range(len(self.exps)):
            have = {r["variant"] for r in self.ok(i) if _at_original(r)}
            jobs += [
                self._job(i, v, original_schedule(v), self.start[i])
                for v in variants
                if v not in have
            ]
        self.joint_screened += len(self._run(jobs, "tradeoff: joint screen"))
        at_original = [r for r in self._joint() if _at_original(r)]
        jobs = []
        for r in to_schedule(at_original, first.noise_z, first.max_scheduled):
            for i in range(len(self.exps)):
                have = {_key(p["schedule"]) for p in self.ok(i) if p["variant"] == r["variant"]}
                jobs += self._schedule_jobs(i, r["per_experiment"][i], have)
        self.joint_screened += len(self._run(jobs, "tradeoff: joint screen schedules"))
        kept = survivors(self._joint(), first.noise_z)
        return closest_to_front(kept, first.max_full)

    def _schedule_jobs(self, i: int, r: dict, skip: set) -> list[dict]:
        """Screen jobs of screen point ``r``'s variant on experiment ``i`` at each step schedule
        of ``tradeoff_jobs.schedules`` but the converged one and those keyed in ``skip``,
        warm-started from ``r``'s fit."""
        return [
            self._job(i, r["variant"], s, {**self.start[i], **r["fitted"]})
            for s in schedules(self.exps[i], r["variant"])
            if s["kind"] not in ("converged", "fixed") and _key(s["schedule"]) not in skip
        ]

    def _joint(self) -> list[dict]:
        return joint_screen([self.ok(i) for i in range(len(self.exps))])

    def full_jobs(self, finalists: list[dict]) -> list[dict]:
        """Rung 4: every finalist (variant, schedule) on every experiment, as ``point_job`` jobs
        warm-started from that experiment's screen fit of it (or of its variant)."""
        keys = []
        for r in finalists:
            key = (r["variant"], r["kind"], r["scale"], _key(r["schedule"]))
            if key not in keys:
                keys.append(key)
        jobs = []
        for i, exp in enumerate(self.exps):
            ok = self.ok(i)
            for variant, kind, scale, sched in keys:
                same = [r for r in ok if r["variant"] == variant]
                exact = [r for r in same if _key(r["schedule"]) == sched]
                warm = (exact or same or [{"fitted": {}}])[0]["fitted"]
                jobs.append(
                    {
                        "scene": self.specs[i],
                        "experiment": exp.name,
                        "variant": variant,
                        "kind": kind,
                        "scale": scale,
                        "schedule": dict(sched),
                        "start": {**self.start[i], **warm},
                        "point_version": POINT_VERSION,
                    }
                )
        return jobs

    def marginals_of(self, i: int, rec: dict) -> list[dict]:
        """What each axis's choice buys at the full rung's recommendation ``rec`` on experiment
        ``i`` (screen points of its one-axis neighbours at its schedule; measured if missing)."""
        ok = self.ok(i)
        here = [
            r for r in ok if r["variant"] == rec["variant"] and r["schedule"] == rec["schedule"]
        ]
        if not here:
            return []
        base = here[0]
        wanted = {}
        for c in _space.neighbours(base["choices"], self.fix):
            v = _space.name_of(c)
            wanted[v] = _schedule_like(v, base)
        have = {(r["variant"], _key(r["schedule"])) for r in ok}
        jobs = []
        for v, sched in wanted.items():
            if (v, _key(sched["schedule"])) not in have:
                warm = next((r["fitted"] for r in ok if r["variant"] == v), base["fitted"])
                jobs.append(self._job(i, v, sched, {**self.start[i], **warm}))
        self._run(jobs, f"tradeoff: {self.exps[i].name} screen of the neighbours")
        points = [
            r
            for r in self.ok(i)
            if r["variant"] in wanted
            and _key(r["schedule"]) == _key(wanted[r["variant"]]["schedule"])
        ]
        unique = {r["variant"]: r for r in points}  # one point per neighbour
        return marginals(base, list(unique.values()))


def _at_original(r: dict) -> bool:
    """Whether screen point ``r`` is at its variant's original schedule."""
    return _key(r["schedule"]) == _key(original_schedule(r["variant"])["schedule"])


def _schedule_like(variant: str, base: dict) -> dict:
    """The schedule of ``variant`` closest to ``base``'s: the same steps where both raymarch
    (its own reflection schedule kept), its only schedule where one of them does not."""
    own = original_schedule(variant)
    if not base["schedule"] or not own["schedule"]:
        return own
    sched = {
        **own["schedule"],
        **{k: v for k, v in base["schedule"].items() if k in own["schedule"]},
    }
    return {"kind": base["kind"], "scale": base["scale"], "schedule": sched}


def _key(schedule: dict) -> tuple:
    return tuple(sorted(schedule.items()))
