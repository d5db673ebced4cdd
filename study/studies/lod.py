"""Level of detail over bands of the water: which point of the shader space (a configuration at
a step schedule) each band of pixels gets, chosen from the points' per-pixel maps.

A policy splits the water pixels by a measure of what a pixel needs (:data:`MEASURES`: its
distance to the camera, or its footprint, the world area of the water plane the pixel covers)
into 1-5 bands, at bounds taken from a grid of the measure's quantiles, and gives each band one
point. Its FLIP is the mean over the water of the chosen points' FLIP maps, each on its band;
its cost the mean of their texture-fetch maps alike. Both add up over the bands, so for given
bounds the front of policies (FLIP against mean fetches per water pixel) is that of a
multiple-choice knapsack, merged band by band (:func:`_merge`); the fronts of every set of
bounds, and of both measures, are merged into one.

The tradeoff chooses the policy among the points measured in full (:func:`full_points`: maps at
the experiment's resolution, each point's constants fitted on the whole view; a fit on a band's
pixels could only lower that band's error); the adaptive search's screen, at the fit's
resolution, only proposes bands for that rung (:func:`policy_bands`). The seams between bands
and the cost of a blend margin are measured on the policy drawn as one shader
(``study.studies.lod_export``).

Inputs are per-pixel maps (``flip_map`` and ``fetch_map``, (H, W) float32, NaN off the water:
``tradeoff_jobs.point_job``'s or ``screen_job``'s) and the measure maps of
:func:`band_measures` at the same resolution.
"""

from __future__ import annotations

import itertools

import numpy as np

from shaders_port.pipeline.interpolate import plane_points

from ..scene.mitsuba_scene import camera_view_proj
from .pareto import recommend
from .search import paired_se
from .tradeoff_analysis import config_label, point_record
from .tradeoff_jobs import SCREEN_BLOCK, block_means, unpack_map

#: what decides a pixel's need: name -> what it is (units)
MEASURES = {
    "distance": "distance from the camera to the water point the pixel sees (world units)",
    "footprint": "world area of the water plane the pixel covers (square world units)",
}
#: the bounds between bands are taken at these quantiles of the measure over the water
QUANTILES = tuple(np.round(np.arange(1, 10) / 10, 2))
MAX_BANDS = 5


def full_points(rows: list[dict], scene: str) -> list[dict]:
    """The full rung's points of ``scene`` with their maps, from the tradeoff's table rows
    (``tradeoff.parquet``; ``tradeoff_jobs.point_job`` with ``flip_map`` and ``fetch_map`` at
    the experiment's resolution): records with ``variant``, ``schedule``, ``kind``, ``flip``,
    ``fetches_mean``, ``fitted`` (the point's constants, ``Constants.to_dict`` form) and the
    unpacked maps; the error floor (``converged``) and failed points left out."""
    out = []
    for r in rows:
        if (r.get("job.experiment") != scene or r.get("status") != "ok"
                or r.get("job.kind") == "converged" or r.get("flip_map") is None):  # fmt: skip
            continue
        rec = point_record(r)
        rec["fitted"] = {k[len("fitted.") :]: v for k, v in r.items()
                         if k.startswith("fitted.") and v is not None}  # fmt: skip
        rec["flip_map"] = unpack_map(r["flip_map"], r["map_shape"])
        rec["fetch_map"] = unpack_map(r["fetch_map"], r["map_shape"])
        out.append(rec)
    return out


def band_measures(view_proj: np.ndarray, viewpos, width: int, height: int) -> dict:
    """The :data:`MEASURES` maps, (height, width) float64 each, of a camera ``view_proj``
    ((4, 4) world -> GL clip) at ``viewpos`` ((3,) world units) over the water plane y = 0,
    row 0 at the top; NaN where the pixel's ray does not meet the plane in front of the
    camera. The footprint is the area of the parallelogram spanned by the derivatives of the
    plane point along the pixel's x and y (:func:`footprint`)."""
    rows, cols = np.mgrid[0:height, 0:width].astype(np.float64)
    p, t = plane_points(view_proj, width, height, cols, rows)
    seen = np.isfinite(t) & (t > 0)
    dist = np.linalg.norm(p - np.asarray(viewpos, np.float64), axis=-1)
    area = footprint(view_proj, viewpos, width, height, cols, rows)
    return {
        "distance": np.where(seen, dist, np.nan),
        "footprint": np.where(seen & np.isfinite(area), area, np.nan),
    }


def footprint(view_proj: np.ndarray, viewpos, width: int, height: int, cols, rows) -> np.ndarray:
    """The world area of the plane y = 0 that the pixels ``(cols, rows)`` (row 0 at the top)
    cover: ``|dp/dx x dp/dy|`` of the plane point p along the pixel's axes, in closed form.
    The ray through a pixel is ``D = h.xyz - h.w * viewpos`` with ``h = inverse(view_proj) @
    (ndc, 1, 1)``, linear in the pixel, and ``p = viewpos + t D``, ``t = -viewpos.y / D.y``,
    so ``dp = t (dD - (dD.y / D.y) D)``: the policy shader computes the same in float32
    without the cancellation of differences of nearby points
    (``study.export.policy_shader``)."""
    inv = np.linalg.inv(np.asarray(view_proj, np.float64))
    o = np.asarray(viewpos, np.float64)
    x = 2.0 * (np.asarray(cols, np.float64) + 0.5) / width - 1.0
    y = 2.0 * (height - np.asarray(rows, np.float64) - 0.5) / height - 1.0
    h = np.stack([x, y, np.ones_like(x), np.ones_like(x)], -1) @ inv.T
    ray = h[..., :3] - h[..., 3:] * o
    t = -o[1] / ray[..., 1]
    along = []
    for col, scale in ((0, 2.0 / width), (1, -2.0 / height)):  # rows grow downwards
        dh = inv[:, col] * scale
        dray = dh[:3] - dh[3] * o
        along.append(t[..., None] * (dray - (dray[1] / ray[..., 1])[..., None] * ray))
    with np.errstate(invalid="ignore"):
        return np.linalg.norm(np.cross(along[0], along[1]), axis=-1)


def _pareto(flip: np.ndarray, cost: np.ndarray) -> np.ndarray:
    """Indices of the points no other beats in both (lower FLIP at no more cost), cheapest
    first."""
    order = np.lexsort((flip, cost))
    f = np.asarray(flip)[order]
    before = np.minimum.accumulate(np.concatenate([[np.inf], f[:-1]]))
    return order[f < before - 1e-15].astype(np.int64)


def _merge(front: tuple, band_flip: np.ndarray, band_cost: np.ndarray) -> tuple:
    """The front of (FLIP sum, cost sum, choices) after one more band: every front entry with
    every point on that band (``band_flip``, ``band_cost``: (P,) sums over its pixels), kept
    where on the merged front."""
    f0, c0, ch0 = front
    own = _pareto(band_flip, band_cost)
    f = (f0[:, None] + band_flip[own][None, :]).ravel()
    c = (c0[:, None] + band_cost[own][None, :]).ravel()
    keep = _pareto(f, c)
    i, j = np.divmod(keep, len(own))
    return f[keep], c[keep], np.concatenate([ch0[i], own[j][:, None]], 1)


def policy_front(points: list[dict], measures: dict, max_bands: int = MAX_BANDS) -> list[dict]:
    """The front of band policies over ``points`` (dicts with ``flip_map`` and ``fetch_map``,
    (H, W), NaN off the water) and ``measures`` (name -> (H, W) map), on the water pixels all
    maps share: dicts with ``measure``, ``bounds`` (the measure's values between bands, its
    unit), ``shares`` (each band's fraction of the water), ``choices`` (each band's index into
    ``points``), ``flip`` and ``fetches`` (means over the water), cheapest first. Adjacent
    bands choosing the same point are one band; a single point is a one-band policy."""
    flips = np.stack([np.asarray(p["flip_map"], np.float64) for p in points])
    costs = np.stack([np.asarray(p["fetch_map"], np.float64) for p in points])
    water = np.isfinite(flips).all(0) & np.isfinite(costs).all(0)
    found = []  # (measure, sorted values, edges, (FLIP sums, cost sums, choices), pixels)
    for name, m in measures.items():
        mask = water & np.isfinite(m)
        n = int(mask.sum())
        if n < 2:
            continue
        order = np.argsort(m[mask], kind="stable")
        values = m[mask][order]
        zero = np.zeros((len(points), 1))
        cf = np.concatenate([zero, np.cumsum(flips[:, mask][:, order], 1)], 1)
        cc = np.concatenate([zero, np.cumsum(costs[:, mask][:, order], 1)], 1)
        # each cut at the start of its run of equal values, so that a bound (the midpoint of
        # the values either side) splits the pixels as the cut does (a symmetric view has
        # pairs of pixels at one distance)
        raw = {min(max(int(round(q * n)), 1), n - 1) for q in QUANTILES}
        grid = sorted({int(np.searchsorted(values, values[g], side="left")) for g in raw} - {0})
        for k in range(1, max_bands + 1):
            for cuts in itertools.combinations(grid, k - 1):
                edges = (0, *cuts, n)
                front = (np.zeros(1), np.zeros(1), np.zeros((1, 0), np.int64))
                for a, b in zip(edges[:-1], edges[1:]):
                    front = _merge(front, cf[:, b] - cf[:, a], cc[:, b] - cc[:, a])
                found.append((name, values, edges, front, n))
    if not found:
        return []
    flip = np.concatenate([f / n for *_, (f, _, _), n in found])
    cost = np.concatenate([c / n for *_, (_, c, _), n in found])
    where = [(i, j) for i, (*_, (f, _, _), _) in enumerate(found) for j in range(len(f))]
    out = []
    for k in _pareto(flip, cost):
        i, j = where[k]
        name, values, edges, (_, _, ch), _ = found[i]
        out.append(_policy(name, values, edges, ch[j], flip[k], cost[k]))
    return out


def _policy(measure: str, values: np.ndarray, edges: tuple, choices, flip, fetches) -> dict:
    """A policy's record with adjacent bands of one choice joined."""
    n = edges[-1]
    bands = []  # (end index, choice)
    for b, ch in zip(edges[1:], choices):
        if bands and bands[-1][1] == int(ch):
            bands[-1] = (b, int(ch))
        else:
            bands.append((b, int(ch)))
    ends = [b for b, _ in bands]
    return {
        "measure": measure,
        "bounds": [float(0.5 * (values[b - 1] + values[b])) for b in ends[:-1]],
        "shares": [(b - a) / n for a, b in zip([0, *ends[:-1]], ends)],
        "choices": [ch for _, ch in bands],
        "flip": float(flip),
        "fetches": float(fetches),
    }


def composite(policy: dict, points: list[dict], measures: dict) -> tuple[np.ndarray, np.ndarray]:
    """(FLIP map, fetch map) (H, W) of ``policy``: each pixel from its band's point (NaN off
    the water or where the measure is undefined)."""
    m = measures[policy["measure"]]
    band = np.searchsorted(np.asarray(policy["bounds"]), m, side="right")
    flip = np.full(m.shape, np.nan)
    cost = np.full(m.shape, np.nan)
    for k, ch in enumerate(policy["choices"]):
        here = (band == k) & np.isfinite(m)
        flip[here] = np.asarray(points[ch]["flip_map"])[here]
        cost[here] = np.asarray(points[ch]["fetch_map"])[here]
    return flip, cost


def paired_difference(fmap: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """(``fmap``'s mean FLIP minus ``ref``'s, its paired standard error) on the pixels both
    maps ((H, W), NaN where not scored) cover; 4 x 4-pixel blocks of both maps, as the
    search judges noise."""
    both = np.isfinite(fmap) & np.isfinite(ref)
    d = float(fmap[both].mean() - ref[both].mean())
    se = paired_se(block_means(np.where(both, fmap, np.nan), SCREEN_BLOCK).ravel(),
                   block_means(np.where(both, ref, np.nan), SCREEN_BLOCK).ravel())  # fmt: skip
    return d, se


def _within(fmap: np.ndarray, ref: np.ndarray, z: float) -> tuple[bool, float, float]:
    """(``fmap``'s mean FLIP is above ``ref``'s by no more than ``z`` paired standard errors,
    the difference, the standard error): :func:`paired_difference`."""
    d, se = paired_difference(fmap, ref)
    return d <= z * se, d, se


def best_policy(front: list[dict], points: list[dict], measures: dict, tolerance: float,
                z: float = 1.0) -> dict:  # fmt: skip
    """What bands buy against the single point a user would take: the cheapest point whose
    FLIP is within ``tolerance`` (relative) of the lowest (the tradeoff's recommendation,
    ``pareto.recommend``), and the cheapest policy of two bands or more on ``front``
    (cheapest first) whose FLIP is above that point's by no more than ``z`` paired standard
    errors (:func:`_within`). Returns ``{"best": index of the lowest-FLIP point, "single":
    index of that cheapest point, "single_d": (its FLIP above the lowest, the paired standard
    error), "policy": the policy with its "se" and "d_flip" (above the single point) or None,
    "fetch_ratio": the policy's mean fetches over the single point's (None without a
    policy)}``."""
    best = int(np.argmin([p["flip"] for p in points]))
    chosen = recommend(points, "fetches_mean", "flip", tolerance)
    single = next(i for i, p in enumerate(points) if p is chosen)
    ref = np.asarray(points[single]["flip_map"], np.float64)
    _, *single_d = _within(ref, np.asarray(points[best]["flip_map"], np.float64), z)
    policy = None
    for pol in front:
        if len(pol["choices"]) < 2:
            continue
        ok, d, se = _within(composite(pol, points, measures)[0], ref, z)
        if ok:
            policy = {**pol, "se": se, "d_flip": d}
            break
    cost = points[single]["fetches_mean"]
    return {
        "best": best,
        "single": single,
        "single_d": tuple(single_d),
        "policy": policy,
        "fetch_ratio": float(policy["fetches"] / cost) if policy and cost > 0 else None,
    }


def _against(policy: dict | None, points: list[dict], measures: dict, i: int) -> dict | None:
    """``policy``'s FLIP above point ``i``'s (``d_flip``, paired ``se``) and its fetches over
    point ``i``'s (``fetch_ratio``); None without a policy."""
    if policy is None:
        return None
    _, d, se = _within(composite(policy, points, measures)[0], points[i]["flip_map"], 1.0)
    cost = points[i]["fetches_mean"]
    return {"d_flip": d, "se": se, "fetch_ratio": policy["fetches"] / cost if cost > 0 else None}


def held_out(points: list[dict], measures: dict, tolerance: float, z: float = 1.0) -> dict | None:
    """The choice checked on pixels it did not see. The water's ``SCREEN_BLOCK``-pixel blocks
    are split as a checkerboard; the single point and the policy are chosen
    (:func:`best_policy`) on one colour's blocks and scored on the other's. Returns
    ``{"choices", "measure", "bounds", "d_flip", "se", "within", "fetch_ratio"}``: the
    policy's FLIP minus the single point's on the unseen blocks with its paired standard
    error, whether that is within ``z`` of them, and its fetches over the single point's
    there; None when no policy is chosen on the first half."""
    h, w = np.asarray(points[0]["flip_map"]).shape
    by, bx = np.mgrid[0:h, 0:w] // SCREEN_BLOCK
    black = (by + bx) % 2 == 0

    def half(mask: np.ndarray) -> list[dict]:
        out = []
        for p in points:
            f = np.where(mask, np.asarray(p["flip_map"], np.float64), np.nan)
            c = np.where(mask, np.asarray(p["fetch_map"], np.float64), np.nan)
            out.append({"flip_map": f, "fetch_map": c, "flip": float(np.nanmean(f)),
                        "fetches_mean": float(np.nanmean(c))})  # fmt: skip
        return out

    seen, unseen = half(black), half(~black)
    found = best_policy(policy_front(seen, measures), seen, measures, tolerance, z)
    pol = found["policy"]
    if pol is None:
        return None
    flip, cost = composite(pol, unseen, measures)
    within, d, se = _within(flip, unseen[found["single"]]["flip_map"], z)
    single = unseen[found["single"]]["fetches_mean"]
    return {
        "choices": pol["choices"],
        "measure": pol["measure"],
        "bounds": pol["bounds"],
        "d_flip": d,
        "se": se,
        "within": bool(within),
        "fetch_ratio": float(np.nanmean(cost) / single) if single > 0 else None,
    }


#: bands pay when the policy costs at most this share of the single point's fetches
TARGET_RATIO = 0.8


def scene_policies(exp, screen: list[dict], tolerance: float) -> dict | None:
    """The level-of-detail finding of one scene (``exp``, an ``Experiment``) from its points
    with maps (:func:`full_points`, or ``search.screen_record``s): the single points' front,
    the policies' front, and the policy of :func:`best_policy` against the cheapest point
    within ``tolerance`` of the lowest FLIP, with labels (``tradeoff_analysis.config_label``)
    in place of indices. None when fewer than two points have maps (a table measured before
    the maps were kept). ``held_out``: the choice made on half the water's blocks, scored on
    the other half (:func:`held_out`)."""
    pts = [r for r in screen if r.get("flip_map") is not None and r.get("fetch_map") is not None]
    if len(pts) < 2:
        return None
    h, w = pts[0]["flip_map"].shape
    cam = exp.section("camera")
    measures = band_measures(camera_view_proj(exp, w, h), cam["position"], w, h)
    front = policy_front(pts, measures)
    found = best_policy(front, pts, measures, tolerance)
    labels = [config_label(p) for p in pts]

    def config(i: int) -> dict:  # what draws the point again (study.studies.lod_export)
        return {"variant": pts[i]["variant"], "fitted": pts[i]["fitted"]}

    def named(pol: dict, configs: bool = False) -> dict:
        out = {k: v for k, v in pol.items() if k != "choices"}
        if configs:
            out["band_points"] = [config(c) for c in pol["choices"]]
        return {**out, "bands": [labels[c] for c in pol["choices"]]}

    def point(i: int) -> dict:
        return {"label": labels[i], "flip": pts[i]["flip"], "fetches": pts[i]["fetches_mean"],
                **config(i)}  # fmt: skip

    flips, fetches = (np.array([p[k] for p in pts]) for k in ("flip", "fetches_mean"))
    singles = _pareto(flips, fetches)
    check = held_out(pts, measures, tolerance)
    if check is not None:
        check["bands"] = [labels[c] for c in check.pop("choices")]
    return {
        "resolution": [w, h],
        "points": len(pts),
        "measures": MEASURES,
        "best": point(found["best"]),
        "single": {
            **point(found["single"]),
            "d_flip": found["single_d"][0],
            "se": found["single_d"][1],
        },  # fmt: skip
        "policy": named(found["policy"], configs=True) if found["policy"] else None,
        "fetch_ratio": found["fetch_ratio"],
        # the same policy against the lowest-FLIP point: what it saves there is partly what a
        # cheaper single point saves too
        "against_best": _against(found["policy"], pts, measures, found["best"]),
        # the same choice made on half the blocks and scored on the other half: bands pay when
        # it holds there (FLIP within one paired standard error) at TARGET_RATIO or less
        "held_out": check,
        "reaches": bool(
            check is not None
            and check["within"]
            and check["fetch_ratio"] is not None
            and check["fetch_ratio"] <= TARGET_RATIO
        ),
        "single_front": [
            {"label": labels[i], "flip": pts[i]["flip"], "fetches": pts[i]["fetches_mean"]}
            for i in singles
        ],  # fmt: skip
        "front": [named(p) for p in front],
    }


def policy_bands(exp, screen: list[dict], tolerance: float) -> list[dict]:
    """The screen points (``search.screen_record``s with maps) that the screen's chosen policy
    gives its bands (:func:`best_policy` on the screen's front): the adaptive search measures
    them in full, so that the full rung, where the policy is chosen at the experiment's
    resolution, has them. [] without maps or without a policy."""
    pts = [r for r in screen if r.get("flip_map") is not None and r.get("fetch_map") is not None]
    if len(pts) < 2:
        return []
    h, w = pts[0]["flip_map"].shape
    measures = band_measures(camera_view_proj(exp, w, h), exp.section("camera")["position"], w, h)
    found = best_policy(policy_front(pts, measures), pts, measures, tolerance)
    return [pts[c] for c in found["policy"]["choices"]] if found["policy"] else []
