"""The transport loss (``fit.loss = "transport"``): values matched within tiles, never above the
squared error, its Jacobian against central differences, parameter recovery on a synthetic
target, and the known-truth misregistration where the squared error misses the highlight."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from helpers.port_checks import assert_residual_jacobian
from helpers.synthetic import FITTED
from helpers.synthetic import GLINT_START as START
from helpers.synthetic import GLINT_TRUTH as TRUTH

W, H = 96, 64  # the fit's pixels
S = 4  # samples a pixel side, in the target and the fit (the footprint of a 4x finer image)
HIGHLIGHT = ["specular_strength", "specular_exponent"]


class _Image:
    """A model whose image is its constants: ``residual(c) = c - reference`` over a 16 x 16
    all-water image (the transport loss needs only the model's residual, mask and tiles)."""

    def __init__(self, reference: np.ndarray):
        from study.fit.model import ReferenceModel

        self.reference = reference
        self.mask = np.ones(reference.shape[:2], bool)
        self._tiles = ReferenceModel.residual_tiles
        self._ref = reference[self.mask].ravel()

    def residual(self, image):
        return image[self.mask].ravel() - self._ref

    def residual_tiles(self, size):
        return self._tiles(self, size)


def test_a_glint_moved_within_its_tile_costs_a_quarter_of_the_squared_error():
    """The loss is a quarter the squared error, three quarters the values matched in their
    tiles: a glint moved within its tile costs a quarter of the squared error's charge (half of
    a glint removed), one moved to another tile the whole of it."""
    from study.fit.losses import TRANSPORT_LINEAR_SHARE, transformed

    assert TRANSPORT_LINEAR_SHARE == 0.25
    ref = np.full((16, 16, 3), 0.1)
    ref[2, 3] = 5.0  # a glint in the first 8 x 8 tile
    loss, lin = transformed(_Image(ref), "transport"), transformed(_Image(ref), "linear")
    within, across, removed = ref.copy(), ref.copy(), ref.copy()
    within[2, 3], within[6, 5] = 0.1, 5.0
    across[2, 3], across[2, 9] = 0.1, 5.0
    removed[2, 3] = 0.1

    def cost(model, image):
        r = model.residual(image)
        return float(r @ r) / 4.9**2  # in units of one channel of the glint

    assert cost(lin, within) == pytest.approx(6) and cost(lin, across) == pytest.approx(6)
    assert cost(lin, removed) == pytest.approx(3)
    assert cost(loss, within) == pytest.approx(0.25 * 6)
    assert cost(loss, across) == pytest.approx(6)
    assert cost(loss, removed) == pytest.approx(3)


def test_transport_never_costs_more_than_the_squared_error():
    """The sorted matching is the assignment within each tile and channel that minimises the
    squared error, so the loss is at most the squared error's, on any image."""
    from study.fit.losses import transformed

    rng = np.random.default_rng(3)
    ref = rng.gamma(0.5, 1.0, (16, 16, 3))
    lin, tr = transformed(_Image(ref), "linear"), transformed(_Image(ref), "transport")
    n = ref.size
    for _ in range(20):
        img = ref * rng.lognormal(0, 0.5, ref.shape) + rng.normal(0, 0.1, ref.shape)
        r_lin, r_tr = lin.residual(img), tr.residual(img)
        assert r_tr @ r_tr <= r_lin @ r_lin + 1e-12
        np.testing.assert_allclose(r_tr[:n], 0.5 * r_lin)
        # the matched part: per tile and channel the same values, in another order (the first
        # tile's channel 1 follows its channel 0)
        matched = r_tr[n:] / np.sqrt(0.75)
        port = img[:8, :8, 1].ravel()
        np.testing.assert_allclose(np.sort(port), np.sort(ref[:8, :8, 1].ravel()) + matched[64:128])


def _scene(shift: float):
    """(fine inputs, target): the synthetic pool at S x the fit's size, and the target at the
    fit's size, each pixel the mean of its S x S samples, of the port at TRUTH with every wave
    layer moved by ``shift`` texture units."""
    from helpers.synthetic import synthetic_inputs
    from shaders_port import Constants
    from shaders_port.ports import water_refraction
    from study._metrics import downsample

    fine = synthetic_inputs(width=S * W, height=S * H)
    moved = dataclasses.replace(fine, waves=fine.waves + shift)
    image = water_refraction.render(moved, Constants(**TRUTH)).numpy()["color"]
    return fine, downsample(image, S, S)


def _model(fine, target, loss: str):
    from study.fit.losses import transformed
    from study.fit.model import ShaderModel

    return transformed(ShaderModel("water_refraction", fine, target, supersample=S), loss)


def _fitted_errors(shift: float, loss: str) -> dict:
    from helpers.synthetic import relative_errors
    from shaders_port import Constants
    from study.fit.calibrate import calibrate_model

    model = _model(*_scene(shift), loss)
    fit = calibrate_model(model, Constants(**START), FITTED, "levenberg_marquardt", 60)
    return relative_errors(fit.fitted, TRUTH, FITTED)


def test_transport_jacobian_matches_central_differences():
    """Away from ties the sorting order is constant, so the Jacobian is the model's rows in
    that order: central differences of the residual agree with it, for the constants that move
    no discrete decision (bumptex_mult moves the raymarch's crossing step: its column is
    checked where no decision changes, helpers.port_checks.check_jacobian_column)."""
    from shaders_port import Constants

    model = _model(*_scene(0.0), "transport")
    steps = {"attenuation_distance": 1e-3, "water_color[1]": 1e-4, "specular_strength": 1e-3}
    assert_residual_jacobian(model, Constants(**START), steps, atol=1e-6)


def test_transport_recovers_the_constants_and_the_highlight_under_misregistration():
    """Known truth. Registered, the transport loss fits every constant within 1 %. With the
    target's waves moved by 0.003 texture units (0.03-0.08 of a fit pixel over the pool), the
    squared error misses the highlight (measured: specular_exponent 10 %, specular_strength
    8 %) while the transport loss recovers every constant within 5 % (measured: 4.4 %, the
    highlight's; 1.5 % with no share of the squared error, which scores a higher FLIP than this
    loss on three of the five shipped user shaders)."""
    registered = _fitted_errors(0.0, "transport")
    assert max(registered.values()) < 0.01, registered
    lin, tr = _fitted_errors(0.003, "linear"), _fitted_errors(0.003, "transport")
    assert max(lin[n] for n in HIGHLIGHT) > 0.05, lin
    assert max(tr.values()) < 0.05, tr


def test_every_loss_is_offered_by_the_key_and_named_by_the_report():
    """The registry, the key's choices and the report's words list the same losses."""
    from study.config.schema import SCHEMA
    from study.fit.losses import LOSSES
    from study.report.calibration import LOSS_WORDS

    assert set(SCHEMA["fit.loss"].choices) == set(LOSSES) == set(LOSS_WORDS)
