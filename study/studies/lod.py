"""Level of detail over bands of the water: which point of the shader space (a configuration at
a step schedule) each band of pixels gets, chosen from the adaptive search's per-pixel maps.

A policy splits the water pixels by a measure of what a pixel needs (:data:`MEASURES`: its
distance to the camera, or its footprint, the world area of the water plane the pixel covers)
into 1-5 bands, at bounds taken from a grid of the measure's quantiles, and gives each band one
screen point. Its FLIP is the mean over the water of the chosen points' FLIP maps, each on its
band; its cost the mean of their texture-fetch maps alike. Both add up over the bands, so for
given bounds the front of policies (FLIP against mean fetches per water pixel) is that of a
multiple-choice knapsack, merged band by band (:func:`_merge`); the fronts of every set of
bounds, and of both measures, are merged into one.

What it does not count yet:

* each band's constants are its point's screen fit on the whole view; a fit on the band's
  pixels can only lower that band's error, so the policy's FLIP is an upper bound there;
* the seam between bands and the cost of a blend margin (pixels shaded by both points): they
  need the policy's own shader, drawn and scored.

Inputs are the screen's maps (``tradeoff_jobs.screen_job``: ``flip_map`` and ``fetch_map``,
(H, W) float32 at the screen resolution, NaN off the water) and the measure maps of
:func:`band_measures` at the same resolution.
"""

from __future__ import annotations

import itertools

import numpy as np

from shaders_port.pipeline.interpolate import plane_points

from ..scene.mitsuba_scene import camera_view_proj
from .search import paired_se
from .tradeoff_analysis import config_label
from .tradeoff_jobs import SCREEN_BLOCK, block_means

#: what decides a pixel's need: name -> what it is (units)
MEASURES = {
    "distance": "distance from the camera to the water point the pixel sees (world units)",
    "footprint": "world area of the water plane the pixel covers (square world units)",
}
#: the bounds between bands are taken at these quantiles of the measure over the water
QUANTILES = tuple(np.round(np.arange(1, 10) / 10, 2))
MAX_BANDS = 5


def band_measures(view_proj: np.ndarray, viewpos, width: int, height: int) -> dict:
    """The :data:`MEASURES` maps, (height, width) float64 each, of a camera ``view_proj``
    ((4, 4) world -> GL clip) at ``viewpos`` ((3,) world units) over the water plane y = 0,
    row 0 at the top; NaN where the pixel's ray does not meet the plane in front of the
    camera. The footprint is the area of the parallelogram spanned by the plane points a pixel
    apart in x and in y (central differences of ``plane_points``)."""
    rows, cols = np.mgrid[0:height, 0:width].astype(np.float64)
    p, t = plane_points(view_proj, width, height, cols, rows)
    dx = plane_points(view_proj, width, height, cols + 0.5, rows)[0]
    dx = dx - plane_points(view_proj, width, height, cols - 0.5, rows)[0]
    dy = plane_points(view_proj, width, height, cols, rows + 0.5)[0]
    dy = dy - plane_points(view_proj, width, height, cols, rows - 0.5)[0]
    seen = np.isfinite(t) & (t > 0)
    dist = np.linalg.norm(p - np.asarray(viewpos, np.float64), axis=-1)
    area = np.linalg.norm(np.cross(dx, dy), axis=-1)
    return {
        "distance": np.where(seen, dist, np.nan),
        "footprint": np.where(seen & np.isfinite(area), area, np.nan),
    }


def _pareto(flip: np.ndarray, cost: np.ndarray) -> np.ndarray:
    """Indices of the points no other beats in both (lower FLIP at no more cost), cheapest
    first."""
    order = np.lexsort((flip, cost))
    keep, best = [], np.inf
    for i in order:
        if flip[i] < best - 1e-15:
            keep.append(i)
            best = flip[i]
    return np.asarray(keep, dtype=np.int64)


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
    found = []
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
                for f, c, ch in zip(*front):
                    found.append(_policy(name, values, edges, ch, f / n, c / n))
    keep = _pareto(np.array([p["flip"] for p in found]), np.array([p["fetches"] for p in found]))
    return [found[i] for i in keep]


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


def _within(fmap: np.ndarray, ref: np.ndarray, z: float) -> tuple[bool, float, float]:
    """(``fmap``'s mean FLIP is above ``ref``'s by no more than ``z`` paired standard errors,
    the difference, the standard error), on the pixels both cover; 4 x 4-pixel blocks of
    both maps, as the search judges noise."""
    both = np.isfinite(fmap) & np.isfinite(ref)
    d = float(fmap[both].mean() - ref[both].mean())
    se = paired_se(block_means(np.where(both, fmap, np.nan), SCREEN_BLOCK).ravel(),
                   block_means(np.where(both, ref, np.nan), SCREEN_BLOCK).ravel())  # fmt: skip
    return d <= z * se, d, se


def best_policy(front: list[dict], points: list[dict], measures: dict, z: float = 1.0) -> dict:
    """What bands buy at the lowest FLIP a single point reaches: the cheapest single point
    and the cheapest policy of two bands or more on ``front`` (cheapest first) whose FLIP is
    above the lowest-FLIP point's by no more than ``z`` paired standard errors
    (:func:`_within`). Returns ``{"best": index of the lowest-FLIP point, "single": index of
    that cheapest point, "single_d": (difference, se), "policy": the policy with its "se" and
    "d_flip" or None, "fetch_ratio": the policy's mean fetches over the single point's (None
    without a policy)}``."""
    best = int(np.argmin([p["flip"] for p in points]))
    ref = np.asarray(points[best]["flip_map"], np.float64)
    singles = sorted(range(len(points)), key=lambda i: points[i]["fetches_mean"])
    for i in singles:
        ok, d, se = _within(np.asarray(points[i]["flip_map"], np.float64), ref, z)
        if ok:
            single, single_d = i, (d, se)
            break
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
        "single_d": single_d,
        "policy": policy,
        "fetch_ratio": float(policy["fetches"] / cost) if policy and cost > 0 else None,
    }


def held_out(points: list[dict], measures: dict, z: float = 1.0) -> dict | None:
    """The choice checked on pixels it did not see. The water's ``SCREEN_BLOCK``-pixel blocks
    are split as a checkerboard; the lowest-FLIP point, the single point and the policy are
    chosen (:func:`best_policy`) on one colour's blocks and scored on the other's. Returns
    ``{"choices", "measure", "bounds", "d_flip", "se", "within", "fetch_ratio"}``: the
    policy's FLIP minus the lowest-FLIP point's on the unseen blocks with its paired standard
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
    found = best_policy(policy_front(seen, measures), seen, measures, z)
    pol = found["policy"]
    if pol is None:
        return None
    flip, cost = composite(pol, unseen, measures)
    within, d, se = _within(flip, unseen[found["best"]]["flip_map"], z)
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


def scene_policies(exp, screen: list[dict]) -> dict | None:
    """The level-of-detail finding of one scene (``exp``, an ``Experiment``) from its screen
    records (``search.screen_record``s with maps): the single points' front, the policies'
    front, and the policy of :func:`best_policy` against the lowest-FLIP point, with labels
    (``tradeoff_analysis.config_label``) in place of indices. None when fewer than two
    points have maps (a table screened before the maps were kept). ``held_out``: the choice
    made on half the water's blocks, scored on the other half (:func:`held_out`)."""
    pts = [r for r in screen if r.get("flip_map") is not None and r.get("fetch_map") is not None]
    if len(pts) < 2:
        return None
    h, w = pts[0]["flip_map"].shape
    cam = exp.section("camera")
    measures = band_measures(camera_view_proj(exp, w, h), cam["position"], w, h)
    front = policy_front(pts, measures)
    found = best_policy(front, pts, measures)
    labels = [config_label(p) for p in pts]

    def named(pol: dict) -> dict:
        out = {k: v for k, v in pol.items() if k != "choices"}
        return {**out, "bands": [labels[c] for c in pol["choices"]]}

    def point(i: int) -> dict:
        return {"label": labels[i], "flip": pts[i]["flip"], "fetches": pts[i]["fetches_mean"]}

    flips, fetches = (np.array([p[k] for p in pts]) for k in ("flip", "fetches_mean"))
    singles = _pareto(flips, fetches)
    check = held_out(pts, measures)
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
        "policy": named(found["policy"]) if found["policy"] else None,
        "fetch_ratio": found["fetch_ratio"],
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
