"""Parameter recovery and identifiability on the real shader port (``water_refraction``).

The target image is rendered by the port itself with known constants on small synthetic
inputs (tests/synthetic.py, 48x36), so the fit has an exact answer; every solver family
starts from the shader's defaults (attenuation 7.5, BumptexMult 1, waterColor
(0.05, 0.25, 0.3)) and must find the truth. Then: the JAX bridge on the port against central
differences, the automatic freezing of what a scene cannot identify, and the step schedule,
which no gradient solver can fit and a sweep chooses instead.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from helpers.synthetic import synthetic_inputs
from shaders_port import Constants
from shaders_port.ports import water_refraction
from study.fit.calibrate import STEP_GRID, calibrate_model, make_problem, step_sweep
from study.fit.solvers import fit
from study.fit.identify import probe_gradient_solver
from study.fit.model import ShaderModel
from study.fit.model import get_value, with_values

TRUTH = Constants(attenuation_distance=5.0, bumptex_mult=0.7, water_color=(0.1, 0.3, 0.2, 1.0))
NAMES = [
    "attenuation_distance",
    "bumptex_mult",
    "water_color[0]",
    "water_color[1]",
    "water_color[2]",
]
REQUESTED = ["attenuation_distance", "bumptex_mult", "water_color", "specular_strength"]
FLAT_NORMAL = (0.5, 1.0, 0.5)  # encoded (0, 1, 0): calm water


def _inputs(**changes):
    return dataclasses.replace(synthetic_inputs(width=48, height=36), **changes)


def _model(inputs, truth: Constants) -> ShaderModel:
    target = water_refraction.render(inputs, truth).numpy()["color"]
    return ShaderModel("water_refraction", inputs, target)


def _rel_errors(values: dict, truth: Constants, names) -> dict:
    return {n: abs(values[n] - get_value(truth, n)) / abs(get_value(truth, n)) for n in names}


@pytest.fixture(scope="module")
def model():
    return _model(_inputs(), TRUTH)


# ---- recovery with every solver family ---------------------------------------------------


@pytest.mark.parametrize(
    "solver", ["levenberg_marquardt", "gauss_newton", "dogleg", "bfgs", "nelder_mead"]
)
def test_solver_recovers_known_constants(model, solver):
    """All five continuous constants from the defaults to 1e-3 relative. Nelder-Mead (NumPy,
    values only) gets a 2000-step cap and tight tolerances: on these 5 parameters it converges
    in about 300 steps (about 600 renders, under 1 s at 48x36)."""
    problem = make_problem(model, Constants(), NAMES, progress=False)
    kw = {"max_steps": 2000, "rtol": 1e-10, "atol": 1e-14} if solver == "nelder_mead" else {}
    res = fit(problem, solver=solver, **kw)
    assert res.converged, res.message
    err = _rel_errors(res.constants, TRUTH, NAMES)
    assert max(err.values()) < 1e-3, (err, res.message)
    assert res.loss < 1e-6 * res.loss_start
    if solver == "nelder_mead":
        assert res.n_jac_calls == 0
    else:
        assert res.n_jac_calls >= 1


@pytest.mark.parametrize("reverse", [True, False], ids=["reverse_loss_ad", "forward_JTr"])
def test_adam_reduces_loss(model, reverse):
    """Adam (Dr.Jit, lr 0.1 in u units, 300 iterations), looser criterion than the solvers: the
    loss drops by at least 1e3 and every constant ends within 1e-2 relative of the truth.
    ``reverse``: gradient by reverse mode through ``ShaderModel.loss_ad`` (what ``make_problem``
    hands Adam); otherwise ``J^T r`` from the forward-mode Jacobian."""
    problem = make_problem(model, Constants(), NAMES, progress=False)
    if not reverse:
        problem.loss_drjit = None
    res = fit(problem, solver="adam", max_steps=300, lr=0.1)
    assert res.loss_start / max(res.loss, 1e-300) > 1e3, (res.loss_start, res.loss, res.message)
    err = _rel_errors(res.constants, TRUTH, NAMES)
    assert max(err.values()) < 1e-2, err
    assert (res.n_grad_calls > 0) == reverse


# ---- the JAX bridge on the port ------------------------------------------------------------

SMOOTH = ["attenuation_distance", "water_color[0]", "water_color[1]", "water_color[2]"]
X0 = np.array([6.0, 0.08, 0.27, 0.25])  # travel lengths stay below 6: no attenuation clamp
BASE = Constants(bumptex_mult=0.9)


def _jax_residual(model, names):
    from study.fit.jax_residual import make_jax_residual

    def vals(x):
        return with_values(BASE, dict(zip(names, map(float, x))))

    m = model.residual(BASE).size
    return make_jax_residual(
        lambda x: model.residual(vals(x)),
        lambda x: model.residual_and_jacobian(vals(x), names),
        len(names),
        m,
    )


@pytest.mark.parametrize("jit", [False, True])
def test_bridge_jvp_on_port_matches_central_differences(model, jit):
    """jax.jvp of the port residual along t against (r(x + h t) - r(x - h t)) / 2h, h = 1e-2.
    The port computes in float32 (colour rounding ~3e-8), so h is large enough that rounding
    adds < 1e-5 relative; the constants chosen are smooth at X0."""
    import jax

    res = _jax_residual(model, SMOOTH)
    t = np.array([1.0, 0.3, -0.5, 0.7])
    f = jax.jit(res) if jit else res
    r, jt = jax.jvp(f, (jax.numpy.asarray(X0),), (jax.numpy.asarray(t),))
    h = 1e-2
    fd = (res.value(X0 + h * t) - res.value(X0 - h * t)) / (2 * h)
    # the primal of the Jacobian render may differ from a plain render by an ulp (measured:
    # 1.2e-7 on ~10% of entries when attenuation_distance is differentiated)
    np.testing.assert_allclose(np.asarray(r), res.value(X0), rtol=0, atol=1e-6)
    assert np.linalg.norm(fd) > 1.0  # a real derivative
    assert np.linalg.norm(np.asarray(jt) - fd) < 2e-3 * np.linalg.norm(fd)


def test_bridge_grad_of_loss_on_port_matches_central_differences(model):
    """jax.grad of 0.5*||r||^2 against central differences of the loss, one component at a
    time (h = 1e-2 * |x_j|)."""
    import jax
    import jax.numpy as jnp

    res = _jax_residual(model, SMOOTH)
    g = np.asarray(jax.grad(lambda x: 0.5 * jnp.sum(res(x) ** 2))(jnp.asarray(X0)))

    def loss(x):
        r = res.value(x)
        return 0.5 * float(r @ r)

    fd = np.array(
        [
            (loss(X0 + e) - loss(X0 - e)) / (2 * e[j])
            for j, e in enumerate(np.diag(1e-2 * np.abs(X0)))
        ]
    )
    assert np.all(np.abs(fd) > 1e-3), fd
    assert np.all(np.abs(g - fd) < 1e-3 * np.linalg.norm(fd)), (g, fd)


def test_bridge_jvp_bumptex_mult_matches_between_jumps(model):
    """BumptexMult moves every refracted ray, and the crossing point then jumps wherever the
    ray's crossing moves to another texel of the nearest-filtered depth texture or another
    step: a central difference over such a jump is ~jump / 2h, which AD (the derivative between
    jumps) does not see. Criterion: AD and FD (h = 1e-2 * 0.9) agree to 1e-2 of the largest
    derivative on at least 90% of the residual entries (measured: 94%), and to 1e-2 relative
    there; a zero derivative would agree on far fewer."""
    import jax

    res = _jax_residual(model, ["bumptex_mult"])
    x = np.array([0.9])
    _, jt = jax.jvp(res, (jax.numpy.asarray(x),), (jax.numpy.asarray([1.0]),))
    jt = np.asarray(jt)
    h = 1e-2 * 0.9
    fd = (res.value(x + h) - res.value(x - h)) / (2 * h)
    tol = 1e-2 * np.abs(jt).max()
    agree = np.abs(jt - fd) < tol
    assert agree.mean() >= 0.9, agree.mean()
    assert np.linalg.norm((jt - fd)[agree]) < 1e-2 * np.linalg.norm(jt[agree])
    assert (np.abs(fd) < tol).mean() < 0.5  # zero would not pass the first test


# ---- identifiability: what a scene cannot tell is frozen -----------------------------------


def _calibrate(inputs, truth):
    model = _model(inputs, truth)
    return calibrate_model(model, Constants(), REQUESTED, "levenberg_marquardt", 60)


def _check_fitted(cal, truth, names):
    for n in names:
        p = cal.parameters[n]
        assert not p["frozen"] and p["status"] == "fitted", (n, p)
        assert abs(p["fitted"] - get_value(truth, n)) < 1e-3 * abs(get_value(truth, n)), (n, p)


TRUTH_SPEC = TRUTH.replace(specular_strength=3.0)


def test_nothing_frozen_with_waves_and_light():
    """Control: with waves and a light every requested constant is identified and recovered."""
    cal = _calibrate(_inputs(), TRUTH_SPEC)
    _check_fitted(cal, TRUTH_SPEC, NAMES + ["specular_strength"])
    assert cal.fit_summary["converged"]


def test_calm_water_freezes_bumptex_mult():
    """A flat normal map (every texel (0.5, 1.0, 0.5)): BumptexMult cannot change the normal,
    so its Jacobian column is 0; it is frozen at its start with a reason about sensitivity
    while the rest is still recovered."""
    flat = np.tile(np.array(FLAT_NORMAL, np.float32), (8, 8, 1))
    cal = _calibrate(_inputs(normal_map=flat), TRUTH_SPEC)
    p = cal.parameters["bumptex_mult"]
    assert (
        p["frozen"]
        and p["status"] == "frozen"
        and p["fitted"] is None
        and "sensitivity" in p["reason"]
    ), p
    assert p["sensitivity_start"] < 1e-3
    assert cal.fitted.bumptex_mult == Constants().bumptex_mult
    _check_fitted(
        cal,
        TRUTH_SPEC,
        [
            "attenuation_distance",
            "water_color[0]",
            "water_color[1]",
            "water_color[2]",
            "specular_strength",
        ],
    )


def test_black_light_freezes_specular_strength():
    """Light colour zero: the highlight is black whatever SPECULAR_STRENGTH is."""
    cal = _calibrate(_inputs(lightcolor=np.zeros(3)), TRUTH_SPEC)
    p = cal.parameters["specular_strength"]
    assert p["frozen"] and p["fitted"] is None and "sensitivity" in p["reason"], p
    assert cal.fitted.specular_strength == Constants().specular_strength
    _check_fitted(cal, TRUTH_SPEC, NAMES)


def test_calm_experiment_freezes_bumptex_mult(mi):
    """The same through the scene: ``waves.amplitude = 0`` gives a flat normal map from
    ``build_shader_inputs``, and the calibration freezes BumptexMult."""
    from helpers.experiments import small_experiment
    from study.scene.shader_inputs import build_shader_inputs

    inputs = build_shader_inputs(small_experiment(**{"waves.amplitude": 0})).with_resolution(32, 32)
    assert np.all(inputs.normal_map == np.array(FLAT_NORMAL, np.float32))
    cal = _calibrate(inputs, TRUTH_SPEC)
    p = cal.parameters["bumptex_mult"]
    assert p["frozen"] and "sensitivity" in p["reason"], p
    _check_fitted(
        cal,
        TRUTH_SPEC,
        ["attenuation_distance", "water_color[0]", "water_color[1]", "water_color[2]"],
    )


# ---- the step schedule ---------------------------------------------------------------------

STEP_TRUTH = TRUTH.replace(steps_grazing=6.0, steps_steep=2.0)


@pytest.fixture(scope="module")
def step_problem():
    """Truth at steps (6, 2); the other constants already at the truth; start at (10, 3)."""
    model = _model(_inputs(), STEP_TRUTH)
    return make_problem(
        model, TRUTH, ["steps_grazing", "steps_steep", "attenuation_distance"], progress=False
    )


def test_gradient_solver_does_not_move_steps_grazing(step_problem):
    """Levenberg-Marquardt pointed at STEPS_GRAZING (start 10, truth 6, one scale = 5) stops
    where it starts: the loss is piecewise smooth in the step count, and the derivative AD
    gives (the derivative between jumps, nonzero: moving the step moves each crossing point
    continuously) describes neither the jumps nor the loss one scale away. Measured: moved
    0.002, loss unchanged to 1e-5; AD norm 0.45 vs 0.015 for a central difference over +-5."""
    probe = probe_gradient_solver(step_problem, "steps_grazing", solver="levenberg_marquardt")
    res = probe["fit"]
    assert probe["moved"] < 0.01 * step_problem.params["steps_grazing"].typical, probe["moved"]
    assert abs(res.constants["steps_grazing"] - 6.0) > 3.9
    assert res.loss > 0.9 * res.loss_start, (res.loss, res.loss_start)
    assert probe["fd_derivative"] > 0
    ad, fd = probe["ad_derivative"], probe["fd_derivative"]
    assert abs(ad - fd) > 0.5 * max(ad, fd), (ad, fd)


def test_steps_grazing_jumps_that_ad_misses(step_problem):
    """Per residual entry, a small central difference (h = 1e-2) agrees with AD on most water
    pixels but is far larger on some: the jumps of the crossing step."""
    vals = step_problem.start_values(None)
    _, J = step_problem.residual_and_jacobian(vals, ["steps_grazing"])
    h = 1e-2
    r_hi = np.asarray(step_problem.residual({**vals, "steps_grazing": 10.0 + h}))
    r_lo = np.asarray(step_problem.residual({**vals, "steps_grazing": 10.0 - h}))
    fd, ad = (r_hi - r_lo) / (2 * h), J[:, 0]
    tol = 1e-2 * np.abs(ad).max()
    assert (np.abs(fd - ad) < tol).mean() > 0.8
    jumps = np.abs(fd) > 10 * np.abs(ad) + 10 * tol
    assert jumps.sum() >= 1


def test_step_sweep_returns_grid_minimum(step_problem):
    """The 2-D sweep finds the truth (6, 2) on its grid, where the loss is 0 (the target was
    rendered with it); the 1-D sweep at steps_steep = 2 finds 6 too."""
    sw = step_sweep(step_problem, TRUTH, ["steps_grazing", "steps_steep"])
    grid = np.array(sw["loss"])
    assert grid.shape == (len(STEP_GRID["steps_grazing"]), len(STEP_GRID["steps_steep"]))
    i, j = np.unravel_index(np.argmin(grid), grid.shape)
    assert sw["best"] == {
        "steps_grazing": STEP_GRID["steps_grazing"][i],
        "steps_steep": STEP_GRID["steps_steep"][j],
    }
    assert sw["best"] == {"steps_grazing": 6.0, "steps_steep": 2.0}
    assert grid[i, j] < 1e-12 and np.sort(grid.ravel())[1] > 1e-4
    sw1 = step_sweep(step_problem, TRUTH.replace(steps_steep=2.0), ["steps_grazing"])
    assert sw1["best"] == {"steps_grazing": 6.0}
    assert min(sw1["loss"]) == sw1["loss"][STEP_GRID["steps_grazing"].index(6.0)]


def test_clear_water_freezes_attenuation_distance():
    """Clear water (sigma_t = 0) cannot identify an attenuation distance, whatever the Jacobian
    says: it is frozen before the fit, with the scene's reason, and never claimed as fitted."""
    from helpers.experiments import small_experiment

    from study.fit.calibrate import scene_frozen

    assert scene_frozen(small_experiment()) == {}
    why = scene_frozen(small_experiment(**{"water.sigma_t": "[0, 0, 0]"}))
    assert set(why) == {
        "attenuation_distance",
        "absorption_r",
        "absorption_g",
        "absorption_b",
    }  # seed and Beer variant
    assert "sigma_t = 0" in why["attenuation_distance"]
    cal = calibrate_model(
        _model(_inputs(), TRUTH_SPEC),
        Constants(),
        ["attenuation_distance", "bumptex_mult"],
        "levenberg_marquardt",
        100,
        frozen_by_scene=why,
    )
    p = cal.parameters["attenuation_distance"]
    assert p["status"] == "frozen" and p["fitted"] is None and "sigma_t = 0" in p["reason"]
    assert cal.fitted.attenuation_distance == Constants().attenuation_distance
    assert cal.parameters["bumptex_mult"]["status"] == "fitted"


def test_calibrate_model_with_step_counts():
    """Requesting the step counts: continuous constants by the solver, step counts by the sweep
    (status 'swept'), the sweep table in the result; and step counts alone work too."""
    truth = Constants(attenuation_distance=5.0, steps_grazing=6.0, steps_steep=2.0)
    model = _model(_inputs(), truth)
    cal = calibrate_model(
        model,
        Constants(),
        ["attenuation_distance", "steps_grazing", "steps_steep"],
        "levenberg_marquardt",
        60,
    )
    assert cal.parameters["steps_grazing"]["status"] == "swept"
    assert (cal.fitted.steps_grazing, cal.fitted.steps_steep) == (6.0, 2.0)
    assert cal.sweep["best"] == {"steps_grazing": 6.0, "steps_steep": 2.0}
    assert np.array(cal.sweep["loss"]).shape == (
        len(STEP_GRID["steps_grazing"]),
        len(STEP_GRID["steps_steep"]),
    )
    only = calibrate_model(model, Constants(), ["steps_grazing"], "levenberg_marquardt", 60)
    assert only.parameters["steps_grazing"]["status"] == "swept" and only.sweep["names"] == [
        "steps_grazing"
    ]


# ---- standard errors from the reference's noise ------------------------------------------


def test_noise_errors_match_the_spread_of_least_squares_solutions():
    """``noise_errors`` (the sandwich A diag(sigma^2) A^T) against the spread of 4000 least-squares
    solutions with heteroscedastic noise (a few pixels 30x noisier, like the sun's glitter) drawn
    in the target: within 5 % (the sampling error of a standard deviation from 4000 draws is
    about 1.1 %). ``std_errors`` reads the residual instead and misses the glitter's weight."""
    from study.fit.rounds import noise_errors, std_errors

    rng = np.random.default_rng(3)
    m, k = 600, 3
    J = rng.normal(size=(m, k))
    J[:20, 2] *= 10.0  # the third parameter is set by a few bright pixels ...
    sigma = np.full(m, 0.01)
    sigma[:20] = 0.3  # ... which are the noisy ones
    theta = np.array([2.0, -1.0, 0.5])
    sols = []
    for _ in range(4000):
        y = J @ theta + rng.normal(size=m) * sigma
        sols.append(np.linalg.lstsq(J, y, rcond=None)[0])
    spread = np.std(sols, axis=0, ddof=1) / np.abs(theta)
    predicted = np.array(noise_errors(J, sigma, theta))
    np.testing.assert_allclose(predicted, spread, rtol=0.05)
    y = J @ theta + rng.normal(size=m) * sigma
    r = J @ np.linalg.lstsq(J, y, rcond=None)[0] - y
    assert std_errors(J, r, theta)[2] < 0.5 * predicted[2]
    assert noise_errors(J[:2], sigma[:2], theta) == [None] * k


def test_tile_errors_cover_a_model_error_shared_within_tiles():
    """``tile_errors`` (the cluster sandwich over image tiles) against the spread of 2000
    least-squares solutions whose residuals share an error within each of 60 tiles (a model
    error: one offset per tile, larger than the independent noise): within 10 %, where
    ``std_errors``, which takes the residuals as independent, is under half of it. With
    independent residuals, one a tile, the two agree within 10 %."""
    from study.fit.rounds import std_errors, tile_errors

    rng = np.random.default_rng(5)
    g, per, k = 60, 20, 2
    m = g * per
    tiles = np.repeat(np.arange(g), per)
    slope = np.repeat(rng.normal(size=g), per) + 0.3 * rng.normal(size=m)  # varies by tile
    J = np.stack([np.ones(m), slope], axis=1)
    theta = np.array([1.0, 2.0])

    def solve(shared: float, noise: float):
        y = J @ theta + shared * np.repeat(rng.normal(size=g), per) + noise * rng.normal(size=m)
        est = np.linalg.lstsq(J, y, rcond=None)[0]
        return est, J @ est - y

    draws = [solve(0.1, 0.02) for _ in range(2000)]
    spread = np.std([est for est, _ in draws], axis=0, ddof=1) / np.abs(theta)
    # the sandwich's variance, averaged over 200 of the fits (one fit's has a sampling error of
    # about 1 / sqrt(2 x 60 tiles), 9 %)
    predicted = np.sqrt(
        np.mean([np.square(tile_errors(J, r, tiles, theta)) for _, r in draws[:200]], axis=0)
    )
    np.testing.assert_allclose(predicted, spread, rtol=0.1)
    est, r = draws[0]
    assert std_errors(J, r, est)[0] < 0.5 * spread[0]
    est, r = solve(0.0, 0.02)
    own = np.arange(m)  # each residual a tile of its own: the errors are independent
    np.testing.assert_allclose(tile_errors(J, r, own, est), std_errors(J, r, est), rtol=0.1)
    assert tile_errors(J, r, np.zeros(m, int), est) == [None] * k  # one tile: nothing to say


def test_calibration_reports_the_reference_noise_error():
    """With the reference's per-pixel standard error the fit reports ``rel_noise_error`` for each
    fitted constant, proportional to that error; without it, none."""
    inputs = _inputs()
    target = water_refraction.render(inputs, TRUTH).numpy()["color"]
    out = {}
    for scale in (None, 0.01, 0.02):
        se = None if scale is None else np.full(target.shape, scale, np.float32)
        model = ShaderModel("water_refraction", inputs, target, reference_stderr=se)
        cal = calibrate_model(model, Constants(), NAMES[:2], "levenberg_marquardt", 50)
        out[scale] = {n: cal.parameters[n].get("rel_noise_error") for n in NAMES[:2]}
    assert all(v is None for v in out[None].values())
    for n in NAMES[:2]:
        assert out[0.01][n] > 0
        assert out[0.02][n] == pytest.approx(2 * out[0.01][n], rel=1e-3)
    with pytest.raises(ValueError, match="reference_stderr"):
        ShaderModel(
            "water_refraction", inputs, target, reference_stderr=np.zeros((2, 2, 3), np.float32)
        )


def test_downsample_stderr_matches_the_spread_of_box_means():
    """The standard error carried through the fit's 2x2 box filter against the spread of box
    means of 4000 noisy images (unequal errors within each box): within 5 %."""
    from study._metrics import downsample, downsample_stderr

    rng = np.random.default_rng(4)
    se = rng.uniform(0.01, 0.2, size=(4, 6, 3))
    means = np.stack([downsample(rng.normal(size=se.shape) * se, 2, 2) for _ in range(4000)])
    np.testing.assert_allclose(downsample_stderr(se, 2, 2), means.std(0, ddof=1), rtol=0.05)
