"""Other basins of the bump scale's loss, and whether the reference's noise can tell them apart.

The bump scale (``BumptexMult``) tilts the normals that the raymarch follows, and the step at
which each ray crosses the floor jumps as it changes: the loss along it is piecewise, with
jumps, and can have several basins of nearly equal depth. A local solver stops in one of them,
and the Gauss-Newton standard error, which reads the local curvature, says nothing of the
others.

:func:`scan` evaluates the least-squares loss ``0.5 ||r||^2`` on a grid of ``POINTS`` values
within ``+- SPAN`` (relative) of the fitted value, the other constants held at the solution,
and finds the grid's local minima. For each other minimum ``b`` it compares the loss difference
``dL = L(b) - L(b0)`` with that difference's standard deviation under the reference's measured
Monte Carlo noise: with zero-mean noise ``e`` of standard deviation ``sigma`` (m,) in the target,
``L(b) - L(b0)`` moves by ``-(r(b) - r(b0)) . e`` to first order, whose standard deviation is
``||sigma * (r(b) - r(b0))||``. A basin with ``|dL| < NOISE_Z`` of those is *indistinguishable*
from the fit's: another render of the same reference could pick it; one *lower* by more than
that is a basin the local solver missed (its steps stop at a jump of the piecewise loss). The
texture's noise moves the loss too, so this is a lower bound on what the data cannot tell apart.

``study.fit.calibrate.calibrate_model`` (``scan_basins``, every ``study calibrate``) refits once
from the lowest basin that is lower beyond the noise and keeps the lower of the two solutions;
indistinguishable basins it reports (the exported value is one of them, not known to its
standard error). Where the texture has two independent halves (``reference.texture_method =
"lighting"``), a lower basin must also be lower in their *decorrelated* loss
(:func:`texture_delta`; ``study.fit.decorrelated``), whose expectation is the noise-free
texture's loss: the texture's noise, or the bias of its denoiser, can make a basin lower in
the texture's own loss and not in theirs. Such a basin is reported, not refitted. One scan
costs ``POINTS`` renders at the fit resolution.
"""

from __future__ import annotations

import numpy as np

from shaders_port import Constants

from .model import get_value, with_values

BASIN_PARAMETERS = ("bumptex_mult",)
SPAN, POINTS = 0.12, 49  # grid: +- 12 % of the fitted value in 49 points (0.5 % apart)
NOISE_Z = 2.0  # |dL| below this many noise standard deviations: indistinguishable


def local_minima(loss: np.ndarray) -> list[int]:
    """Indices of the interior local minima of a 1-D array (lower than the left neighbour, not
    higher than the right; non-finite values never are)."""
    loss = np.asarray(loss, np.float64)
    out = []
    for j in range(1, len(loss) - 1):
        if np.isfinite(loss[j]) and loss[j] < loss[j - 1] and loss[j] <= loss[j + 1]:
            out.append(j)
    return out


def loss_difference_sd(r_b: np.ndarray, r_0: np.ndarray, sigma: np.ndarray) -> float:
    """Standard deviation of ``0.5||r_b||^2 - 0.5||r_0||^2`` under independent zero-mean noise of
    standard deviation ``sigma`` (m,) in the target (first order; see the module docstring)."""
    d = np.asarray(r_b, np.float64) - np.asarray(r_0, np.float64)
    return float(np.sqrt(np.sum((np.asarray(sigma, np.float64) * d) ** 2)))


def texture_delta(model_a, model_b, at: Constants, name: str, value: float) -> float:
    """The decorrelated loss ``0.5 r_A . r_B`` (``study.fit.decorrelated``) at ``name = value``
    minus at ``at`` (the others held), on the models of the texture's two independent halves:
    the loss difference of the noise-free texture, in expectation (negative: ``value`` lower)."""
    moved = with_values(at, {name: float(value)})
    d = [
        float(
            np.asarray(model_a.residual(c), np.float64)
            @ np.asarray(model_b.residual(c), np.float64)
        )
        for c in (moved, at)
    ]
    return 0.5 * (d[0] - d[1])


def scan(
    model,
    at: Constants,
    name: str,
    sigma: np.ndarray | None = None,
    span: float = SPAN,
    points: int = POINTS,
) -> dict:
    """The loss along constant ``name`` around its value in ``at`` (others held) and its other
    basins; ``sigma``: the reference's per-residual standard error (m,) (None: no noise test).
    Returns ``{"name", "value", "grid", "loss", "basins": [{"value", "delta_loss", "noise_sd",
    "indistinguishable"}], "indistinguishable": [values], "lower": [values of basins lower than
    the fit's by more than the noise explains: the solver stopped short]}`` (JSON-ready)."""
    if points < 3 or points % 2 == 0:
        raise ValueError(
            f"points must be odd and at least 3 (the fitted value in the middle), got {points}"
        )
    v0 = get_value(at, name)
    lo, hi = model.bounds(name)
    grid = np.clip(v0 * (1.0 + np.linspace(-span, span, points)), lo, hi)
    res = [np.asarray(model.residual(with_values(at, {name: float(g)})), np.float64) for g in grid]
    loss = np.array([0.5 * float(r @ r) if np.all(np.isfinite(r)) else np.nan for r in res])
    mid = points // 2
    basins = []
    for j in local_minima(loss):
        if j == mid:
            continue
        sd = loss_difference_sd(res[j], res[mid], sigma) if sigma is not None else None
        dl = float(loss[j] - loss[mid])
        basins.append(
            {
                "value": float(grid[j]),
                "delta_loss": dl,
                "noise_sd": sd,
                "indistinguishable": bool(sd is not None and abs(dl) < NOISE_Z * sd),
            }
        )
    lower = [
        b["value"]
        for b in basins
        if b["noise_sd"] is not None and b["delta_loss"] < -NOISE_Z * b["noise_sd"]
    ]
    return {
        "name": name,
        "value": v0,
        "grid": grid.tolist(),
        "loss": loss.tolist(),
        "basins": basins,
        "indistinguishable": [b["value"] for b in basins if b["indistinguishable"]],
        "lower": lower,
    }
