"""Parallax offset mapping (``parallax = "offset"``, ``PARALLAX_OFFSET``): the height map is the
reference surface's heights (known truth: the study's waves), the shifted normal is the
surface's where the eye ray meets it, the port matches llvmpipe and the SPIR-V executor in both
raycast files with one more fetch per layer, its derivatives match central differences, and
the space names and refuses it."""

from __future__ import annotations

import numpy as np
import pytest
from helpers.experiments import small_experiment
from helpers.gl import check_gl_match, compare_or_skip
from helpers.port_checks import VARIANT_CUSTOM, assert_variant_jacobian_columns
from helpers.synthetic import sun_mirrored_at_the_centre, synthetic_inputs

from shaders_port.pipeline.normal_maps import height_map
from shaders_port.variants import get_variant
from study.scene.shader_waves import angles_deg

NAMES = [
    "water_refraction_beer_disc_walls_parallax",
    "water_reflection_beer_ggx_2layers_slopes_parallax",
    "water_refraction_1layer_parallax",
]


def test_the_height_map_is_the_waves_height(mi):
    """Known truth: the study's normal map holds the slopes of ``amplitude * h0`` over the tile
    (``study.scene.geometry.Waves``); integrated back, its heights are ``amplitude * h0 /
    normal_tile`` in tile lengths (measured: within 1.1e-9 of 0.025)."""
    from study.scene.mitsuba_scene import study_waves

    waves = study_waves(small_experiment())
    S = 256
    c = (np.arange(S) + 0.5) / S
    h0, _, _ = waves._h0(*np.meshgrid(c, c))
    truth = waves.amplitude * h0 / waves.tile
    got = height_map(waves.normal_map(S))
    assert got.shape == (S, S) and np.abs(truth).max() > 0.01
    np.testing.assert_allclose(got, truth, atol=1e-6)


def test_the_shifted_normal_is_the_surfaces_where_the_eye_ray_meets_it(mi):
    """Known truth: the reference's surface is the mean of the layers' heights; where the eye
    ray through a pixel meets it (fixed-point on the ray) its normal is the slope-blended
    normal read at the shifted coordinates, not at the water plane's point (measured: 0.06
    against 0.63 degrees mean)."""
    import drjit as dr

    from shaders_port.pipeline.normal_maps import with_maps
    from shaders_port.pipeline.raster import prepare
    from shaders_port.pipeline.texture import backend_types
    from shaders_port.ports.normals import normal_map_block
    from study.scene.mitsuba_scene import study_waves
    from study.scene.shader_inputs import build_shader_inputs

    exp = small_experiment(**{"waves.normal_map_size": 512})
    waves = study_waves(exp)
    inputs = build_shader_inputs(exp).with_resolution(96, 96)
    m = backend_types("llvm")
    P = with_maps(m, prepare(inputs, m), heights=True)
    eye = np.asarray(inputs.viewpos, np.float64)
    p = P.raster.world.astype(np.float64)
    d = (p - eye) / np.linalg.norm(p - eye, axis=-1, keepdims=True)
    for _ in range(8):
        h, _, _ = waves.height_and_gradient(p[:, 0], p[:, 2])
        p = eye + ((h - eye[1]) / d[:, 1])[:, None] * d
    _, gx, gz = waves.height_and_gradient(p[:, 0], p[:, 2])
    truth = np.stack([-gx, np.ones_like(gx), -gz], -1)
    truth /= np.linalg.norm(truth, axis=-1, keepdims=True)
    errors = []
    for parallax in (False, True):
        n, _, _ = normal_map_block(m, P, 1.0, 4, "slopes", parallax, dr.normalize(P.varyingVecEye))
        errors.append(angles_deg(np.array(n.numpy()).T, truth).mean())
    assert errors[1] < 0.2 * errors[0] and errors[1] < 0.1, errors


@pytest.mark.parametrize("name", NAMES)
def test_parallax_matches_opengl_and_the_executor(name):
    """The port against llvmpipe running the GLSL file with ``PARALLAX_OFFSET``, four, two and
    one layers, both files; the SPIR-V executor's run equals the port exactly, fetches included
    (one more per layer); and the choice changes the image."""
    from shaders_port.spirv import translated

    inputs = sun_mirrored_at_the_centre(synthetic_inputs(96, 72))
    check_gl_match(compare_or_skip(inputs, VARIANT_CUSTOM, name), f"gl_{name}")
    v = get_variant(name)
    ours = v.render(inputs, VARIANT_CUSTOM).numpy()
    spec = translated.builtin_spec(v.shader, v.defines)
    executed = translated.render(inputs, VARIANT_CUSTOM, spec=spec).numpy()
    assert np.array_equal(executed["color"], ours["color"])
    assert np.array_equal(executed["fetches"], ours["fetches"])
    plain = get_variant(name.replace("_parallax", "")).render(inputs, VARIANT_CUSTOM).numpy()
    if v.shader == "water_refraction":  # the fetches beside the raymarch's, one more per layer
        layers = 1 if "1layer" in name else 4
        water = ours["mask"] > 0
        fixed = [(o["fetches"] - o["iterations"])[water] for o in (ours, plain)]
        assert np.array_equal(fixed[0], fixed[1] + layers)
    assert np.abs(ours["color"] - plain["color"]).max() > 1e-2


def test_parallax_derivatives_match_central_differences():
    inputs = sun_mirrored_at_the_centre(synthetic_inputs(48, 36))
    constants = VARIANT_CUSTOM.replace(sun_disc_radius=9.0, sun_disc_softness=0.4)
    names = ["bumptex_mult", "sun_disc_radius", "attenuation_distance"]
    v = get_variant("water_refraction_disc_parallax")
    assert_variant_jacobian_columns(v, inputs, constants, names)


def test_the_space_names_and_refuses_parallax():
    from shaders_port import space

    c = space.choices_of("water_refraction_beer_disc_walls_slopes_parallax")
    assert c["parallax"] == "offset" and c["normals"] == "slopes"
    assert "PARALLAX_OFFSET" in space.realise(c)[1]
    with pytest.raises(space.Unrealisable, match="LEAN's level of detail"):
        space.realise({"parallax": "offset", "normals": "lean"})
    with pytest.raises(space.Unrealisable, match="at the plane's point"):
        space.realise({"refraction": "planar", "reflection": "planar", "parallax": "offset"})
    assert {"parallax": "offset"} in space.ALONE.values()
