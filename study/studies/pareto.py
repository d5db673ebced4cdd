"""Pareto fronts of cost against error, and the recommendation within a tolerance.

Both axes are minimised. A point is on the front when no other point is at most as costly and at
most as wrong with one of the two strictly better (points with NaN or missing figures are never
on it). The recommendation is the cheapest point whose error is within ``tolerance`` (a fraction)
of the best error; ties in cost go to the lower error. It always lies on the front: a point
dominated by another one is either costlier than it or no better, so the dominating point is
within tolerance too and at most as costly.
"""

from __future__ import annotations

import math


def _ok(x) -> bool:
    return x is not None and isinstance(x, (int, float)) and math.isfinite(x)


def pareto_front(points: list, cost: str, error: str) -> list:
    """The non-dominated points of ``points`` (dicts), sorted by cost then error."""
    valid = [p for p in points if _ok(p.get(cost)) and _ok(p.get(error))]
    valid.sort(key=lambda p: (p[cost], p[error]))
    front, best = [], math.inf
    for p in valid:
        if p[error] < best:  # strictly better than every cheaper-or-equal point
            front.append(p)
            best = p[error]
    return front


def recommend(points: list, cost: str, error: str, tolerance: float) -> dict | None:
    """The cheapest point with ``error <= (1 + tolerance) * best error`` (None if no valid
    point)."""
    valid = [p for p in points if _ok(p.get(cost)) and _ok(p.get(error))]
    if not valid:
        return None
    if tolerance < 0:
        raise ValueError(f"tolerance must be >= 0, got {tolerance}")
    best = min(p[error] for p in valid)
    within = [p for p in valid if p[error] <= best * (1.0 + tolerance)]
    return min(within, key=lambda p: (p[cost], p[error]))
