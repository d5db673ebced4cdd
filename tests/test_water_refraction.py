"""Tests of the Dr.Jit port of ``water_refraction`` (LLVM backend, small synthetic inputs)."""

from __future__ import annotations

import warnings
from pathlib import Path

import drjit as dr
import numpy as np
import pytest

from synthetic import synthetic_inputs
from shaders_port import (
    Constants,
    ShaderInputs,
    fresnel_lut,
    ortho_tex_matrix,
    perspective_view_proj,
)
from shaders_port.ports import water_refraction
from shaders_port.ports.numpy_ref import render_reference

from regenerate import CUSTOM, SCENES, read_exr, render_scene, write_exr


def _defines(reflection: bool) -> tuple:
    """The ``#define`` names of water_refraction with (True) or without its sky reflection."""
    return () if reflection else ("NOREFLECTION",)


FAILURES = Path(__file__).parent / "_failures"
PRIMAL_ATOL = 5e-5  # port vs NumPy reference, linear RGB (both float32)
FD_RTOL, FD_NOISE = 0.1, 4e-6  # finite differences: relative truncation, float32 colour noise
FD_EPS = {  # relative step of the central differences
    "attenuation_distance": 1e-3,
    "bumptex_mult": 3e-4,
    "water_color[1]": 1e-3,
    "water_color[2]": 1e-3,
    "reflect_color[0]": 1e-3,
    "reflect_color[2]": 1e-3,
    "specular_strength": 1e-3,
    "specular_exponent": 1e-3,
    "refr_coeff": 3e-4,
    "steps_grazing": 3e-4,
    "steps_steep": 3e-4,
}
FD_CONSTANTS = Constants(attenuation_distance=2.0, specular_exponent=32.0)


def _small():
    return synthetic_inputs(width=48, height=36)


def save_failure(name: str, actual: np.ndarray, expected: np.ndarray) -> None:
    """Write the actual image and |actual - expected| to tests/_failures/ as EXR."""
    FAILURES.mkdir(exist_ok=True)
    write_exr(FAILURES / f"{name}_actual.exr", actual)
    write_exr(FAILURES / f"{name}_error.exr", np.abs(actual - expected))


def assert_matches_reference(shader: str, out: dict, ref, ref_diag, tag: str) -> None:
    err = np.abs(out["color"] - ref).max(-1)
    if not err.max() <= PRIMAL_ATOL:
        save_failure(tag, out["color"], ref)
    assert err.max() <= PRIMAL_ATOL, f"{tag}: max |port - reference| = {err.max():.3g}"
    for k, v in ref_diag.items():
        tol = 1e-6 if k == "denominator" else 0.0
        bad = np.abs(out[k] - v) > tol
        assert not bad.any(), f"{tag}: diagnostic {k} differs at {bad.sum()} pixels"


def _perturbed(constants: Constants, name: str, delta: float) -> tuple[Constants, float]:
    if name.endswith("]"):
        base, i = name[:-1].split("[")
        comps = list(getattr(constants, base))
        x = comps[int(i)]
        comps[int(i)] = x + delta * max(1.0, abs(x))
        return constants.replace(**{base: tuple(comps)}), delta * max(1.0, abs(x))
    x = getattr(constants, name)
    h = delta * max(1.0, abs(x))
    return constants.replace(**{name: x + h}), h


def check_jacobian_column(
    render,
    base: dict,
    J: np.ndarray,
    constants: Constants,
    name: str,
    decision_keys: tuple[str, ...],
) -> None:
    """Central differences of ``render`` vs the forward-mode column ``J`` for ``name``.

    Compared on water pixels whose decision diagnostics (crossing step index, ...) are equal
    at -eps, 0 and +eps and whose one-sided slopes agree (no other jump, e.g. a depth texel
    boundary under the crossing, lies within the stencil)."""
    cp, h = _perturbed(constants, name, FD_EPS[name])
    cm, _ = _perturbed(constants, name, -FD_EPS[name])
    p, m = render(cp), render(cm)
    same = base["mask"] > 0
    for k in decision_keys:
        same &= (p[k] == m[k]) & (p[k] == base[k])
    fd = (p["color"] - m["color"]) / (2 * h)
    fp, fm = (p["color"] - base["color"]) / h, (base["color"] - m["color"]) / h
    noise = FD_NOISE / h
    smooth = same & (np.abs(fp - fm) <= 0.2 * np.abs(fd) + 2 * noise).all(-1)
    assert smooth.sum() >= 0.8 * (base["mask"] > 0).sum(), (
        f"{name}: only {smooth.sum()} of {(base['mask'] > 0).sum()} water pixels are comparable"
    )
    err = np.abs(J - fd)
    bad = smooth & ~(err <= 2 * noise + FD_RTOL * np.abs(fd)).all(-1)
    assert np.abs(fd[smooth]).max() > 10 * noise, f"{name}: colour does not depend on it here"
    assert not bad.any(), (
        f"{name}: forward-mode derivative differs from central differences at "
        f"{bad.sum()} pixels (worst |err| {err.max(-1)[bad].max():.3g})"
    )


# ---- port vs the per-pixel NumPy reference ---------------------------------------------------


@pytest.mark.parametrize("reflection", [True, False], ids=["reflection", "noreflection"])
@pytest.mark.parametrize("which", ["default", "custom"])
def test_port_matches_numpy_reference(reflection, which):
    inputs = _small()
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
    inputs = _small()
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
    inputs, other = _small(), synthetic_inputs(width=40, height=30, seed=1)
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
        water_refraction.render_with_jacobian(_small(), None, ["loop_cap"])
    with pytest.raises(ValueError, match="water_color\\[4\\]"):
        water_refraction.render_with_jacobian(_small(), None, ["water_color[4]"])


def test_symbolic_loop_flag_restored_after_jacobian():
    before = dr.flag(dr.JitFlag.SymbolicLoops)
    water_refraction.render_with_jacobian(_small(), None, ["attenuation_distance"])
    assert dr.flag(dr.JitFlag.SymbolicLoops) == before


# ---- diagnostics on hand-checked cases --------------------------------------------------


def flat_pool(depth: float, normal=(0.0, 1.0, 0.0), size: int = 9, **kw) -> ShaderInputs:
    """A flat floor at y = -depth of constant colour, camera 3 units straight above it."""
    tex = 32
    x0, z0, x1, z1 = -2.0, -2.0, 2.0, 2.0
    n = np.asarray(normal, np.float32)
    nm = np.broadcast_to(0.5 * n + 0.5, (8, 8, 3)).copy()
    args = dict(
        refraction_texture=np.full((tex, tex, 3), (0.2, 0.4, 0.6), np.float32),
        world_y=np.full((tex, tex), -depth, np.float32),
        tex_matrix0=ortho_tex_matrix(x0, z0, x1, z1),
        normal_map=nm,
        cubemap=np.full((6, 4, 4, 3), 0.5, np.float32),
        fresnel_lut=fresnel_lut(),
        refl_world_y=np.full((tex, tex), -1e3, np.float32),
        refl_texture=np.zeros((tex, tex, 3), np.float32),
        tex_matrix1=ortho_tex_matrix(x0, z0, x1, z1),
        water_rect=(-1.0, -1.0, 1.0, 1.0),
        normal_tile=1.0,
        waves=np.zeros((4, 2)),
        view_proj=perspective_view_proj((0, 3, 0), (0, 0, 0), up=(0, 0, -1), fov_y_deg=2.0),
        viewpos=np.array([0.0, 3.0, 0.0]),
        lightpos=np.array([0.0, 10.0, 5.0]),
        lightcolor=np.array([1.0, 1.0, 1.0]),
        width=size,
        height=size,
    )
    args.update(kw)
    return ShaderInputs(**args)


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


def degenerate_light_inputs():
    """Light placed exactly on the surface point of one water pixel: varyingVecLight = 0 there,
    so vLight = normalize(0) is NaN (no constant within its valid range can force a NaN)."""
    from shaders_port.pipeline.raster import rasterize_water

    base = flat_pool(0.9)
    r = rasterize_water(base)
    k = len(r.index) // 2
    inputs = flat_pool(0.9, lightpos=r.world[k].astype(np.float64))
    assert np.array_equal(rasterize_water(inputs).world[k], r.world[k])
    return inputs, divmod(int(r.index[k]), inputs.width)


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
        out = water_refraction.render(_small(), Constants()).numpy()
    assert out["nonfinite"].sum() == 0


def test_bad_constants_are_rejected_with_the_name():
    import drjit.llvm.ad as m

    with pytest.raises(ValueError, match="attenuation_distance"):
        water_refraction.render(_small(), Constants(attenuation_distance=float("nan")))
    with pytest.raises(ValueError, match="refr_coeff"):
        water_refraction.render(_small(), Constants(refr_coeff=m.Float(5.0)))
    with pytest.raises(ValueError, match="backend"):
        water_refraction.render(_small(), Constants(), backend="metal")


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
        save_failure(scene, actual, expected)
    assert err.max() <= max_tol and err.mean() <= mean_tol, (
        f"{scene}: max {err.max():.3g} (<= {max_tol}), mean {err.mean():.3g} (<= {mean_tol})"
    )
