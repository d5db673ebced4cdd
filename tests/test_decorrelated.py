"""The decorrelated loss (``study.fit.decorrelated``, ``fit.input_noise = "decorrelate"``).

Its premise is checked on the ports themselves: every shader is affine in its textures, so the
residual with the mean of two textures is the mean of their residuals. Its gradient is checked
against central finite differences. Then parameter recovery: a target rendered by the port with
a clean texture, two noisy halves of that texture, and the fit on their mean is pulled off the
truth (the attenuation distance shortens to hide the noise) while the decorrelated refinement
lands on it. Last, the experiment-level errors: the option needs the lighting texture's halves.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from helpers.synthetic import synthetic_inputs
from shaders_port import Constants
from shaders_port.ports import water_reflection, water_refraction
from study.fit.calibrate import calibrate_model
from study.fit.decorrelated import decorrelated_loss, loss_grad_hessian
from study.fit.model import ShaderModel, get_value, with_values

TRUTH = Constants(
    attenuation_distance=5.0,
    bumptex_mult=0.7,
    water_color=(0.1, 0.3, 0.2, 1.0),
    specular_strength=3.0,
)
NAMES = [
    "attenuation_distance",
    "water_color[0]",
    "water_color[1]",
    "water_color[2]",
    "specular_strength",
]
NOISE = 0.1  # standard deviation of the halves' texel noise (linear RGB; the texture is 0.2-0.8)


def _halves(seed: int = 0):
    """Clean synthetic inputs and two noisy copies of them (independent noise on both textures)."""
    clean = synthetic_inputs(width=48, height=36)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(2):
        n = rng.normal(scale=NOISE, size=clean.refraction_texture.shape).astype(np.float32)
        out.append(
            dataclasses.replace(
                clean,
                refraction_texture=clean.refraction_texture + n,
                refl_texture=np.where(
                    clean.refl_world_y[..., None] > 0, clean.refl_texture + n, 0.0
                ).astype(np.float32),
            )
        )
    return clean, out


@pytest.mark.parametrize(
    "shader", [water_refraction, water_reflection], ids=lambda s: s.__name__.split(".")[-1]
)
def test_ports_are_affine_in_their_textures(shader):
    """render(mean of A, B) == mean of render(A), render(B), to float32 rounding: the premise
    that makes the decorrelated loss unbiased (a clamp of the output would break it)."""
    _, (a, b) = _halves()
    mean = dataclasses.replace(
        a,
        refraction_texture=0.5 * (a.refraction_texture + b.refraction_texture),
        refl_texture=0.5 * (a.refl_texture + b.refl_texture),
    )
    img = {
        k: shader.render(i, TRUTH).numpy()["color"] for k, i in (("a", a), ("b", b), ("mean", mean))
    }
    assert np.abs(img["a"] - img["b"]).max() > 0.05  # the noise reaches the image
    np.testing.assert_allclose(img["mean"], 0.5 * (img["a"] + img["b"]), atol=2e-5)


def test_decorrelated_gradient_matches_central_differences():
    clean, (a, b) = _halves()
    target = water_refraction.render(clean, TRUTH).numpy()["color"]
    ma, mb = (ShaderModel("water_refraction", i, target) for i in (a, b))
    at = with_values(
        TRUTH, {"attenuation_distance": 4.0, "water_color[1]": 0.25, "specular_strength": 2.5}
    )
    loss, g, h = loss_grad_hessian(ma, mb, at, NAMES)
    assert loss == pytest.approx(decorrelated_loss(ma.residual(at), mb.residual(at)), rel=1e-6)
    for i, n in enumerate(NAMES):
        step = 1e-3 * max(abs(get_value(at, n)), 0.1)
        lp, lm = (
            decorrelated_loss(ma.residual(c), mb.residual(c))
            for c in (with_values(at, {n: get_value(at, n) + s}) for s in (step, -step))
        )
        assert g[i] == pytest.approx((lp - lm) / (2 * step), rel=2e-3, abs=1e-6), n
    np.testing.assert_allclose(h, h.T)
    assert np.linalg.eigvalsh(h).min() > 0


def test_decorrelated_refinement_recovers_what_noise_biases():
    """Over three noise draws, least squares on the halves' mean shortens the attenuation distance
    by about 10 % and lifts the red water colour by 40 %; the decorrelated refinement's mean error
    is within 3 % on every one of them (what is left is its variance, which the mean of three
    draws cuts), and it reports what it did. The fit starts at the true bump scale (not fitted
    here: its loss has steps, and this test is about the texture's noise)."""
    requested = ["attenuation_distance", "water_color", "specular_strength"]
    start = Constants(bumptex_mult=TRUTH.bumptex_mult)
    names = NAMES[:4]
    errs = {"plain": [], "decorrelated": []}
    for seed in range(3):
        clean, (a, b) = _halves(seed)
        target = water_refraction.render(clean, TRUTH).numpy()["color"]
        mean = dataclasses.replace(
            a,
            refraction_texture=0.5 * (a.refraction_texture + b.refraction_texture),
            refl_texture=0.5 * (a.refl_texture + b.refl_texture),
        )
        model = ShaderModel("water_refraction", mean, target)
        halves = tuple(ShaderModel("water_refraction", i, target) for i in (a, b))
        plain = calibrate_model(model, start, requested, "levenberg_marquardt", 100)
        dec = calibrate_model(model, start, requested, "levenberg_marquardt", 100, halves=halves)
        for key, cal in (("plain", plain), ("decorrelated", dec)):
            errs[key].append([get_value(cal.fitted, n) / get_value(TRUTH, n) - 1 for n in names])
        info = dec.fit_summary["input_noise"]
        assert (
            info["accepted"] is True and info["steps"] >= 1 and info["loss"] < info["loss_start"]
        ), info
        json.loads(json.dumps(info))  # written to constants.json as it is
        assert "input_noise" not in plain.fit_summary
    plain, dec = (dict(zip(names, np.mean(errs[k], axis=0))) for k in ("plain", "decorrelated"))
    assert plain["attenuation_distance"] < -0.07 and plain["water_color[0]"] > 0.3, plain
    assert max(abs(v) for v in dec.values()) < 0.03, dec


def test_decorrelated_refinement_may_end_on_a_bound():
    """Water that absorbs no red (true red 0): least squares on the noisy mean texture lifts the
    red above 0.04; the refinement takes it to its bound 0, where its curvature leaves the
    check, and the calibration reports it on its bound."""
    truth = TRUTH.replace(water_color=(0.0, 0.3, 0.2, 1.0))
    clean, (a, b) = _halves(0)
    target = water_refraction.render(clean, truth).numpy()["color"]
    mean = dataclasses.replace(
        a,
        refraction_texture=0.5 * (a.refraction_texture + b.refraction_texture),
        refl_texture=0.5 * (a.refl_texture + b.refl_texture),
    )
    model = ShaderModel("water_refraction", mean, target)
    halves = tuple(ShaderModel("water_refraction", i, target) for i in (a, b))
    requested = ["attenuation_distance", "water_color", "specular_strength"]
    start = Constants(bumptex_mult=TRUTH.bumptex_mult)
    plain = calibrate_model(model, start, requested, "levenberg_marquardt", 100)
    dec = calibrate_model(model, start, requested, "levenberg_marquardt", 100, halves=halves)
    assert plain.parameters["water_color[0]"]["status"] == "fitted"
    assert plain.parameters["water_color[0]"]["fitted"] > 0.04
    info = dec.fit_summary["input_noise"]
    assert info["accepted"] and info["at_bound"] == {"water_color[0]": "lower"}, info
    p = dec.parameters["water_color[0]"]
    assert p["status"] == "bound" and p["fitted"] == 0.0 and "decorrelated" in p["reason"]
    assert dec.parameters["attenuation_distance"]["rel_std_error"] is not None


def test_decorrelate_needs_the_lighting_texture():
    from helpers.experiments import small_experiment
    from study.config.experiment import ExperimentError
    from study.scene.shader_inputs import half_inputs

    with pytest.raises(ExperimentError, match='texture_method = "lighting"'):
        small_experiment(
            **{"fit.input_noise": '"decorrelate"', "reference.texture_method": '"colour"'}
        )
    exp = small_experiment(**{"fit.input_noise": '"decorrelate"'})
    with pytest.raises(ExperimentError, match="two independent halves"):
        half_inputs(exp, synthetic_inputs(width=8, height=8))
