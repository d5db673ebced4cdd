"""The refraction texture as lighting x albedo (study.scene.lighting) against the colour render."""

import numpy as np
import pytest
from helpers.experiments import small_experiment
from helpers.images import save_failure

from study.scene import lighting
from study.scene.shader_inputs import top_down_colour
from study.scene.topdown import texture_extent, top_down_world_y


def test_interpolate_reproduces_linear_functions_and_clamps():
    extent = (-2.0, -1.0, 2.0, 3.0)
    n = 8
    X, Z = lighting.texel_centres(extent, n)
    grid = np.stack([X, Z, 2 * X - Z + 1], -1)
    x = np.linspace(X.min(), X.max(), 13)
    z = np.linspace(Z.min(), Z.max(), 11)
    xx, zz = np.meshgrid(x, z)
    got = lighting.interpolate(grid, extent, xx, zz)
    np.testing.assert_allclose(got[..., 0], xx, atol=1e-5)
    np.testing.assert_allclose(got[..., 2], 2 * xx - zz + 1, atol=1e-5)
    # outside the outermost texel centres the value is that of the edge texels
    edge = lighting.interpolate(grid, extent, np.array([-2.0, 2.0]), np.array([-1.0, 3.0]))
    np.testing.assert_allclose(edge[:, 0], [X.min(), X.max()], atol=1e-5)
    np.testing.assert_allclose(edge[:, 1], [Z.min(), Z.max()], atol=1e-5)


def test_lighting_texture_matches_colour_render_within_noise(mi):
    """Same scene, same integrator: over the pool, lighting x albedo and the colour render agree
    in the mean of every tile-sized block within the measured noise (the lighting is coarser, so
    texel by texel they differ by the caustics finer than a lighting texel)."""
    exp = small_experiment(
        **{
            "reference.texture_size": "32",
            "reference.lighting_size": "16",
            "reference.texture_spp": "64",
            "reference.wall_spp": "16",
            "reference.lighting_denoise": '"none"',
        }
    )
    extent = texture_extent(exp)
    size = 32
    world_y = top_down_world_y(exp, extent, size)
    got, info, halves = lighting.lighting_colour(exp, extent, size, seed=3, world_y=world_y)
    assert info["method"] == "lighting" and info["noise"] > 0
    # undenoised, the texture is the mean of its two halves, which differ by the noise alone
    assert halves.shape == (2,) + got.shape
    np.testing.assert_allclose(halves.mean(0), got, rtol=1e-5, atol=1e-6)
    assert not np.allclose(halves[0], halves[1])
    passes = np.stack(
        [top_down_colour(exp, extent, size, 64, seed=11 + s, world_y=world_y) for s in range(4)]
    )
    want = passes.mean(0)
    se_want = np.sqrt(passes.var(0, ddof=1) / 4)
    X, Z = lighting.texel_centres(extent, size)
    hx, hz = exp["pool.half_extent"]
    inside = (np.abs(X) < hx - 0.5) & (np.abs(Z) < hz - 0.5)
    # 4 x 4 blocks of texels wholly inside the pool
    blocks = inside.reshape(8, 4, 8, 4).all((1, 3))
    g = got.reshape(8, 4, 8, 4, 3).mean((1, 3))[blocks]
    w = want.reshape(8, 4, 8, 4, 3).mean((1, 3))[blocks]
    se = np.sqrt(
        (se_want**2).reshape(8, 4, 8, 4, 3).mean((1, 3))[blocks] / 16 + (info["noise"] ** 2) / 16
    )
    z = (g - w) / se
    if np.abs(z).max() > 5.0 or abs(z.mean()) > 1.0:
        save_failure("lighting_vs_colour", actual=got, expected=want, error=np.abs(got - want))
    assert np.abs(z).max() < 5.0, f"block mean differs by {np.abs(z).max():.1f} standard errors"
    assert abs(z.mean()) < 1.0, f"mean bias {z.mean():.2f} standard errors"
    # outside the pool (the walls) the colour render is used, as before
    outside = (np.abs(X) > hx + 0.1) | (np.abs(Z) > hz + 0.1)
    assert abs(got[outside].mean() - want[outside].mean()) < 0.05 * want[outside].mean()


def test_zero_floor_albedo_is_a_clear_error(mi):
    exp = small_experiment(
        **{
            "floor.tile_albedo2": "[0.0, 0.0, 0.0]",
            "reference.texture_size": "16",
            "reference.lighting_size": "8",
            "reference.texture_spp": "4",
        }
    )
    from study.config.experiment import ExperimentError  # reported by the CLI as one line

    with pytest.raises(ExperimentError, match="zero floor albedo.*floor.tile_albedo"):
        lighting.lighting_colour(exp, texture_extent(exp), 16, seed=0)


def test_oidn_denoises_a_noisy_lighting_and_keeps_its_mean():
    """The denoiser (``reference.lighting_denoise = "oidn"``) on a synthetic floor: tile albedo
    times a smooth lighting, with Monte Carlo-like noise. It must cut the error to the truth
    several-fold, keep the mean within 2 %, and keep the tile edges (the albedo guides it)."""
    rng = np.random.default_rng(0)
    n = 128
    y, x = np.mgrid[0:n, 0:n] / n
    albedo = np.where(((x * 8).astype(int) + (y * 8).astype(int)) % 2 == 0, 0.7, 0.3)[..., None] * [
        1.0,
        0.9,
        0.8,
    ]
    light = (1.0 + 0.5 * np.sin(2 * np.pi * x) * np.cos(np.pi * y))[..., None] * [1.0, 1.0, 1.0]
    truth = (albedo * light).astype(np.float32)
    noisy = (truth * rng.gamma(4.0, 0.25, truth.shape)).astype(np.float32)  # relative noise 0.5
    out = lighting.denoise_radiance(noisy, albedo.astype(np.float32))
    assert out.shape == truth.shape and out.dtype == np.float32 and np.all(np.isfinite(out))
    err_in = np.sqrt(np.mean((noisy - truth) ** 2))
    err_out = np.sqrt(np.mean((out - truth) ** 2))
    if err_out > err_in / 4:
        save_failure("oidn_lighting", actual=out, expected=truth, error=np.abs(out - truth))
    assert err_out < err_in / 4, f"denoised error {err_out:.4f} vs input {err_in:.4f}"
    assert abs(out.mean() / truth.mean() - 1) < 0.02
    # the lighting recovered by dividing out the albedo is smooth across the tile edges
    rec = out / albedo
    assert np.sqrt(np.mean((rec - light) ** 2)) < 0.1 * light.mean()


def test_denoise_gain_measures_a_brightness_bias_with_its_standard_error():
    """``lighting.denoise_gain``: over independent noise draws of a raw lighting, the ratio's
    spread matches the standard error it reports (within 15 %), and a denoiser that brightens the
    red channel by 6 % is measured at 1.06 within three of those standard errors."""
    rng = np.random.default_rng(1)
    n = 64
    y, x = np.mgrid[0:n, 0:n] / n
    truth = (1.0 + 0.4 * np.sin(2 * np.pi * x) * np.cos(np.pi * y))[..., None] * [0.2, 0.5, 0.9]
    sd = 0.3 * truth  # per-texel standard error of the raw mean
    gains, ses = [], []
    for _ in range(300):
        raw = truth + sd * rng.standard_normal(truth.shape)
        g, e = lighting.denoise_gain(truth, raw, sd)  # a perfect denoiser: the truth itself
        gains.append(g)
        ses.append(e)
    gains, ses = np.array(gains), np.array(ses)
    assert np.all(np.abs(gains.mean(0) - 1.0) < 3 * ses.mean(0) / np.sqrt(len(gains)) + 1e-4)
    ratio = gains.std(0, ddof=1) / ses.mean(0)
    assert np.all(np.abs(ratio - 1.0) < 0.15), ratio
    raw = truth + sd * rng.standard_normal(truth.shape)
    g, e = lighting.denoise_gain(truth * [1.06, 1.0, 1.0], raw, sd)
    assert abs(g[0] - 1.06) < 3 * e[0] and abs(g[1] - 1.0) < 3 * e[1] and abs(g[2] - 1.0) < 3 * e[2]
    assert e[0] < 0.01  # precise enough to see a 6 % bias
    dark = truth * [0.0, 1.0, 1.0]  # a channel without light: nothing to match
    g, e = lighting.denoise_gain(dark, dark, sd * [0.0, 1.0, 1.0])
    assert g[0] == 1.0 and e[0] == 0.0 and np.all(np.isfinite(g + e))


def test_denoised_texture_keeps_the_raw_mean_and_reports_the_denoiser_bias(mi):
    """``reference.lighting_denoise = "oidn"``: the denoised texture's mean over the pool is the
    raw mean of the same samples in every colour channel (the path tracer's brightness), the
    denoiser's own ratio is reported, and ``"oidn_unmatched"`` keeps it: its texture's mean over
    the pool is the raw one times that ratio; outside the pool both are the dry render."""
    base = {
        "reference.texture_size": "32",
        "reference.lighting_size": "16",
        "reference.texture_spp": "16",
        "reference.wall_spp": "16",
        "reference.lighting_direct": '"path"',
    }
    exp = small_experiment(**base, **{"reference.lighting_denoise": '"oidn"'})
    raw_exp = small_experiment(**base, **{"reference.lighting_denoise": '"oidn_unmatched"'})
    extent = texture_extent(exp)
    world_y = top_down_world_y(exp, extent, 32)
    got, info, halves = lighting.lighting_colour(exp, extent, 32, seed=2, world_y=world_y)
    kept, info_u, _ = lighting.lighting_colour(raw_exp, extent, 32, seed=2, world_y=world_y)
    X, Z = lighting.texel_centres(extent, 32)
    hx, hz = exp["pool.half_extent"]
    inside = (np.abs(X) < hx) & (np.abs(Z) < hz) & (world_y < 0.0)
    raw_mean = halves.mean(0)[inside].mean(0)
    np.testing.assert_allclose(got[inside].mean(0), raw_mean, rtol=1e-4)
    assert info["denoise_matched"] and "denoise_matched" not in info_u
    np.testing.assert_allclose(info["denoise_gain"], info_u["denoise_gain"], rtol=1e-6)
    np.testing.assert_allclose(
        kept[inside].mean(0), raw_mean * np.array(info_u["denoise_gain"]), rtol=1e-4
    )
    assert all(0 < e < 0.1 for e in info["denoise_gain_se"])
    outside = ~((np.abs(X) < hx) & (np.abs(Z) < hz))
    np.testing.assert_array_equal(got[outside], kept[outside])


def test_dry_render_denoised_outside_the_pool_keeps_its_raw_mean_there():
    """``reference.wall_denoise = "oidn"``: the dry render's noise (5-8 % per texel at 16 spp)
    cut by more than half outside the pool, its mean there equal to the raw mean per colour channel,
    the denoiser's own brightness reported."""
    rng = np.random.default_rng(1)
    n = 96
    y, x = np.mgrid[0:n, 0:n] / n
    outside = (np.abs(x - 0.5) > 0.38) | (np.abs(y - 0.5) > 0.38)  # a ring of walls' tops
    albedo = np.where(
        outside, 0.6, np.where(((x * 8).astype(int) + (y * 8).astype(int)) % 2 == 0, 0.7, 0.3)
    )
    albedo = (albedo[..., None] * [1.0, 0.95, 0.9]).astype(np.float32)
    truth = (albedo * (1.2 + 0.3 * x[..., None])).astype(np.float32)
    noisy = (truth * rng.gamma(200.0, 1 / 200.0, truth.shape)).astype(
        np.float32
    )  # relative noise 7 %
    out, info = lighting.denoise_dry(noisy, albedo, outside)
    assert out.shape == truth.shape and out.dtype == np.float32
    np.testing.assert_allclose(out[outside].mean(0), noisy[outside].mean(0), rtol=1e-5)
    err_in = np.sqrt(np.mean((noisy - truth)[outside] ** 2))
    err_out = np.sqrt(np.mean((out - truth)[outside] ** 2))
    assert err_out < err_in / 2, (err_out, err_in)  # measured: 2.4x less
    assert len(info["wall_denoise_gain"]) == 3 and all(
        abs(g - 1.0) < 0.05 for g in info["wall_denoise_gain"]
    )
