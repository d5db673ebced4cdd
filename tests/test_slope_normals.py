"""Slope-blended normals (``normals = "slopes"``, ``SLOPE_NORMALS``): the layers' mean slope is
the normal of the reference's surface, the port matches llvmpipe in both raycast files, and the
space names and refuses it (its derivative: ``test_variants``' central differences)."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.experiments import small_experiment
from helpers.port_checks import port_normals
from study.scene.shader_waves import angles_deg


def _errors_deg(amplitude: float) -> tuple[np.ndarray, np.ndarray]:
    """Per water pixel, the angle (degrees) of the slope-blended and of the averaged normal
    from the reference surface's at waves of ``amplitude``."""
    from study.scene.mitsuba_scene import study_waves
    from study.scene.shader_inputs import build_shader_inputs

    exp = small_experiment(**{"waves.amplitude": amplitude, "waves.normal_map_size": 512})
    inputs = build_shader_inputs(exp).with_resolution(96, 96)
    xz, slopes = port_normals(inputs, slopes=True)
    _, gx, gz = study_waves(exp).height_and_gradient(*xz.T)
    truth = np.stack([-gx, np.ones_like(gx), -gz], -1)
    truth /= np.linalg.norm(truth, axis=-1, keepdims=True)
    return angles_deg(slopes, truth), angles_deg(port_normals(inputs)[1], truth)


def test_slope_blended_normal_is_the_reference_surfaces_normal(mi):
    """Known truth: the reference's surface is the mean of the normal map's four layers'
    heights (``study.scene.geometry.Waves``). On steep waves (amplitude 0.2, 4x the default)
    the slope-blended normal is the surface's up to the texture's filtering, the averaged
    normals are not (measured: 0.003 against 2.6 degrees mean). At the default amplitude
    (0.05) both are within 0.1 degree (measured: 0.002 and 0.09)."""
    slopes, average = _errors_deg(0.2)
    assert slopes.mean() < 0.01 * average.mean(), (slopes.mean(), average.mean())
    assert slopes.mean() < 0.05, slopes.mean()
    slopes, average = _errors_deg(0.05)
    assert slopes.mean() < 0.1 * average.mean() and average.mean() < 0.1, (slopes, average)
    # two layers: the mean of two slopes, the same as the average's direction for one layer
    from study.scene.shader_inputs import build_shader_inputs

    inputs = build_shader_inputs(small_experiment()).with_resolution(48, 48)
    two = port_normals(inputs, 2, slopes=True)[1]
    assert angles_deg(two, port_normals(inputs, 2)[1]).max() > 0.1
    np.testing.assert_allclose(port_normals(inputs, 1, True)[1], port_normals(inputs, 1)[1])


@pytest.mark.parametrize(
    "name",
    ["water_refraction_beer_disc_walls_slopes", "water_reflection_beer_ggx_2layers_slopes"],
)
def test_slope_normals_match_opengl(name):
    """The port against llvmpipe running the GLSL file with ``SLOPE_NORMALS``, four and two
    layers, the refraction and the reflection file; and the choice changes the image."""
    from helpers.gl import check_gl_match, compare_or_skip
    from helpers.port_checks import VARIANT_CUSTOM
    from helpers.synthetic import synthetic_inputs_for
    from shaders_port.variants import get_variant

    inputs = synthetic_inputs_for(name, 96, 72)
    res = compare_or_skip(inputs, VARIANT_CUSTOM, name)
    check_gl_match(res, f"gl_{name}")
    ours = get_variant(name).render(inputs, VARIANT_CUSTOM).numpy()["color"]
    other = get_variant(name.replace("_slopes", "")).render(inputs, VARIANT_CUSTOM).numpy()
    assert np.abs(ours - other["color"]).max() > 1e-3


def test_the_space_names_and_refuses_slope_normals():
    from shaders_port import space

    c = space.choices_of("water_refraction_beer_disc_walls_slopes")
    assert c["normals"] == "slopes" and c["layers"] == 4
    assert "SLOPE_NORMALS" in space.realise(c)[1]
    with pytest.raises(space.Unrealisable, match="one layer has nothing to blend"):
        space.realise({"normals": "slopes", "layers": 1})
    with pytest.raises(space.Unrealisable, match="four layers averaged"):
        space.realise({"refraction": "planar", "reflection": "planar", "normals": "slopes"})
    assert {"normals": "slopes"} in space.ALONE.values()
