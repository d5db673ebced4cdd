"""One constants block for several scenes: the joint fit and leave-one-scene-out validation.

A game ships one constants block for many views. :class:`JointModel` stacks the residuals of
several :class:`~study.fit.model.ShaderModel` s (one per experiment, same shader variant) so
that :func:`~study.fit.calibrate.calibrate_model` fits them as one problem, unchanged: same
identifiability, bounds, standard errors and stopping rule. Each scene is weighted equally,
whatever its number of water pixels: scene ``i``'s residual (``m_i`` entries) is multiplied by
``sqrt(m_mean / m_i)``, so the joint loss is ``m_mean/2 * sum_i mean_i(r^2)`` (the sum of the
scenes' mean squared errors, scaled to the size of one scene).

:func:`joint_frozen` merges the scenes' physics freezes (a constant is frozen only when *no*
scene can identify it: clear water alone cannot fix the attenuation distance, but with a murky
scene beside it the joint fit can). :func:`leave_one_out` fits on all scenes but one and
scores the left-out scene under the seed's constants, the others' fit and its own fit.
:func:`universality` says which constants are universal: each scene's own fitted value within
``Z_UNIVERSAL = 2`` of its standard errors of the joint value (a two-sided ~95 % test; the
standard errors are Gauss-Newton ones, lower bounds under correlated model error, so "scene-
specific" is the safer verdict).
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from shaders_port import Constants

from .calibrate import Calibration, calibrate_model
from .model import get_value

Z_UNIVERSAL = 2.0


class JointModel:
    """Stacked, equally weighted residuals of ``models`` (same ``shader``: hand ports or a
    user's shader through SPIR-V), a :class:`~study.fit.protocol.CalibrationModel`: the
    parameters, their ranges and start constants are the first model's."""

    def __init__(self, models: list, names: list[str] | None = None):
        if len(models) < 1:
            raise ValueError("a joint fit needs at least one scene")
        shaders = {m.shader for m in models}
        if len(shaders) != 1:
            raise ValueError(
                f"a joint fit needs one shader variant for all scenes, got {sorted(shaders)}; "
                "set the same fit.shader in every experiment"
            )
        self.models = list(models)
        self.names = list(names) if names else [f"scene{i}" for i in range(len(models))]
        self.shader = models[0].shader
        sizes = np.array([3 * int(m.mask.sum()) for m in models], np.float64)
        self.sizes = sizes.astype(int).tolist()
        self.weights = np.sqrt(sizes.mean() / sizes)

    @property
    def label(self) -> str:
        return self.models[0].label

    @property
    def defines(self) -> list[str]:
        return self.models[0].defines

    @property
    def reference_stderr(self):
        return None  # the scenes' noise is not stacked: no noise errors for a joint fit

    def parameter_names(self, requested):
        return self.models[0].parameter_names(requested)

    def bounds(self, name: str) -> tuple[float, float]:
        return self.models[0].bounds(name)

    def start_constants(self, exp=None):
        return self.models[0].start_constants(exp)

    def residual(self, constants: Constants) -> np.ndarray:
        """(sum m_i,) float64: each scene's residual times its weight."""
        return np.concatenate(
            [w * m.residual(constants) for w, m in zip(self.weights, self.models)]
        )

    def residual_tiles(self) -> np.ndarray:
        """(sum m_i,) int: each scene's image tiles (``residual_tiles``), numbered apart."""
        out, offset = [], 0
        for m in self.models:
            t = np.asarray(m.residual_tiles())
            out.append(t + offset)
            offset += int(t.max()) + 1 if len(t) else 0
        return np.concatenate(out)

    def residual_and_jacobian(self, constants: Constants, names: list[str]):
        rs, Js = [], []
        for w, m in zip(self.weights, self.models):
            r, J = m.residual_and_jacobian(constants, names)
            rs.append(w * r)
            Js.append(w * J)
        return np.concatenate(rs), np.concatenate(Js, axis=0)

    def normal_equations(self, constants: Constants, names: list[str]):
        """The scenes' weighted normal equations summed (``study.fit.normal_equations``): those
        of the stacked residual."""
        total = None
        for w, m in zip(self.weights, self.models):
            ne = m.normal_equations(constants, names).weighted(w)
            total = ne if total is None else total + ne
        return total

    def loss_ad(self, constants: Constants):
        total = None
        for w, m in zip(self.weights, self.models):
            li = float(w) ** 2 * m.loss_ad(constants)
            total = li if total is None else total + li
        return total


def joint_frozen(frozen_per_scene: list[dict]) -> dict:
    """Name -> reason for the constants that *every* scene freezes by its physics."""
    if not frozen_per_scene:
        return {}
    common = set(frozen_per_scene[0]).intersection(*map(set, frozen_per_scene[1:]))
    return {
        n: "every scene of the joint fit freezes it: " + frozen_per_scene[0][n]
        for n in sorted(common)
    }


def joint_calibrate(
    models: list,
    start: Constants,
    requested: list[str],
    solver: str,
    max_steps: int,
    frozen_per_scene: list[dict] | None = None,
    names: list[str] | None = None,
) -> Calibration:
    """The joint fit: :func:`calibrate_model` on the :class:`JointModel` of ``models``."""
    return calibrate_model(
        JointModel(models, names),
        start,
        requested,
        solver,
        max_steps,
        frozen_by_scene=joint_frozen(frozen_per_scene or [{} for _ in models]),
    )


def leave_one_out(
    names: list[str],
    fit_on: Callable[[list[int]], Calibration],
    evaluate: Callable[[int, Constants], dict],
    start: Constants,
    log: Callable = print,
) -> list[dict]:
    """For each scene ``i`` of ``names``: fit on the others and on ``i`` alone
    (``fit_on(indices) -> Calibration``: the same fit for both, one scene or several) and score
    ``i`` with ``evaluate(i, constants) -> {"rmse": .., "flip": ..}`` under the seed's
    (``start``), the others' and its own constants. Returns one dict per scene with the three
    scores and both calibrations (``own``: :class:`Calibration`, ``others``:
    :class:`Calibration` or None for a single scene)."""
    n = len(names)
    rows = []
    for i in range(n):
        log(f"generalise: scene {names[i]} ({i + 1}/{n}): own fit")
        own = fit_on([i])
        others = None
        if n > 1:
            log(f"generalise: scene {names[i]}: fit on the other {n - 1} scenes")
            others = fit_on([j for j in range(n) if j != i])
        rows.append(
            {
                "scene": names[i],
                "seed": evaluate(i, start),
                "others": evaluate(i, others.fitted) if others is not None else None,
                "own": evaluate(i, own.fitted),
                "own_calibration": own,
                "others_calibration": others,
            }
        )
    return rows


def universality(own: dict, joint: Calibration, z: float = Z_UNIVERSAL) -> dict:
    """Which constants are universal. ``own``: scene name -> :class:`Calibration` of that scene
    alone; ``joint``: the joint fit. For each constant fitted in the joint fit: every scene's own
    value and absolute standard error, ``z_i = (v_i - v_joint) / se_i``, and a verdict:
    ``universal`` (all scenes fitted it and all ``|z_i| <= z``), ``scene-specific`` (some
    ``|z_i| > z``), or ``undetermined`` (fewer than two scenes fitted it with a standard error).
    """
    out = {}
    for n, jp in joint.parameters.items():
        if jp["status"] != "fitted":
            continue
        vj = get_value(joint.fitted, n)
        per = {}
        for scene, cal in own.items():
            p = cal.parameters.get(n, {})
            rse = p.get("rel_std_error")
            if p.get("status") == "fitted" and rse is not None and math.isfinite(rse):
                v = get_value(cal.fitted, n)
                se = rse * abs(v)
                per[scene] = {"value": v, "se": se, "z": (v - vj) / se if se > 0 else math.inf}
            else:
                per[scene] = {
                    "value": p.get("fitted"),
                    "status": p.get("status"),
                    "se": None,
                    "z": None,
                }
        zs = [d["z"] for d in per.values() if d.get("z") is not None]
        if len(zs) < 2:
            verdict = "undetermined"
        elif all(abs(q) <= z for q in zs) and len(zs) == len(per):
            verdict = "universal"
        elif any(abs(q) > z for q in zs):
            verdict = "scene-specific"
        else:
            verdict = "undetermined"
        out[n] = {
            "joint": vj,
            "scenes": per,
            "max_abs_z": max((abs(q) for q in zs), default=None),
            "verdict": verdict,
        }
    return out
