"""reflection = box, the local cube map of Lagarde and Zanuttini: the box projection's geometry,
the port against llvmpipe, its derivatives against central differences, its fetches, and the
cube map captured from the Mitsuba scene."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from helpers.experiments import small_experiment
from helpers.gl import check_gl_match, compare_or_skip
from helpers.port_checks import VARIANT_CUSTOM as CUSTOM
from helpers.port_checks import assert_variant_jacobian_columns
from helpers.synthetic import synthetic_box_inputs, synthetic_inputs

from shaders_port import space as _space
from shaders_port.variants import get_variant


def test_the_lookup_points_from_the_capture_at_the_wall_the_ray_leaves_through():
    import drjit as dr

    from shaders_port.pipeline.texture import backend_types
    from shaders_port.ports.box import BoxProbe, box_lookup

    m = backend_types("llvm")
    box = BoxProbe(None, (-2.0, -1.6, -3.0), (2.0, 0.6, 3.0), (0.3, 0.6, -0.2))
    rng = np.random.default_rng(1)
    n = 400
    origin = np.stack([rng.uniform(-1.9, 1.9, n), np.zeros(n), rng.uniform(-2.9, 2.9, n)], -1)
    R = rng.normal(size=(n, 3))
    R[:, 1] = np.abs(R[:, 1]) * rng.choice([0.05, 1.0], n) + 1e-3
    R /= np.linalg.norm(R, axis=-1, keepdims=True)
    d = box_lookup(m, box, m.Array3f(origin.T), m.Array3f(R.T))
    d = np.stack([np.array(d[k]) for k in range(3)], -1).astype(np.float64)
    # where the ray leaves the box: the nearest side plane, or the top
    lo, hi = np.array(box.boxMin), np.array(box.boxMax)
    t = (np.where(R > 0, hi, lo) - origin) / R
    t_side = t[:, [0, 2]].min(-1)
    hit = origin + t_side[:, None] * R
    wall = hit[:, 1] < hi[1]
    assert 50 < wall.sum() < n - 50  # both exits drawn
    assert np.allclose(d[wall], hit[wall] - np.array(box.boxCapturePosition), atol=1e-4)
    assert np.allclose(d[~wall], R[~wall], atol=1e-6)
    assert dr.all(dr.isfinite(m.Float(d.ravel())))


@pytest.mark.parametrize(
    "name", ["water_refraction_box", "water_refraction_box_beer_ggx_walls_secant_2layers"]
)
def test_the_box_reflection_matches_opengl(name):
    v = get_variant(name)
    assert "BOX_REFLECTION" in v.defines and "box_cubemap" in v.inputs
    res = compare_or_skip(synthetic_box_inputs(96, 72), CUSTOM, name)
    check_gl_match(res, f"gl_box_{name}")
    assert res["n_nonfinite"] == 0


def test_the_box_projection_moves_the_walls_only():
    # the original shader reading the same cube map along R: the two agree where the reflected
    # ray leaves through the box's open top (the sky), and differ where it meets a wall
    inputs = synthetic_box_inputs(64, 48)
    same = dataclasses.replace(inputs, cubemap=inputs.box_cubemap)
    box = get_variant("water_refraction_box").render(inputs, CUSTOM).numpy()
    cube = get_variant("water_refraction").render(same, CUSTOM).numpy()
    water = box["mask"] > 0
    changed = np.abs(box["color"] - cube["color"]).max(-1)[water] > 1e-3
    assert 0.05 < changed.mean() < 0.95, changed.mean()
    assert np.array_equal(box["fetches"][water], cube["fetches"][water])  # one cube fetch each


def test_the_box_derivatives_match_central_differences():
    v = get_variant("water_refraction_box_beer_walls")
    inputs = synthetic_box_inputs(48, 36)
    assert_variant_jacobian_columns(v, inputs, CUSTOM, ["bumptex_mult", "reflect_color[1]"])


def test_without_its_inputs_the_box_reflection_says_how_to_build_them():
    v = get_variant("water_refraction_box")
    with pytest.raises(ValueError, match="box_cubemap.*with_box_inputs"):
        v.render(synthetic_inputs(32, 24), CUSTOM)


def test_the_search_and_the_sources_reach_the_box():
    near = {_space.name_of(n) for n in _space.neighbours(_space.ORIGINAL)}
    assert "water_refraction_box" in near  # a one-axis neighbour: screened, and in the report
    assert _space.ALONE["Lagarde and Zanuttini (local cube map)"] == {"reflection": "box"}
    assert _space.choices_of("water_refraction_box_beer_walls")["reflection"] == "box"


@pytest.fixture(scope="module")
def captured(mi, tmp_path_factory):
    from study.scene import box_inputs as B
    from study.scene.shader_inputs import build_shader_inputs

    exp = small_experiment()
    base = build_shader_inputs(exp)
    cache = tmp_path_factory.mktemp("cache")
    logs = []
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(B, "BOX_CUBE_SIZE", 32)
        mp.setattr(B, "BOX_SPP", 2)
        mp.setattr(B, "BOX_BAND_SPP", 16)
        inputs = B.with_box_inputs(exp, base, "llvm_ad_rgb", cache=cache, log=logs.append)
        again = B.with_box_inputs(exp, base, "llvm_ad_rgb", cache=cache, log=logs.append)
    return exp, inputs, again, logs


def test_the_cube_map_is_the_dry_scene_seen_from_the_walls_top(captured):
    from study.scene.geometry import cubemap_directions
    from study.scene.user_scene import shader_cubemap

    exp, inputs, again, logs = captured
    assert any("built and cached" in m for m in logs) and "cached" in logs[-1]
    for k in ("box_cubemap", "box_min", "box_max", "box_capture"):
        assert np.array_equal(getattr(again, k), getattr(inputs, k))
    hx, hz = exp.pool.half_extent
    top = exp.pool.wall_height
    assert np.allclose(inputs.box_max, [hx, top, hz]) and np.allclose(inputs.box_capture[1], top)
    cube = inputs.box_cubemap
    assert cube.shape == (6, 32, 32, 3) and np.isfinite(cube).all() and cube.min() >= 0
    # the upper half of the scene (the stored y flip: texel d holds the scene in d * (1,-1,1))
    # is the sky cube map's texels; the walls just below the horizon are the walls' colour
    d = cubemap_directions(32) * np.array([1.0, -1.0, 1.0])
    sky = shader_cubemap(exp, 32)
    up = d[..., 1] > 0.0
    assert np.array_equal(cube[up], sky[up])
    below = (d[..., 1] < 0.0) & (d[..., 1] > -0.5 * top / max(hx, hz))
    assert below.sum() > 20
    assert np.abs(cube[below] - sky[below]).max(-1).mean() > 0.05


def test_the_cube_maps_key_is_the_dry_scene():
    a = small_experiment()
    moved = small_experiment(**{"camera.position": "[1.0, 3.0, 6.0]", "waves.amplitude": "0.02"})
    taller = small_experiment(**{"pool.wall_height": "0.5"})
    assert a.dry_scene_hash() == moved.dry_scene_hash()  # every view and wave shares it
    assert a.dry_scene_hash() != taller.dry_scene_hash()


def test_game_textures_quantise_the_local_cube_map():
    from shaders_port.inputs import game_precision

    inputs = synthetic_box_inputs(32, 24)
    inputs = dataclasses.replace(inputs, box_cubemap=inputs.box_cubemap + np.float32(1e-4))
    game = game_precision(inputs)
    assert not np.array_equal(game.box_cubemap, inputs.box_cubemap)
    assert np.array_equal(game.box_cubemap, game.box_cubemap.astype(np.float16).astype(np.float32))
