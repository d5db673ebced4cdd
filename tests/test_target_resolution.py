"""A fit pixel shaded at the game's pixel footprint (``fit.target_resolution``): the factor,
the folded model against one shaded at the finer grid, its derivatives against central
differences, and parameter recovery on a target the path tracer's way (each pixel the mean of
its area) where one sample per pixel misses the highlight."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.port_checks import assert_residual_jacobian
from helpers.synthetic import FITTED
from helpers.synthetic import GLINT_START as START
from helpers.synthetic import GLINT_TRUTH as TRUTH

W, H = 48, 32  # the fit's pixels


def test_the_factor_is_the_targets_rows_over_the_fits_capped():
    from study.config.resolution import MAX_SUPERSAMPLE, supersample_factor

    assert supersample_factor([128, 128], None) == 1
    assert supersample_factor([128, 128], [256, 256]) == 2
    assert supersample_factor([128, 128], [128, 128]) == 1
    assert supersample_factor([128, 128], [64, 64]) == 1  # a coarser target: one sample
    assert supersample_factor([128, 72], [1920, 1080]) == MAX_SUPERSAMPLE == 4
    assert supersample_factor([480, 270], [1920, 1080]) == 4
    assert supersample_factor([960, 540], [1920, 1080]) == 2
    # rows, as the field of view is vertical: a wide target over a square scene
    assert supersample_factor([128, 128], [1280, 360]) == 3


def test_the_key_takes_a_preset_and_defaults_to_the_scenes_resolution():
    from study.calibration.fitting import FitOptions
    from study.config.errors import ExperimentError

    from helpers.experiments import small_experiment

    exp = small_experiment(**{"resolution": "[64, 64]", "fit.resolution": "[32, 32]"})
    assert exp.fit.target_resolution is None
    assert FitOptions.of(exp).supersample(exp) == 2  # unset: the reference's resolution
    exp = small_experiment(**{"fit.target_resolution": '"1080p"'})
    assert exp.fit.target_resolution == [1920, 1080]
    assert FitOptions.of(exp).supersample(exp) == 4
    # the screen of a sweep at a coarser resolution takes more samples per pixel
    assert FitOptions.of(exp, resolution=(16, 16)).supersample(exp) == 4
    with pytest.raises(ExperimentError, match="fit.target_resolution"):
        small_experiment(**{"fit.target_resolution": '"4k"'})


def _models(s: int):
    """(the model at W x H shading s x s samples per pixel, the model shading the same samples
    one per pixel at sW x sH), both against the same target."""
    from helpers.synthetic import synthetic_inputs
    from shaders_port import Constants
    from shaders_port.ports import water_refraction
    from study._metrics import downsample
    from study.fit.model import ShaderModel

    fine = synthetic_inputs(width=s * W, height=s * H)
    image = water_refraction.render(fine, Constants(**TRUTH)).numpy()["color"]
    target = downsample(image, s, s)
    folded = ShaderModel("water_refraction", fine, target, supersample=s)
    unfolded = ShaderModel("water_refraction", fine, image)
    return folded, unfolded


def test_a_folded_model_is_the_box_mean_of_the_finer_one_and_its_jacobian_central_differences():
    """At s = 2: the image and the Jacobian are the 2 x 2 box means of those at twice the size;
    the Jacobian matches central differences of the residual (for the constants that move no
    discrete decision); the reverse-mode loss is half the residual's squared norm."""
    import drjit as dr

    from shaders_port import Constants
    from study._metrics import downsample

    folded, unfolded = _models(2)
    c = Constants(**START)
    np.testing.assert_allclose(
        folded.render(c)[0], downsample(unfolded.render(c)[0], 2, 2), rtol=0, atol=1e-6
    )
    names = ["attenuation_distance", "water_color[1]", "specular_strength", "bumptex_mult"]
    r, J = folded.residual_and_jacobian(c, names)
    _, J_fine = unfolded._shade_with_jacobian(c, names)
    want = downsample(np.asarray(J_fine), 2, 2)[folded.mask].reshape(-1, len(names))
    np.testing.assert_allclose(J, want, rtol=1e-5, atol=1e-6)
    # the residual's two paths, and central differences of the folded residual for the
    # constants that move no discrete
    # decision (bumptex_mult moves the raymarch's crossing step: its per-sample column is
    # checked where no decision changes, helpers.port_checks.check_jacobian_column, and the
    # folded column is its box mean, above)
    steps = {"attenuation_distance": 1e-4, "water_color[1]": 1e-5, "specular_strength": 1e-3}
    assert_residual_jacobian(folded, c, steps, atol=1e-12)
    loss = folded.loss_ad(c)
    assert float(dr.ravel(loss)[0]) == pytest.approx(0.5 * float(r @ r), rel=1e-4)


def _fit(model):
    from shaders_port import Constants
    from study.fit.calibrate import calibrate_model

    return calibrate_model(model, Constants(**START), FITTED, "levenberg_marquardt", 60).fitted


def _errors(fitted) -> dict:
    from helpers.synthetic import relative_errors

    return relative_errors(fitted, TRUTH, FITTED)


def test_supersampled_fit_recovers_what_one_sample_per_pixel_misses():
    """Known truth: each target pixel is the mean over its area (4 x 4 samples) of the shader at
    TRUTH, as the path tracer's pixels are. Fitted at 4 x 4 samples per pixel, every constant is
    recovered within 1 % (measured: to the float). One sample per pixel, at the pixel's centre,
    removes the highlight (measured: specular_strength 2 -> 0, 100 % low; specular_exponent
    99 %; water_color[0] 486 %, bumptex_mult 25 %): its glints are not those the area
    averages, and the squared error prefers none."""
    from study.fit.model import ShaderModel

    folded, _ = _models(4)
    point = ShaderModel("water_refraction", folded.inputs.with_resolution(W, H), folded.reference)
    fitted_folded, fitted_point = _fit(folded), _fit(point)
    err = _errors(fitted_folded)
    assert max(err.values()) < 0.01, err
    assert fitted_point.specular_strength < 0.5 * TRUTH["specular_strength"], _errors(fitted_point)


def test_the_report_says_where_it_scored_and_what_the_fit_saw():
    """The report's line under its table: the scored resolution, the fitted constants' FLIP at
    the fit's resolution (``fit_error``), and the game's resolution when it is another."""
    from study.report.calibration import resolution_lines

    summary = {"resolution": [256, 256], "fit_resolution": [128, 128], "supersample": 2,
               "fit_error": {"flip": 0.1234, "rmse": 0.0567}}  # fmt: skip
    (line, _) = resolution_lines({**summary, "target_resolution": [256, 256]})
    assert "experiment's 256x256" in line and "fit's 128x128" in line
    assert "2x2 samples a pixel" in line and "FLIP 0.1234, RMSE 0.0567" in line
    assert "game's" not in line
    (line, _) = resolution_lines({**summary, "target_resolution": [1920, 1080]})
    assert "The game's 1920x1080 is not scored here" in line
    assert resolution_lines({k: v for k, v in summary.items() if k != "fit_error"}) == []


def test_the_fit_resolution_error_is_the_folded_image_against_the_folded_reference():
    from shaders_port import Constants
    from study._metrics import flip_map, rmse
    from study.calibration.result import fit_resolution_error

    folded, _ = _models(2)
    c = Constants(**START)
    img, _ = folded.render(c)
    got = fit_resolution_error(folded, c)
    assert got["flip"] == pytest.approx(float(flip_map(folded.reference, img)[folded.mask].mean()))
    assert got["rmse"] == pytest.approx(rmse(folded.reference, img, folded.mask))
    assert (
        0.0 < got["flip"] < 1.0 and fit_resolution_error(folded, Constants(**TRUTH))["flip"] < 1e-3
    )
