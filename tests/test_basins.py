"""The basin scan of the bump scale's loss (``study.fit.basins``) and the restart it triggers.

Local minima of a grid; the loss difference's standard deviation under target noise against
the spread of that difference over 4000 noise draws; the scan on the real port: its grid
centred on the fitted value, whose loss is the fit's, and the calibration's record and report;
the restart from a lower basin, kept only when its loss is lower.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers.synthetic import synthetic_inputs
from shaders_port import Constants
from shaders_port.ports import water_refraction
from study.fit.basins import NOISE_Z, POINTS, local_minima, loss_difference_sd, scan
from study.fit.calibrate import calibrate_model
from study.fit.model import ShaderModel, get_value


def test_local_minima_of_a_grid():
    loss = np.array([5.0, 3.0, 4.0, 4.0, 2.0, 2.0, 6.0, 1.0, np.nan, 0.5])
    # 1: a basin; 4: lower than its left, equal to its right (a flat floor counts once); 7 is next
    # to a NaN (never a minimum by comparison) and the ends are not interior
    assert local_minima(loss) == [1, 4]
    assert local_minima(np.array([1.0, 2.0, 3.0])) == []


def test_loss_difference_sd_matches_the_spread_over_noise_draws():
    rng = np.random.default_rng(0)
    m = 500
    target = rng.normal(size=m)
    port_0 = target + rng.normal(scale=0.3, size=m)
    port_b = target + rng.normal(scale=0.3, size=m)
    sigma = rng.uniform(0.01, 0.2, size=m)
    diffs = []
    for _ in range(4000):
        noisy = target + rng.normal(size=m) * sigma
        r0, rb = port_0 - noisy, port_b - noisy
        diffs.append(0.5 * rb @ rb - 0.5 * r0 @ r0)
    predicted = loss_difference_sd(port_b - target, port_0 - target, sigma)
    assert np.std(diffs, ddof=1) == pytest.approx(predicted, rel=0.05)


@pytest.fixture(scope="module")
def noisy_model():
    inputs = synthetic_inputs(width=48, height=36)
    truth = Constants(attenuation_distance=5.0, bumptex_mult=0.7, water_color=(0.1, 0.3, 0.2, 1.0))
    clean = water_refraction.render(inputs, truth).numpy()["color"]
    rng = np.random.default_rng(1)
    sigma = np.full(clean.shape, 0.02, np.float32)
    target = (clean + rng.normal(size=clean.shape) * sigma).astype(np.float32)
    return ShaderModel("water_refraction", inputs, target, reference_stderr=sigma)


def test_scan_is_centred_on_the_fit_and_reports_basins(noisy_model):
    requested = ["attenuation_distance", "bumptex_mult", "water_color"]
    cal = calibrate_model(
        noisy_model, Constants(), requested, "levenberg_marquardt", 100, scan_basins=True
    )
    b = cal.parameters["bumptex_mult"]["basins"]
    v = get_value(cal.fitted, "bumptex_mult")
    assert len(b["grid"]) == len(b["loss"]) == POINTS and b["grid"][POINTS // 2] == pytest.approx(v)
    r = noisy_model.residual(cal.fitted)
    assert b["loss"][POINTS // 2] == pytest.approx(0.5 * float(r @ r), rel=1e-6)
    assert min(b["grid"]) < v < max(b["grid"]) and np.all(np.isfinite(b["loss"]))
    for o in b["basins"]:
        assert o["value"] != v and o["noise_sd"] > 0
        assert o["indistinguishable"] == (abs(o["delta_loss"]) < NOISE_Z * o["noise_sd"])
    assert b["indistinguishable"] == [o["value"] for o in b["basins"] if o["indistinguishable"]]
    assert b["lower"] == [
        o["value"] for o in b["basins"] if o["delta_loss"] < -NOISE_Z * o["noise_sd"]
    ]
    # without the flag (the studies' fits) no scan is made; without a noise estimate no verdict
    plain = calibrate_model(noisy_model, Constants(), requested, "levenberg_marquardt", 100)
    assert "basins" not in plain.parameters["bumptex_mult"]
    quiet = ShaderModel("water_refraction", noisy_model.inputs, noisy_model.reference)
    s = scan(quiet, cal.fitted, "bumptex_mult")
    assert all(o["noise_sd"] is None and not o["indistinguishable"] for o in s["basins"])
    with pytest.raises(ValueError, match="odd"):
        scan(quiet, cal.fitted, "bumptex_mult", points=4)


def test_report_says_what_the_scan_found():
    from study.report.calibration import basin_lines

    params = {
        "bumptex_mult": {
            "basins": {
                "grid": [0.9, 1.0],
                "loss": [1.0, 1.0],
                "indistinguishable": [0.96],
                "basins": [
                    {
                        "value": 0.96,
                        "delta_loss": 0.004,
                        "noise_sd": 0.01,
                        "indistinguishable": True,
                    }
                ],
            }
        },
        "attenuation_distance": {},
    }
    text = "\n".join(basin_lines(params))
    assert "another basin of the loss at 0.96" in text and "cannot tell it from the fit's" in text
    params["bumptex_mult"]["basins"]["basins"][0].update(indistinguishable=False, delta_loss=0.1)
    assert "1 other local minimum of the loss" in "\n".join(basin_lines(params))
    params["bumptex_mult"]["basins"]["basins"][0]["noise_sd"] = None
    assert "no noise estimate" in "\n".join(basin_lines(params))
    params["bumptex_mult"]["basins"]["basins"][0]["noise_sd"] = 0.01
    params["bumptex_mult"]["basins"]["basins"][0].update(delta_loss=-0.1)
    params["bumptex_mult"]["basins"]["lower"] = [0.96]
    text = "\n".join(basin_lines(params))
    assert (
        "lower than the fit's by 0.1" in text
        and "stopped short" in text
        and "other local minim" not in text
    )
    # what to run: start the fit in that basin (the experiment's [constants] table by the
    # study's name; a user's shader: its own initializer)
    assert "`--set constants.bumptex_mult=0.96`" in text
    named = {"BumptexMult": {**params["bumptex_mult"], "name": "bumptex_mult"}}
    assert "`--set constants.bumptex_mult=0.96`" in "\n".join(basin_lines(named))
    user = {"uBump": params["bumptex_mult"]}
    assert "set the initializer of `uBump` in your shader to 0.96" in "\n".join(basin_lines(user))
    params["bumptex_mult"]["basins"]["basins"] = []
    assert "no other basin" in "\n".join(basin_lines(params))
    assert basin_lines({"a": {}}) == []


def test_restart_from_a_lower_basin_keeps_the_lower_solution(noisy_model, monkeypatch):
    """A scan that reports a basin lower beyond the noise (here made up at 0.9, the truth being
    0.7) makes the calibration refit from there once; whichever of the two solutions has the
    lower loss is exported, and the restart is recorded and reported."""
    from study.fit import basins, rounds  # the rounds call the scan: patched where they look
    from study.report.calibration import basin_lines

    real_scan = basins.scan
    calls = []

    def fake_scan(model, at, name, sigma=None, **kw):
        out = real_scan(model, at, name, sigma, **kw)
        if not calls:  # the first scan (the restart's) finds a lower basin
            out["basins"].append(
                {"value": 0.9, "delta_loss": -1.0, "noise_sd": 0.1, "indistinguishable": False}
            )
            out["lower"] = [0.9]
        calls.append(name)
        return out

    monkeypatch.setattr(rounds, "scan", fake_scan)
    requested = ["attenuation_distance", "bumptex_mult", "water_color"]
    first = calibrate_model(noisy_model, Constants(), requested, "levenberg_marquardt", 100)
    cal = calibrate_model(
        noisy_model, Constants(), requested, "levenberg_marquardt", 100, scan_basins=True
    )
    r = cal.parameters["bumptex_mult"]["basins"]["restart"]
    assert r["to"] == 0.9 and r["from"] == pytest.approx(
        get_value(first.fitted, "bumptex_mult"), rel=1e-6
    )
    # scanned again only where the restart moved the solution (else the first scan is reused)
    assert (
        len(calls) == (2 if r["kept"] else 1)
        and cal.fit_summary["rounds"] == first.fit_summary["rounds"] + 1
    )
    loss = 0.5 * float(np.sum(noisy_model.residual(cal.fitted) ** 2))
    assert loss == pytest.approx(min(r["loss_before"], r["loss_after"]), rel=1e-6)
    assert r["kept"] == (r["loss_after"] < r["loss_before"])
    if not r["kept"]:
        assert get_value(cal.fitted, "bumptex_mult") == get_value(first.fitted, "bumptex_mult")
    assert "refitted from there" in "\n".join(basin_lines(cal.parameters))


def _half_models(model, noise: float, seed: int):
    """Two models on independently noisy copies of ``model``'s refraction texture (the halves)."""
    import dataclasses

    rng = np.random.default_rng(seed)
    tex = np.asarray(model.inputs.refraction_texture)
    return tuple(
        ShaderModel(
            "water_refraction",
            dataclasses.replace(
                model.inputs,
                refraction_texture=(tex * (1.0 + noise * rng.standard_normal(tex.shape))).astype(
                    np.float32
                ),
            ),
            model.reference,
            reference_stderr=model.reference_stderr,
        )
        for _ in range(2)
    )


def test_texture_delta_is_the_noise_free_loss_difference(noisy_model):
    """The halves' decorrelated loss difference between two bump scales averages to the
    noise-free texture's least-squares difference (each half 30 % noisy per texel), where least
    squares on one noisy half is biased by the noise."""
    from study.fit.basins import texture_delta

    at = Constants(attenuation_distance=5.0, bumptex_mult=0.7, water_color=(0.1, 0.3, 0.2, 1.0))
    r0, r1 = (
        noisy_model.residual(c)
        for c in (
            at,
            Constants(attenuation_distance=5.0, bumptex_mult=0.8, water_color=(0.1, 0.3, 0.2, 1.0)),
        )
    )
    clean = 0.5 * float(r1 @ r1 - r0 @ r0)
    deltas = [
        texture_delta(*_half_models(noisy_model, 0.3, s), at, "bumptex_mult", 0.8) for s in range(6)
    ]
    assert clean > 0 and abs(np.mean(deltas) - clean) < 0.1 * clean, (np.mean(deltas), clean)


def test_a_lower_basin_the_texture_halves_do_not_confirm_is_reported_not_refitted(
    noisy_model, monkeypatch
):
    """The made-up lower basin at 0.9 (truth 0.7) of the restart test, with the texture's halves
    given: their decorrelated loss puts 0.9 higher, so the fit is not restarted, the basin is
    recorded as unconfirmed and the report says why; with halves that confirm it, it restarts."""
    from study.fit import basins, rounds  # the rounds call the scan: patched where they look
    from study.report.calibration import basin_lines

    real_scan = basins.scan

    def fake_scan(model, at, name, sigma=None, **kw):
        out = real_scan(model, at, name, sigma, **kw)
        out["basins"].append(
            {"value": 0.9, "delta_loss": -1.0, "noise_sd": 0.1, "indistinguishable": False}
        )
        out["lower"] = [0.9]
        return out

    monkeypatch.setattr(rounds, "scan", fake_scan)
    requested = ["attenuation_distance", "bumptex_mult", "water_color"]
    halves = _half_models(noisy_model, 0.1, 7)
    first = calibrate_model(noisy_model, Constants(), requested, "levenberg_marquardt", 100)
    cal = calibrate_model(
        noisy_model,
        Constants(),
        requested,
        "levenberg_marquardt",
        100,
        scan_basins=True,
        basin_check=halves,
    )
    b = cal.parameters["bumptex_mult"]["basins"]
    assert "restart" not in b and cal.fit_summary["rounds"] == first.fit_summary["rounds"]
    assert get_value(cal.fitted, "bumptex_mult") == get_value(first.fitted, "bumptex_mult")
    assert [o["value"] for o in b["unconfirmed"]] == [0.9] and b["unconfirmed"][0][
        "texture_delta"
    ] > 0
    text = "\n".join(basin_lines(cal.parameters))
    assert "not refitted" in text and "stopped short" not in text
    monkeypatch.setattr(rounds, "texture_delta", lambda *a, **k: -0.5)  # halves that agree
    cal = calibrate_model(
        noisy_model,
        Constants(),
        requested,
        "levenberg_marquardt",
        100,
        scan_basins=True,
        basin_check=halves,
    )
    r = cal.parameters["bumptex_mult"]["basins"]["restart"]
    assert r["to"] == 0.9 and r["texture_delta"] == -0.5
