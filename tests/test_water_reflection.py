"""Tests of the Dr.Jit port of ``water_reflection`` (LLVM backend, small synthetic inputs)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from shaders_port import Constants
from shaders_port.ports import water_reflection
from helpers.numpy_ref import render_reference
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


@pytest.mark.parametrize("which", ["default", "custom"])
def test_port_matches_numpy_reference(which):
    inputs = small_inputs()
    constants = Constants() if which == "default" else CUSTOM
    out = water_reflection.render(inputs, constants).numpy()
    ref, ref_diag = render_reference("water_reflection", inputs, constants)
    assert out["refl_hit"].sum() > 10, "the scene must exercise both hit and no-hit"
    assert (out["refl_hit"][out["mask"] > 0] == 0).sum() > 10
    assert_matches_reference(
        "water_reflection", out, ref, ref_diag, f"water_reflection_ref_{which}"
    )


_FD_NAMES = list(FD_EPS)


@pytest.fixture(scope="module")
def jacobian():
    inputs = small_inputs()
    out, J = water_reflection.render_with_jacobian(inputs, FD_CONSTANTS, _FD_NAMES)
    return inputs, out.numpy(), J


@pytest.mark.parametrize("name", _FD_NAMES)
def test_jacobian_matches_central_differences(jacobian, name):
    inputs, base, J = jacobian
    check_jacobian_column(
        lambda c: water_reflection.render(inputs, c).numpy(),
        base,
        J[..., _FD_NAMES.index(name)],
        FD_CONSTANTS,
        name,
        ("iterations", "refl_iterations", "refl_hit"),
    )


def test_replay_jacobian_equals_evaluated_loop_ad(jacobian):
    inputs, base, J = jacobian
    names = _FD_NAMES + ["refl_steps_grazing", "refl_steps_steep", "refl_height_cut"]
    out_e, J_e = water_reflection.render_with_jacobian(
        inputs, FD_CONSTANTS, names, loop_ad="evaluated"
    )
    out_r, J_r = water_reflection.render_with_jacobian(inputs, FD_CONSTANTS, names)
    assert np.array_equal(out_e.numpy()["color"], out_r.numpy()["color"])
    assert np.array_equal(J_r[..., : len(_FD_NAMES)], J)
    scale = np.abs(J_e).max(axis=(0, 1, 2)) + 1e-6
    assert (np.abs(J_e - J_r).max(axis=(0, 1, 2)) <= 1e-5 * scale + 1e-6).all()


def test_diagnostics_sky_straight_up():
    # flat mirror, camera straight above: R = (0, 1, 0), numsteps = REFL_STEPS_STEEP = 0.5, so the
    # first step reaches y = 2 > REFL_HEIGHT_CUT = 0.8 with nothing above: one iteration, no hit.
    out = water_reflection.render(flat_pool(0.9), Constants()).numpy()
    c = out["mask"] > 0
    assert np.all(out["refl_iterations"][c] == 1) and np.all(out["refl_hit"][c] == 0)
    assert np.all(out["iterations"][c] == 3)
    assert np.all(out["fetches"][c] == 4 + 1 + 3 + 1 + 1 + 1 + 1 + 1)


def test_diagnostics_ceiling_hit_interpolates_to_the_ceiling():
    # geometry above at y = 3 everywhere: the first step (y = 2) is below it -> hit at step 1;
    # t = (cpoy - olddepth) / (cpoy - cpy + depth - olddepth) = (0 - 3) / (0 - 2) = 1.5 -> y = 3.
    tex = 32
    inputs = flat_pool(
        0.9,
        refl_world_y=np.full((tex, tex), 3.0, np.float32),
        refl_texture=np.full((tex, tex, 3), (0.7, 0.1, 0.2), np.float32),
    )
    out = water_reflection.render(inputs, Constants(refl_height_cut=5.0)).numpy()
    sky = water_reflection.render(flat_pool(0.9), Constants(refl_height_cut=5.0)).numpy()
    c = out["mask"] > 0
    assert np.all(out["refl_iterations"][c] == 1) and np.all(out["refl_hit"][c] == 1)
    # the colour changes only through vReflection = reflectionBottom colour instead of the sky
    lut = inputs.fresnel_lut
    F_r = lut[-1, 1]  # NdotV = 1 straight down -> last LUT texel
    expected = sky["color"][c] + F_r * (np.array([0.7, 0.1, 0.2]) - 0.5)
    np.testing.assert_allclose(out["color"][c], expected, atol=1e-4)


def test_nonfinite_is_flagged():
    inputs, (row, col) = degenerate_light_inputs()
    with pytest.warns(RuntimeWarning, match="1 water pixel"):
        out = water_reflection.render(inputs, Constants()).numpy()
    assert np.argwhere(out["nonfinite"] > 0).tolist() == [[row, col]]
    assert np.all(np.isfinite(out["color"]))


@pytest.mark.parametrize("scene", [s for s in SCENES if SCENES[s][0] == "water_reflection"])
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
