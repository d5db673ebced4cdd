"""reflection = ssr, the screen-space reflection of engines: the march's frustum segment, the
port against llvmpipe, its derivatives against central differences (on the pixels it hits too),
its fetches, the #defines the port mirrors, and the camera's buffers it reads."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest
from helpers.experiments import small_experiment
from helpers.gl import check_gl_match, compare_or_skip
from helpers.port_checks import VARIANT_CUSTOM as CUSTOM
from helpers.port_checks import assert_variant_jacobian_columns
from helpers.synthetic import synthetic_inputs, synthetic_ssr_inputs

from shaders_port import space as _space
from shaders_port.glsl_text import read_source
from shaders_port.ports import ssr as _ssr
from shaders_port.variants import get_variant


def _probe(m, inputs):
    return _ssr.ssr_state(m, inputs, "test")


def test_the_march_runs_from_the_water_point_to_where_the_ray_leaves_the_frustum():
    from shaders_port.pipeline.texture import backend_types

    m = backend_types("llvm")
    inputs = synthetic_ssr_inputs(32, 24)
    S = _probe(m, inputs)
    rng = np.random.default_rng(2)
    n = 400
    origin = np.stack([rng.uniform(-1.9, 1.9, n), np.zeros(n), rng.uniform(-1.9, 1.9, n)], -1)
    R = rng.normal(size=(n, 3))
    R[:, 1] = np.abs(R[:, 1]) * rng.choice([0.05, 1.0], n) + 1e-3
    R /= np.linalg.norm(R, axis=-1, keepdims=True)
    a, b = _ssr.frustum_segment(m, S, m.Array3f(origin.T), m.Array3f(R.T))
    a, b = (np.stack([np.array(v[k]) for k in range(3)], -1).astype(np.float64) for v in (a, b))
    vp = inputs.view_proj.astype(np.float64)
    clip = np.concatenate([origin, np.ones((n, 1))], -1) @ vp.T
    assert np.allclose(a, 0.5 * clip[:, :3] / clip[:, 3:] + 0.5, atol=1e-5)
    # the end is on the frustum's boundary (a window coordinate at 0 or 1) ...
    assert np.allclose(np.minimum(b, 1.0 - b).min(-1), 0.0, atol=1e-4)
    assert (b > -1e-4).all() and (b < 1 + 1e-4).all()
    # ... and on the ray: unprojected, it lies ahead of the origin along R
    q = np.concatenate([2.0 * b - 1.0, np.ones((n, 1))], -1) @ np.linalg.inv(vp).T
    p = q[:, :3] / q[:, 3:]
    t = ((p - origin) * R).sum(-1)
    off = np.linalg.norm(p - origin - t[:, None] * R, axis=-1)
    assert (t > 0).all() and np.median(off / t) < 1e-3


@pytest.mark.parametrize(
    "name",
    [
        "water_refraction_ssr",
        "water_refraction_ssr_beer_ggx_walls_secant_2layers",
        "water_refraction_ssr_game_textures",
    ],
)
def test_the_screen_space_reflection_matches_opengl(name):
    v = get_variant(name)
    assert "SSR_REFLECTION" in v.defines and set(v.inputs) == {"scene_color", "scene_depth"}
    res = compare_or_skip(synthetic_ssr_inputs(96, 72), CUSTOM, name)
    check_gl_match(res, f"gl_ssr_{name}")
    assert res["n_nonfinite"] == 0


def _renders(inputs):
    ssr = get_variant("water_refraction_ssr").render(inputs, CUSTOM).numpy()
    cube = get_variant("water_refraction").render(inputs, CUSTOM).numpy()
    return ssr, cube, ssr["mask"] > 0


def test_the_walls_it_finds_replace_the_sky_and_each_costs_its_depth_samples():
    ssr, cube, water = _renders(synthetic_ssr_inputs(64, 48))
    changed = np.abs(ssr["color"] - cube["color"]).max(-1)[water] > 1e-3
    assert 0.05 < changed.mean() < 0.8, changed.mean()
    extra = (ssr["fetches"] - cube["fetches"])[water]
    assert set(np.unique(extra)) <= set(range(1, _ssr.SSR_STEPS + 1))
    # where nothing is found the march ran to its end: every sample read, the sky cube map's colour
    assert (extra[~changed] == _ssr.SSR_STEPS).mean() > 0.95
    assert extra[changed].mean() < _ssr.SSR_STEPS


def test_without_a_depth_buffer_it_is_the_sky_cube_map():
    # a clear depth buffer (nothing drawn): every ray misses, the colour is the original's
    inputs = synthetic_ssr_inputs(48, 36)
    empty = dataclasses.replace(inputs, scene_depth=np.ones_like(inputs.scene_depth))
    ssr, cube, water = _renders(empty)
    assert np.allclose(ssr["color"][water], cube["color"][water], atol=1e-6)
    assert (ssr["fetches"] - cube["fetches"])[water].min() == _ssr.SSR_STEPS


def test_a_surface_in_front_of_the_whole_step_is_not_hit():
    # a depth buffer everywhere just in front of the camera's near plane: behind it but far too
    # far in front of every step's previous sample (the thickness test), so nothing is hit
    inputs = synthetic_ssr_inputs(48, 36)
    near = dataclasses.replace(inputs, scene_depth=np.full_like(inputs.scene_depth, 1e-3))
    ssr, cube, water = _renders(near)
    assert np.allclose(ssr["color"][water], cube["color"][water], atol=1e-6)


def test_the_ssr_derivatives_match_central_differences():
    v = get_variant("water_refraction_ssr_beer_walls")
    inputs = synthetic_ssr_inputs(48, 36)
    assert_variant_jacobian_columns(v, inputs, CUSTOM, ["bumptex_mult", "reflect_color[1]"])


def test_the_hits_move_with_the_ray_in_the_derivatives():
    # on the pixels whose reflection comes from the colour buffer, d colour / d bumptex_mult
    # against central differences (the hit point moves with R, the buffer is bilinear)
    inputs = synthetic_ssr_inputs(64, 48)
    v = get_variant("water_refraction_ssr")
    ssr, cube, water = _renders(inputs)
    hit = water & (np.abs(ssr["color"] - cube["color"]).max(-1) > 1e-3)
    _, J = v.render_with_jacobian(inputs, CUSTOM, ["bumptex_mult"])
    h = 1e-3
    b = CUSTOM.bumptex_mult
    plus = v.render(inputs, CUSTOM.replace(bumptex_mult=b + h)).numpy()["color"]
    minus = v.render(inputs, CUSTOM.replace(bumptex_mult=b - h)).numpy()["color"]
    fd = (plus - minus) / (2 * h)
    err = np.abs(J[..., 0] - fd).max(-1)[hit]
    scale = np.abs(fd).max(-1)[hit]
    assert hit.sum() > 100 and scale.max() > 1e-2
    # a hit decided otherwise at b +- h (the depth buffer is nearest-filtered) is a jump
    assert np.mean(err <= 2e-2 * scale + 2e-3) >= 0.85, np.median(err)


def test_without_its_inputs_it_says_how_to_build_them():
    v = get_variant("water_refraction_ssr")
    with pytest.raises(ValueError, match="scene_color, scene_depth.*with_baseline_inputs"):
        v.render(synthetic_inputs(32, 24), CUSTOM)


@pytest.mark.parametrize("dialect", ["compat", "core"])
def test_the_glsl_defines_what_the_port_marches(dialect):
    src = read_source("water_refraction", "frag", dialect)
    steps = re.search(r"^#define SSR_STEPS (\d+)$", src, re.M)
    thickness = re.search(r"^#define SSR_THICKNESS ([0-9.]+)$", src, re.M)
    assert int(steps[1]) == _ssr.SSR_STEPS
    assert float(thickness[1]) == _ssr.SSR_THICKNESS


def test_the_search_and_the_sources_reach_the_ssr():
    near = {_space.name_of(n) for n in _space.neighbours(_space.ORIGINAL)}
    assert "water_refraction_ssr" in near  # a one-axis neighbour: screened, and in the report
    assert _space.ALONE["screen-space reflection (engines' SSR)"] == {"reflection": "ssr"}
    assert _space.choices_of("water_refraction_ssr_beer_walls")["reflection"] == "ssr"
    assert _space.SOURCE[("reflection", "ssr")] == "screen-space reflection (engines' SSR)"


def test_the_study_gives_it_the_cameras_buffers(monkeypatch):
    from study.scene import baseline_inputs as B

    calls = []

    def fake(exp, inputs, variant, cache=None, log=print):
        calls.append(variant)
        return dataclasses.replace(inputs, scene_color=inputs.refraction_texture)

    monkeypatch.setattr(B, "with_baseline_inputs", fake)
    monkeypatch.setattr(B, "with_box_inputs", lambda *a, **k: pytest.fail("no local cube map"))
    exp = small_experiment()
    base = synthetic_inputs(32, 24)
    out = B.inputs_for_shader(exp, base, "water_refraction_ssr_beer_walls", "llvm_ad_rgb")
    assert calls == ["llvm_ad_rgb"] and out.scene_color is not None
    assert B.inputs_for_shader(exp, base, "water_refraction_beer_walls", "llvm_ad_rgb") is base


def test_game_textures_quantise_the_colour_buffer_not_the_depth():
    from shaders_port.inputs import game_precision

    inputs = synthetic_ssr_inputs(32, 24)
    inputs = dataclasses.replace(inputs, scene_color=inputs.scene_color + np.float32(1e-4))
    game = game_precision(inputs)
    assert np.array_equal(game.scene_color, game.scene_color.astype(np.float16).astype(np.float32))
    assert not np.array_equal(game.scene_color, inputs.scene_color)
    assert np.array_equal(game.scene_depth, inputs.scene_depth)
