"""Tests of the Dr.Jit port of ``water_refraction`` (LLVM backend, small synthetic inputs)."""

from __future__ import annotations

import warnings
from pathlib import Path

import drjit as dr
import numpy as np
import pytest

from golden.regenerate import CUSTOM, SCENES, read_exr, render_scene
from helpers.images import save_comparison
from helpers.port_checks import (
    FD_CONSTANTS,
    FD_EPS,
    assert_matches_reference,
    check_jacobian_column,
    degenerate_light_inputs,
    flat_pool,
    small_inputs,
)
from helpers.synthetic import synthetic_inputs
from shaders_port import Constants
from shaders_port.ports import water_refraction
from helpers.numpy_ref import render_reference


def _defines(reflection: bool) -> tuple:
    """The ``#define`` names of water_refraction with (True) or without its sky reflection."""
    return () if reflection else ("NOREFLECTION",)


# ---- port vs the per-pixel NumPy reference ---------------------------------------------------


@pytest.mark.parametrize("reflection", [True, False], ids=["reflection", "noreflection"])
@pytest.mark.parametrize("which", ["default", "custom"])
def test_port_matches_numpy_reference(reflection, which):
    inputs = small_inputs()
    constants = Constants() if which == "default" else CUSTOM
    out = water_refraction.render(inputs, constants, defines=_defines(reflection)).numpy()
    ref, ref_diag = render_reference("water_refraction", inputs, constants, reflection=reflection)
    assert (out["mask"] > 0).sum() > 100
    assert_matches_reference(
        "water_refraction", out, ref, ref_diag, f"water_refraction_ref_{which}_{reflection}"
    )


# ---- forward-mode derivatives vs central differences ------------------------------------

_FD_NAMES = list(FD_EPS)


@pytest.fixture(scope="module")
def jacobian():
    inputs = small_inputs()
    out, J = water_refraction.render_with_jacobian(inputs, FD_CONSTANTS, _FD_NAMES)
    return inputs, out.numpy(), J


@pytest.mark.parametrize("name", _FD_NAMES)
def test_jacobian_matches_central_differences(jacobian, name):
    inputs, base, J = jacobian
    plain = water_refraction.render(inputs, FD_CONSTANTS).numpy()
    assert np.array_equal(plain["color"], base["color"])
    check_jacobian_column(
        lambda c: water_refraction.render(inputs, c).numpy(),
        base,
        J[..., _FD_NAMES.index(name)],
        FD_CONSTANTS,
        name,
        ("iterations",),
    )


@pytest.mark.parametrize("reflection", [True, False], ids=["reflection", "noreflection"])
def test_replay_jacobian_equals_evaluated_loop_ad(jacobian, reflection):
    # loop_ad='replay' (symbolic loops, derivatives attached after the loop) against AD through
    # the unrolled loop in evaluated mode (the mode checked against finite differences)
    inputs, base, J = jacobian
    out_e, J_e = water_refraction.render_with_jacobian(
        inputs, FD_CONSTANTS, _FD_NAMES, defines=_defines(reflection), loop_ad="evaluated"
    )
    out_r, J_r = water_refraction.render_with_jacobian(
        inputs, FD_CONSTANTS, _FD_NAMES, defines=_defines(reflection)
    )
    assert np.array_equal(out_e.numpy()["color"], out_r.numpy()["color"])
    scale = np.abs(J_e).max(axis=(0, 1, 2)) + 1e-6
    assert (np.abs(J_e - J_r).max(axis=(0, 1, 2)) <= 1e-5 * scale + 1e-6).all()


def test_frozen_replay_equals_traced_render(monkeypatch):
    # plain renders replay recorded kernels (dr.freeze); a change of constants, of the loop cap
    # and of the inputs must give exactly what a freshly traced render gives
    inputs, other = small_inputs(), synthetic_inputs(width=40, height=30, seed=1)
    cases = [
        (inputs, Constants()),
        (inputs, CUSTOM),
        (inputs, Constants(steps_grazing=6.5)),
        (other, Constants(loop_cap=12)),
        (inputs, Constants()),
    ]
    frozen = [water_refraction.render(i, c).numpy() for i, c in cases]
    from shaders_port.pipeline import frame as _frame

    monkeypatch.setattr(_frame, "USE_FROZEN", False)
    for (i, c), f in zip(cases, frozen):
        t = water_refraction.render(i, c).numpy()
        for k in t:
            assert np.array_equal(t[k], f[k]), k


def test_jacobian_rejects_unknown_and_integer_names():
    with pytest.raises(ValueError, match="loop_cap"):
        water_refraction.render_with_jacobian(small_inputs(), None, ["loop_cap"])
    with pytest.raises(ValueError, match="water_color\\[4\\]"):
        water_refraction.render_with_jacobian(small_inputs(), None, ["water_color[4]"])


def test_symbolic_loop_flag_restored_after_jacobian():
    before = dr.flag(dr.JitFlag.SymbolicLoops)
    water_refraction.render_with_jacobian(small_inputs(), None, ["attenuation_distance"])
    assert dr.flag(dr.JitFlag.SymbolicLoops) == before


# ---- diagnostics on hand-checked cases --------------------------------------------------


def test_diagnostics_flat_floor_straight_down():
    # R = (0, -1, 0): numsteps = STEPS_STEEP = 3, steps of 1/3; the floor at -0.9 is crossed at
    # step 3 (y = -1); t = (cpoy - olddepth) / (cpoy - cpy) = (-2/3 + 0.9) / (1/3) = 0.7 puts the
    # interpolated point on the floor, travelLength = 0.9.
    out = water_refraction.render(flat_pool(0.9), Constants(), defines=("NOREFLECTION",)).numpy()
    c = out["mask"] > 0
    assert c.all()
    assert np.all(out["iterations"][c] == 3)
    assert np.all(out["crossed"][c] == 1)
    assert np.all(out["fetches"][c] == 4 + 1 + 3 + 1)
    np.testing.assert_allclose(out["denominator"][c], 1.0 / 3.0, rtol=2e-3)
    a = 0.9 / 7.5
    expected = (1 - a) * np.array([0.2, 0.4, 0.6]) + a * np.array([0.05, 0.25, 0.3])
    np.testing.assert_allclose(out["color"][c], np.broadcast_to(expected, (c.sum(), 3)), atol=2e-4)
    full = water_refraction.render(flat_pool(0.9), Constants()).numpy()
    assert np.all(full["fetches"][c] == 4 + 1 + 3 + 1 + 2)


def test_diagnostics_loop_cap_reached():
    out = water_refraction.render(
        flat_pool(0.9), Constants(loop_cap=2), defines=("NOREFLECTION",)
    ).numpy()
    c = out["mask"] > 0
    assert np.all(out["iterations"][c] == 2) and np.all(out["crossed"][c] == 0)
    assert np.all(np.isfinite(out["color"]))


def test_nonfinite_is_flagged_not_passed_on():
    inputs, (row, col) = degenerate_light_inputs()
    with pytest.warns(RuntimeWarning, match="1 water pixel"):
        out = water_refraction.render(inputs, Constants()).numpy()
    flagged = np.argwhere(out["nonfinite"] > 0)
    assert flagged.tolist() == [[row, col]]
    assert np.all(np.isfinite(out["color"])) and np.all(out["color"][row, col] == 0)
    ref, _ = render_reference("water_refraction", inputs, Constants())
    assert np.isnan(ref[row, col]).all()
    others = np.ones(ref.shape[:2], bool)
    others[row, col] = False
    assert np.isfinite(ref[others]).all()


def test_no_warning_and_no_nonfinite_on_normal_input():
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        out = water_refraction.render(small_inputs(), Constants()).numpy()
    assert out["nonfinite"].sum() == 0


def test_bad_constants_are_rejected_with_the_name():
    import drjit.llvm.ad as m

    with pytest.raises(ValueError, match="attenuation_distance"):
        water_refraction.render(small_inputs(), Constants(attenuation_distance=float("nan")))
    with pytest.raises(ValueError, match="refr_coeff"):
        water_refraction.render(small_inputs(), Constants(refr_coeff=m.Float(5.0)))
    with pytest.raises(ValueError, match="backend"):
        water_refraction.render(small_inputs(), Constants(), backend="metal")


# ---- golden images ----------------------------------------------------------------------


@pytest.mark.parametrize("scene", [s for s in SCENES if SCENES[s][0] == "water_refraction"])
def test_golden(scene):
    golden_path = Path(__file__).parent / "golden" / f"{scene}.exr"
    assert golden_path.is_file(), f"missing {golden_path}; run python tests/golden/regenerate.py"
    expected = read_exr(golden_path)
    actual = render_scene(scene)
    _, _, _, max_tol, mean_tol = SCENES[scene]
    err = np.abs(actual - expected)
    if not (err.max() <= max_tol and err.mean() <= mean_tol):
        save_comparison(scene, actual, expected)
    assert err.max() <= max_tol and err.mean() <= mean_tol, (
        f"{scene}: max {err.max():.3g} (<= {max_tol}), mean {err.mean():.3g} (<= {mean_tol})"
    )
