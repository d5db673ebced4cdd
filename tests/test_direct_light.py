"""The floor's direct sun- and skylight ray traced (study.scene.direct_light) against Mitsuba's own
estimate of the same terms, and the sample-for-sample subtraction the split relies on."""

import numpy as np
import pytest
from helpers.experiments import small_experiment
from helpers.images import save_failure

from study.scene import direct_light, lighting, sun_photons
from study.scene.topdown import ortho_sensor, to_gl_order, underwater_camera_height
from study.scene.user_scene import reference_sky, reference_sky_parts


def _render(mi, exp, sky, max_depth, size, spp, seed, medium=None):
    """(size, size, 6) GL-order radiance and albedo over the pool, camera under the waves."""
    scene, medium = lighting._top_down_scene(
        mi,
        exp,
        water=True,
        sky=sky,
        medium=medium,
        integrator=lighting._albedo_aov(exp, True, max_depth=max_depth),
    )
    extent = lighting.pool_extent(exp)
    sensor = ortho_sensor(
        mi, extent, size, spp, seed, y_cam=underwater_camera_height(exp), medium=medium
    )
    img = np.array(mi.render(scene, sensor=sensor, spp=spp, seed=seed), np.float32)
    return to_gl_order(mi, sensor, img, extent), medium


def test_sky_parts_add_up_to_the_reference_sky_and_the_sun_is_its_disc(mi):
    exp = small_experiment()
    sky, sun = reference_sky_parts(exp)
    np.testing.assert_allclose(sky + sun, reference_sky(exp), rtol=1e-6, atol=1e-7)
    assert sky.min() >= 0.0 and sun.min() >= 0.0
    axis, angle = sun_photons.sun_cone(sun)
    from study.scene.geometry import sun_direction

    assert (
        np.degrees(np.arccos(axis @ sun_direction(exp["sun.elevation"], exp["sun.azimuth"]))) < 0.2
    )
    # the cone holds the disc (sun.radius) and a margin of about two map texels, no more
    texel = 180.0 / sun.shape[0]
    assert exp["sun.radius"] < np.degrees(angle) < exp["sun.radius"] + 3.5 * texel
    # without a sun, no sun part
    _, none = reference_sky_parts(small_experiment(**{"sun.radiance": "[0.0, 0.0, 0.0]"}))
    assert none.max() == 0.0


def test_direct_pass_follows_the_full_pass_sample_for_sample(mi):
    """Same seed, same sensor, same envmap: the max_depth-3 render adds exactly the full render's
    direct contributions, so subtracting it leaves no negative texel (and the light that bounced,
    a fifth or more of the floor's light); with another seed it would, and that is caught."""
    exp = small_experiment()
    full, medium = _render(mi, exp, reference_sky(exp), exp["reference.max_depth"], 24, 8, 5)
    direct, _ = _render(mi, exp, reference_sky(exp), 3, 24, 8, 5, medium)
    rest = full[..., :3] - direct[..., :3]
    assert direct[..., :3].mean() > 0.5 * full[..., :3].mean()
    assert rest.min() >= -1e-5 * full.max() and rest.mean() > 0.1 * full[..., :3].mean()
    lighting._check_lockstep(rest, full[..., :3], exp)
    other, _ = _render(mi, exp, reference_sky(exp), 3, 24, 8, 6, medium)
    with pytest.raises(RuntimeError, match="same paths"):
        lighting._check_lockstep(full[..., :3] - other[..., :3], full[..., :3], exp)


def _compare(name, pt, traced, n_pass):
    """Per colour channel over the pool and in 4 x 4 texel blocks: the two estimates' means agree
    within their standard errors (from the spread of ``n_pass`` independent estimates each)."""
    size = pt[0].shape[0]

    def stats(a):
        a = np.stack(a).reshape(n_pass, size // 4, 4, size // 4, 4, 3).mean((2, 4))
        return a.mean(0), np.sqrt(a.var(0, ddof=1) / n_pass)

    (p, p_se), (t, t_se) = stats(pt), stats(traced)
    z = (t - p) / np.sqrt(p_se**2 + t_se**2)
    mean_p, mean_t = np.mean(pt, 0).mean((0, 1)), np.mean(traced, 0).mean((0, 1))
    se_mean = np.sqrt(
        np.var([a.mean((0, 1)) for a in pt], 0, ddof=1) / n_pass
        + np.var([a.mean((0, 1)) for a in traced], 0, ddof=1) / n_pass
    )
    if np.abs(z).max() > 5.0 or np.any(np.abs(mean_t - mean_p) > 3.5 * se_mean):
        save_failure(
            name,
            actual=np.mean(traced, 0),
            expected=np.mean(pt, 0),
            error=np.abs(np.mean(traced, 0) - np.mean(pt, 0)),
        )
    assert np.all(mean_t > 0.0)
    assert np.all(np.abs(mean_t - mean_p) < 3.5 * se_mean), (mean_t, mean_p, se_mean)
    assert abs(z.mean()) < 0.5 and 0.5 < z.std() < 1.6 and np.abs(z).max() < 5.0, (
        z.mean(),
        z.std(),
    )
    return np.mean(t_se), np.mean(p_se)


def _path_traced_direct(mi, exp, sky, size, spp, seeds, lighting_only=False, max_depth=3):
    """Mitsuba's estimates of the light lit by ``sky`` on paths up to ``max_depth`` (3: the
    direct term) over the pool at each seed, its radiance (or, ``lighting_only``, radiance over
    albedo) with the camera ray's absorption divided out as the lighting texture does; and a
    scene of the geometry."""
    from study.scene.topdown import camera_ray_optical_depth, top_down_world_y

    world_y = top_down_world_y(exp, lighting.pool_extent(exp), size)
    gain = np.exp(camera_ray_optical_depth(exp, underwater_camera_height(exp), world_y))
    medium, out = None, []
    for seed in seeds:
        img, medium = _render(mi, exp, sky, max_depth, size, spp, seed, medium)
        out.append(img[..., :3] / (img[..., 3:6] if lighting_only else 1.0) * gain)
    return out, lighting.lighting_scene(exp, True)[0]


def _wide_sun():
    """(experiment, its sun map, the under-water camera's height, the pool's extent) with a
    15-degree sun, wide enough that the path tracer's estimate of its light converges in a test's
    time."""
    exp = small_experiment(**{"sun.radius": "15.0"})
    return (
        exp,
        reference_sky_parts(exp)[1],
        underwater_camera_height(exp),
        lighting.pool_extent(exp),
    )


def test_traced_sunlight_matches_the_path_tracers_direct_sun(mi):
    """The light-traced direct sunlight against Mitsuba's max_depth-3 render lit by the sun alone,
    corrected for the camera ray's absorption as the lighting texture is: per colour channel over
    the pool and in 4 x 4 texel blocks, within their standard errors (a wide sun, so that the path
    tracer's estimate converges in a test's time)."""
    exp, sun, y_cam, extent = _wide_sun()
    size, spp, n_pass = 16, 256, 8
    pt, scene = _path_traced_direct(mi, exp, sun, size, spp, range(40, 40 + n_pass))
    traced = list(
        sun_photons.sun_direct(
            mi, scene, exp, sun, extent, size, 60_000, range(90, 90 + n_pass), y_cam
        )[0]
    )
    t_se, p_se = _compare("traced_sunlight", pt, traced, n_pass)
    assert t_se < 0.3 * p_se  # the light tracer is the far less noisy estimate


def test_sun_walk_matches_the_path_tracers_sunlight_bounces_included(mi):
    """All the sun's light traced from the sun (:func:`sun_photons.sun_walk`) against Mitsuba's
    full-depth render lit by the sun alone (a wide sun, so that the path tracer converges in a
    test's time): the total in 4 x 4 texel blocks within the standard errors, and the light that
    bounced (walk minus direct photons; full minus max_depth-3 render, sample for sample) over the
    pool and in its four quadrants."""
    exp, sun, y_cam, extent = _wide_sun()
    size, spp, n_pass = 16, 512, 8
    direct_pt, scene = _path_traced_direct(mi, exp, sun, size, spp, range(40, 40 + n_pass))
    full_pt = _path_traced_direct(
        mi, exp, sun, size, spp, range(40, 40 + n_pass), max_depth=exp["reference.max_depth"]
    )[0]
    seeds = range(90, 90 + n_pass)
    walk = sun_photons.sun_walk(mi, scene, exp, sun, extent, size, 100_000, seeds, y_cam)[0]
    direct = sun_photons.sun_direct(mi, scene, exp, sun, extent, size, 100_000, seeds, y_cam)[0]
    _compare("sun_walk", full_pt, list(walk), n_pass)
    quad = lambda a: np.stack(a).reshape(n_pass, 2, size // 2, 2, size // 2, 3).mean((2, 4))  # noqa: E731
    b_pt, b_walk = quad(full_pt) - quad(direct_pt), quad(walk) - quad(direct)
    se = np.sqrt(b_pt.var(0, ddof=1) / n_pass + b_walk.var(0, ddof=1) / n_pass)
    z = (b_walk.mean(0) - b_pt.mean(0)) / se
    if np.abs(z).max() > 4.0:
        save_failure(
            "sun_walk_bounce",
            actual=np.mean(walk - direct, 0),
            expected=np.mean(np.stack(full_pt) - np.stack(direct_pt), 0),
        )
    assert b_walk.mean() > 0.1 * quad(walk).mean(), "no bounced light"  # a fifth of it, measured
    assert np.abs(z).max() < 4.0, z
    pool_pt, pool_walk = b_pt.mean((1, 2)), b_walk.mean((1, 2))
    se_pool = np.sqrt(pool_pt.var(0, ddof=1) / n_pass + pool_walk.var(0, ddof=1) / n_pass)
    assert np.all(np.abs(pool_walk.mean(0) - pool_pt.mean(0)) < 3.5 * se_pool)


def test_traced_skylight_matches_the_path_tracers_direct_sky(mi):
    """The skylight gathered at the floor against Mitsuba's max_depth-3 render lit by the sky
    without the sun (its radiance over its albedo, corrected for the camera ray's absorption)."""
    exp = small_experiment()
    sky, _ = reference_sky_parts(exp)
    size, spp, n_pass = 16, 64, 8
    y_cam = underwater_camera_height(exp)
    extent = lighting.pool_extent(exp)
    pt, scene = _path_traced_direct(
        mi, exp, sky, size, spp, range(20, 20 + n_pass), lighting_only=True
    )
    traced = [
        direct_light.sky_direct(mi, scene, exp, sky, extent, size, 64, 70 + k, y_cam)
        for k in range(n_pass)
    ]
    t_se, p_se = _compare("traced_skylight", pt, traced, n_pass)
    assert t_se < 0.5 * p_se
    with pytest.raises(ValueError, match="square number"):
        direct_light.sky_direct(mi, scene, exp, sky, extent, size, 10, 0, y_cam)
    from study.config.experiment import ExperimentError

    with pytest.raises(ExperimentError, match="reference.sky_directions = 30: .*square number"):
        small_experiment(**{"reference.sky_directions": "30"})


def test_sun_below_the_horizon_lights_nothing(mi):
    exp = small_experiment()
    _, sun = reference_sky_parts(exp)
    flipped = sun[::-1].copy()  # the same disc mirrored below the horizon
    scene, _ = lighting.lighting_scene(exp, True)
    for trace in (sun_photons.sun_direct, sun_photons.sun_walk):
        img, n = trace(
            mi,
            scene,
            exp,
            flipped,
            lighting.pool_extent(exp),
            8,
            1000,
            [0, 1],
            underwater_camera_height(exp),
        )
        assert n == 0 and img.shape == (2, 8, 8, 3) and img.max() == 0.0


def test_traced_texture_keeps_the_raw_mean_and_adds_up(mi):
    """``lighting_direct = "traced"``: the texture is the bounced light (denoised) plus the traced
    direct light (sky denoised, sun raw), each denoised part matched to its raw mean, so over the
    pool the texture's mean is its halves' (raw) mean; the build reports the sky's denoiser ratio
    and the photons; outside the pool it is the dry render, as with ``"path"``; and the traced
    texture agrees with the all-path-traced one, and with the one whose sun's bounced light is
    traced from the sun (``sun_bounces = "photons"``), over the pool within their noise."""
    from study.scene.topdown import texture_extent, top_down_world_y

    base = {
        "reference.texture_size": "32",
        "reference.lighting_size": "16",
        "reference.texture_spp": "64",
        "reference.bounce_spp": "16",
        "reference.wall_spp": "16",
    }
    exp = small_experiment(**base)
    extent = texture_extent(exp)
    world_y = top_down_world_y(exp, extent, 32)
    got, info, halves = lighting.lighting_colour(exp, extent, 32, seed=2, world_y=world_y)
    assert info["direct"] == "traced" and info["spp"] == 16 and info["sun_photons_landed"] > 0
    assert all(abs(g - 1.0) < 0.05 for g in info["sky_denoise_gain"])
    X, Z = lighting.texel_centres(extent, 32)
    hx, hz = exp["pool.half_extent"]
    inside = (np.abs(X) < hx) & (np.abs(Z) < hz) & (world_y < underwater_camera_height(exp))
    np.testing.assert_allclose(got[inside].mean(0), halves.mean(0)[inside].mean(0), rtol=1e-4)
    path, info_p, _ = lighting.lighting_colour(
        small_experiment(**base, **{"reference.lighting_direct": '"path"'}),
        extent,
        32,
        seed=2,
        world_y=world_y,
    )
    assert info_p["direct"] == "path" and info_p["spp"] == 64
    outside = ~((np.abs(X) < hx) & (np.abs(Z) < hz))
    np.testing.assert_array_equal(got[outside], path[outside])
    se = np.hypot(info["noise"], info_p["noise"]) / np.sqrt(
        inside.sum() / 4.0
    )  # 2 x 2 texels per lighting texel
    assert np.all(np.abs(got[inside].mean(0) - path[inside].mean(0)) < 4.0 * se), (
        got[inside].mean(0),
        path[inside].mean(0),
        se,
    )
    # the sun's bounced light traced from the sun instead of path traced with the sky's:
    # the same light
    assert info["sun_bounces"] == "path"
    photons, info_b, _ = lighting.lighting_colour(
        small_experiment(**base, **{"reference.sun_bounces": '"photons"'}),
        extent,
        32,
        seed=2,
        world_y=world_y,
    )
    assert info_b["sun_bounces"] == "photons"
    np.testing.assert_array_equal(got[outside], photons[outside])
    se = np.hypot(info["noise"], info_b["noise"]) / np.sqrt(inside.sum() / 4.0)
    assert np.all(np.abs(got[inside].mean(0) - photons[inside].mean(0)) < 4.0 * se), (
        got[inside].mean(0),
        photons[inside].mean(0),
        se,
    )


def test_scattering_water_and_the_dry_texture_keep_the_path_traced_direct_light(mi):
    """The split holds for water that only absorbs: scattering water (``water.albedo`` > 0) and
    the dry texture path trace all of the lighting, and say so in the texture's info."""
    from study.scene.topdown import texture_extent

    base = {
        "reference.texture_size": "16",
        "reference.lighting_size": "8",
        "reference.texture_spp": "4",
        "reference.wall_spp": "4",
    }
    for extra in ({"water.albedo": "[0.5, 0.5, 0.5]"}, {"reference.refraction_lighting": '"dry"'}):
        exp = small_experiment(**base, **extra)
        _, info, _ = lighting.lighting_colour(exp, texture_extent(exp), 16, seed=0)
        assert info["direct"] == "path" and info["spp"] == 4 and "sky_directions" not in info


def test_the_camera_rays_start_where_their_absorption_is_divided_out_from(mi):
    """The under-water camera's rays start at its near clip plane, not at the camera: the texture
    divides out the absorption from there (``camera_ray_top``). Dividing it out from the camera
    itself made the path-traced lighting exp(sigma_t * 1 cm) too bright (0.25 % in red), which the
    traced skylight, computed at the floor, showed."""
    from study.scene.topdown import camera_ray_top

    exp = small_experiment()
    y_cam = underwater_camera_height(exp)
    from study.scene.topdown import ortho_sensor

    sensor = ortho_sensor(mi, lighting.pool_extent(exp), 8, 1, 0, y_cam=y_cam)
    ray, _ = sensor.sample_ray(0.0, 0.0, mi.Point2f(0.3, 0.6), mi.Point2f(0.5, 0.5))
    assert abs(float(np.array(ray.o.y).ravel()[0]) - camera_ray_top(y_cam)) < 1e-6
    assert camera_ray_top(y_cam) < y_cam
