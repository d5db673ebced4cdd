"""The joint (multi-scene) fit and leave-one-scene-out validation on synthetic scenes.

Two views of the synthetic pool (tests/synthetic.py, 40x30, different cameras): targets
rendered by the port with known constants, so the joint fit has an exact answer when the
scenes share their constants, and must call a constant scene-specific when they do not.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from helpers.synthetic import synthetic_inputs
from shaders_port import Constants, perspective_view_proj
from shaders_port.ports import water_refraction
from study.fit.joint import JointModel, joint_calibrate, joint_frozen, leave_one_out, universality
from study.fit.model import ShaderModel, get_value

REQUESTED = ["attenuation_distance", "bumptex_mult", "water_color"]
NAMES = [
    "attenuation_distance",
    "bumptex_mult",
    "water_color[0]",
    "water_color[1]",
    "water_color[2]",
]
SHARED = Constants(attenuation_distance=5.0, bumptex_mult=0.7, water_color=(0.1, 0.3, 0.2, 1.0))


def _view(eye, w=40, h=30):
    inputs = synthetic_inputs(width=w, height=h)
    return dataclasses.replace(
        inputs,
        viewpos=np.array(eye),
        view_proj=perspective_view_proj(eye, (0.0, -0.8, 0.0), fov_y_deg=50.0, aspect=w / h),
    )


EYES = [(0.3, 2.5, 4.5), (-2.0, 1.6, 3.5)]


def _model(inputs, truth, noise=0.0, seed=0):
    target = water_refraction.render(inputs, truth).numpy()["color"]
    if noise:
        target = target + np.random.default_rng(seed).normal(0, noise, target.shape).astype(
            np.float32
        )
    return ShaderModel("water_refraction", inputs, target)


@pytest.fixture(scope="module")
def shared_models():
    return [_model(_view(e), SHARED) for e in EYES]


def test_scenes_weighted_equally(shared_models):
    """Weighted residual of each scene: its squared norm over the mean size equals its mean
    squared error (each scene counts as one scene, whatever its pixel count)."""
    jm = JointModel(shared_models)
    assert jm.sizes[0] != jm.sizes[1]
    c = Constants()
    r = jm.residual(c)
    parts = np.split(r, np.cumsum(jm.sizes)[:-1])
    mbar = np.mean(jm.sizes)
    for part, m in zip(parts, shared_models):
        own = m.residual(c)
        assert np.isclose(part @ part / mbar, own @ own / own.size, rtol=1e-9)
    r2, J = jm.residual_and_jacobian(c, ["attenuation_distance"])
    assert np.allclose(r2, r, rtol=0, atol=1e-6) and J.shape == (r.size, 1)  # float32 AD pass


def test_joint_fit_recovers_shared_constants(shared_models):
    cal = joint_calibrate(shared_models, Constants(), REQUESTED, "levenberg_marquardt", 100)
    for n in NAMES:
        p = cal.parameters[n]
        assert p["status"] == "fitted", (n, p)
        assert abs(p["fitted"] - get_value(SHARED, n)) < 1e-3 * abs(get_value(SHARED, n)), (n, p)
    assert cal.fit_summary["converged"]


def test_joint_freezes_only_what_every_scene_freezes():
    a = {"attenuation_distance": "clear water"}
    assert joint_frozen([a, {}]) == {}
    assert set(joint_frozen([a, dict(a)])) == {"attenuation_distance"}
    with pytest.raises(ValueError, match="one shader variant"):
        m = _model(_view(EYES[0]), SHARED)
        other = ShaderModel("water_refraction_noreflection", m.inputs, m.reference)
        JointModel([m, other])


def test_leave_one_out_and_universality():
    """Scenes that disagree on the attenuation distance (4 vs 8) and share the rest, with
    independent noise (sigma 0.003) so that standard errors are meaningful: each scene's own fit
    scores best on itself, the attenuation distance is scene-specific, and the seed's
    constants score worst."""
    truths = [SHARED.replace(attenuation_distance=4.0), SHARED.replace(attenuation_distance=8.0)]
    models = [
        _model(_view(e), t, noise=0.003, seed=i) for i, (e, t) in enumerate(zip(EYES, truths))
    ]

    def evaluate(i, c):
        r = models[i].residual(c)
        return {"rmse": float(np.sqrt(np.mean(r**2)))}

    def fit_on(idx):
        return joint_calibrate([models[j] for j in idx], Constants(), REQUESTED,
                               "levenberg_marquardt", 100)  # fmt: skip

    rows = leave_one_out(["a", "b"], fit_on, evaluate, Constants(), log=lambda m: None)
    assert [r["scene"] for r in rows] == ["a", "b"]
    for row, t in zip(rows, truths):
        assert row["own"]["rmse"] < row["others"]["rmse"] < row["seed"]["rmse"], row
        own = row["own_calibration"].fitted.attenuation_distance
        assert abs(own - t.attenuation_distance) < 0.05 * t.attenuation_distance, own
    joint = joint_calibrate(models, Constants(), REQUESTED, "levenberg_marquardt", 100)
    u = universality({r["scene"]: r["own_calibration"] for r in rows}, joint)
    att = u["attenuation_distance"]
    assert att["verdict"] == "scene-specific" and att["max_abs_z"] > 10, att
    assert 4.0 < att["joint"] < 8.0
