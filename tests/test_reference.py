"""Reference cache: keyed on everything that affects the image, atomic, provenance in the EXR;
noise measured from independent passes."""

import numpy as np
import pytest
from helpers.experiments import small_experiment

from study import read_exr
from study.scene.reference import load_or_render, noise_of, reference_key


def test_cache_hit_miss_and_provenance(mi, tmp_path):
    exp = small_experiment()
    logs = []
    a = load_or_render(exp, "llvm_ad_rgb", cache=tmp_path, log=logs.append)
    assert "rendered" in logs[-1]
    rgb, prov, extra = read_exr(a.path)
    assert prov["key"] == reference_key(exp, "llvm_ad_rgb") and prov["spp"] == 16
    assert {"versions", "render_seconds", "noise", "scene_hash", "variant", "seed"} <= set(prov)
    assert prov["spp_asked"] == 16 and prov["spp_per_pass"] * prov["n_seeds"] == prov["spp"]
    assert "reference: rendered 16 spp in" in logs[-1]  # as asked: no note
    assert prov["noise"] > 0 and np.isfinite(rgb).all()
    b = load_or_render(exp, "llvm_ad_rgb", cache=tmp_path, log=logs.append)
    assert "cached" in logs[-1]
    np.testing.assert_array_equal(a.image, b.image)
    np.testing.assert_array_equal(a.stderr, b.stderr)
    # any scene change is a different key, never the stale file
    changed = small_experiment(**{"water.sigma_t": "[0.3, 0.06, 0.04]"})
    assert reference_key(changed, "llvm_ad_rgb") != reference_key(exp, "llvm_ad_rgb")
    c = load_or_render(changed, "llvm_ad_rgb", cache=tmp_path, log=logs.append)
    assert "rendered" in logs[-1] and c.path != a.path
    assert not np.array_equal(c.image, a.image)
    # a fit-only change keeps the key
    same = small_experiment(**{"fit.solver": "bfgs"})
    assert reference_key(same, "llvm_ad_rgb") == reference_key(exp, "llvm_ad_rgb")


def test_foreign_or_corrupt_cache_file_is_not_reused(mi, tmp_path):
    exp = small_experiment()
    a = load_or_render(exp, "llvm_ad_rgb", cache=tmp_path, log=lambda m: None)
    a.path.write_bytes(b"truncated")
    logs = []
    b = load_or_render(exp, "llvm_ad_rgb", cache=tmp_path, log=logs.append)
    assert any("unreadable" in m for m in logs) and np.isfinite(b.image).all()
    # a valid EXR whose recorded key differs (e.g. copied from elsewhere) is not trusted
    from study import write_exr

    write_exr(b.path, b.image, dict(b.provenance, key="someone-else"), extra={"stderr": b.stderr})
    logs = []
    load_or_render(exp, "llvm_ad_rgb", cache=tmp_path, log=logs.append)
    assert any("does not match" in m for m in logs)


def test_killed_render_leaves_no_cache_file(mi, tmp_path, monkeypatch):
    import study.scene.reference as R

    exp = small_experiment()

    def killed(*a, **k):
        raise KeyboardInterrupt("killed")

    monkeypatch.setattr(R, "render_passes", killed)
    with pytest.raises(KeyboardInterrupt):
        load_or_render(exp, "llvm_ad_rgb", cache=tmp_path, log=lambda m: None)
    assert not list(tmp_path.rglob("*.exr"))


def test_noise_estimate_scales_with_spp(mi):
    """Measured noise follows 1/sqrt(spp) (independent sampler and seeds), within sampling error."""
    from study.scene.reference import render_passes, water_mask

    exp = small_experiment(**{"reference.sampler": '"independent"'})
    mask = water_mask(exp, 32, 32)
    _, n4 = noise_of(render_passes(exp, 4, 6, seed0=100), mask)
    _, n64 = noise_of(render_passes(exp, 64, 6, seed0=200), mask)
    ratio = n4 / n64
    assert 2.0 < ratio < 8.0, ratio  # ideal 4.0; heavy-tailed paths widen the spread


def test_pass_spp_rounds_to_the_samplers_grid():
    from study.scene.reference import N_SEEDS, pass_spp

    counts = (1, 16, 64, 128, 1024)
    mj = small_experiment(**{"reference.sampler": '"multijitter"'})
    strat = small_experiment(**{"reference.sampler": '"stratified"'})
    ind = small_experiment(**{"reference.sampler": '"independent"'})
    assert N_SEEDS == 4
    assert [pass_spp(mj, s) for s in counts] == [1, 4, 16, 35, 256]  # a x b, b = floor(sqrt)
    assert [pass_spp(strat, s) for s in counts] == [1, 4, 16, 36, 256]
    assert [pass_spp(ind, s) for s in counts] == [1, 4, 16, 32, 256]


def test_spp_text_says_why_a_count_was_rounded_up():
    from study.scene.reference import spp_text

    prov = {"spp": 140, "spp_asked": 128, "spp_per_pass": 35, "n_seeds": 4}
    assert spp_text({**prov, "sampler": "multijitter"}) == (
        "140 spp (128 asked, rounded up to 4 passes of 35 for the multijitter sampler)"
    )
    assert spp_text({**prov, "spp": 128, "spp_per_pass": 32, "sampler": "independent"}) == (
        "128 spp"
    )
    assert spp_text({"spp": 140}) == "140 spp"  # a reference rendered before spp_asked


@pytest.mark.parametrize("sampler", ["multijitter", "stratified", "independent"])
def test_sampler_spp_is_mitsubas_own_count(mi, sampler):
    """``sampler_spp`` predicts the count the pinned Mitsuba's sampler takes (perfect cubes,
    squares and everything between), so the spp recorded in a reference's provenance is the one
    rendered and Mitsuba never rounds (and warns) behind the study's back."""
    from study.scene.mitsuba_scene import sampler_spp

    for spp in list(range(1, 130)) + [216, 255, 256, 343, 512, 1000, 1024]:
        s = mi.load_dict({"type": sampler, "sample_count": sampler_spp(sampler, spp)})
        assert s.sample_count() == sampler_spp(sampler, spp) >= spp, (sampler, spp)


def test_reference_sampler_draws_uncorrelated_dimensions(mi):
    """The default reference sampler's successive dimensions are uncorrelated: a path tracer
    assumes it, and Mitsuba's ``stratified`` sampler (permutations with consecutive seeds per
    dimension) breaks it, which biased the volumetric reference (deep chromatic water about 1 %
    too bright). The stratified sampler is the positive control: the same measurement finds its
    correlation (about -0.01 at 36 spp)."""
    from study.config.experiment import SCHEMA
    from study.scene.mitsuba_scene import dimension_correlation

    default = SCHEMA["reference.sampler"].default
    assert default == "multijitter"
    r, se = dimension_correlation(mi, default, 36)
    assert abs(r) < max(4 * se, 2e-3), (r, se)
    r_strat, se_strat = dimension_correlation(mi, "stratified", 36)
    assert r_strat < -5e-3 and r_strat < -4 * se_strat, (r_strat, se_strat)


def test_reference_sampler_is_unbiased_and_less_noisy(mi):
    """The default (multi-jittered) sampler against the independent one on the same scene at
    equal spp: the two means agree within their measured standard errors (no bias), and the
    jittered passes' measured noise is lower (on the default scene at 256x256 its variance is
    2.8x lower; here, at 32x32 with 16 spp per pass, its RMS noise is about 1.2x lower: the bound
    1.1 leaves the RMS's own sampling error, about 2 % over these water pixels)."""
    from study.scene.reference import render_reference

    jit = render_reference(small_experiment(**{"reference.spp": "64"}), "llvm_ad_rgb")
    ind = render_reference(
        small_experiment(**{"reference.spp": "64", "reference.sampler": '"independent"'}),
        "llvm_ad_rgb",
    )
    assert jit.spp == ind.spp == 64
    assert jit.noise * 1.1 < ind.noise, (jit.noise, ind.noise)
    diff = jit.image - ind.image
    se = np.sqrt(jit.stderr**2 + ind.stderr**2)
    # the mean difference over the image in units of its standard error: a bias shows as |z| >> 1
    z = diff.sum() / np.sqrt((se**2).sum())
    assert abs(z) < 4.0, z


def test_noise_of_known_gaussian():
    rng = np.random.default_rng(1)
    passes = rng.normal(0.5, 0.2, size=(8, 64, 64, 3))
    se, rms = noise_of(passes, np.ones((64, 64), bool))
    assert rms == pytest.approx(0.2 / np.sqrt(8), rel=0.03)
    with pytest.raises(ValueError, match="at least two"):
        noise_of(passes[:1], np.ones((64, 64), bool))


def test_auto_spp_reaches_target(mi):
    from study.scene.reference import N_SEEDS, PILOT_SPP, choose_spp

    exp = small_experiment(
        **{"reference.spp": '"auto"', "reference.target_noise": "0.02", "reference.max_spp": "4096"}
    )
    spp, info = choose_spp(exp)
    assert info["pilot_spp"] == N_SEEDS * PILOT_SPP  # K passes of PILOT_SPP (8: a 4 x 2 grid)
    assert spp >= info["predicted_spp"] and spp < 2 * info["predicted_spp"] + 8
    loose = small_experiment(**{"reference.spp": '"auto"', "reference.target_noise": "0.2"})
    assert choose_spp(loose)[0] < spp


def test_shader_inputs_cache(mi, tmp_path):
    from study.scene.shader_inputs import load_or_build_shader_inputs

    exp = small_experiment()
    logs = []
    a = load_or_build_shader_inputs(exp, "llvm_ad_rgb", cache=tmp_path, log=logs.append)
    assert "built" in logs[-1]
    b = load_or_build_shader_inputs(exp, "llvm_ad_rgb", cache=tmp_path, log=logs.append)
    assert "cached" in logs[-1]
    np.testing.assert_array_equal(a.refraction_texture, b.refraction_texture)
    np.testing.assert_array_equal(a.view_proj, b.view_proj)
    # a key that changes only the inputs (not the reference) is a different entry
    assert exp["reference.fresnel_transmission"] == "radiance"
    c = load_or_build_shader_inputs(
        small_experiment(**{"reference.fresnel_transmission": '"energy"'}),
        "llvm_ad_rgb",
        cache=tmp_path,
        log=logs.append,
    )
    assert "built" in logs[-1]
    np.testing.assert_allclose(c.fresnel_lut[:, 0], a.fresnel_lut[:, 0] * 1.333**2, rtol=1e-6)
    # so is a changed lighting resolution of the refraction texture: a new render, never a stale one
    load_or_build_shader_inputs(
        small_experiment(**{"reference.lighting_size": "16"}),
        "llvm_ad_rgb",
        cache=tmp_path,
        log=logs.append,
    )
    assert "built" in logs[-1] and "lighting texture" in logs[-1]
    # a corrupt file is rebuilt, not trusted
    for p in (tmp_path / "inputs").glob("*.npz"):
        p.write_bytes(b"garbage")
    load_or_build_shader_inputs(exp, "llvm_ad_rgb", cache=tmp_path, log=logs.append)
    assert any("unreadable" in m for m in logs) and "built" in logs[-1]
