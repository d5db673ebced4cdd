"""specular = disc, the sun's disc seen in the mirror of the normal: the port against the formula
on calm water and against llvmpipe, its derivatives against central differences, recovery of
its constants from a synthetic target, and its start constants read off the scene's sun."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from helpers.experiments import small_experiment
from helpers.gl import check_gl_match, compare_or_skip
from helpers.port_checks import VARIANT_CUSTOM as CUSTOM
from helpers.port_checks import assert_variant_jacobian_columns
from helpers.synthetic import sun_mirrored_at_the_centre, synthetic_inputs

from shaders_port import space as _space
from shaders_port.variants import get_variant

# a wide, soft disc: many pixels on its edge, some inside it
DISC = CUSTOM.replace(sun_disc_radius=9.0, sun_disc_softness=0.4, sun_disc_radiance=3.0)
FLAT_NORMAL = (0.5, 1.0, 0.5)  # encoded (0, 1, 0): calm water


def _smoothstep(e0, e1, x):
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def test_on_calm_water_the_disc_is_the_mirrored_sun_fresnel_weighted():
    from study.scene.baseline_inputs import pixel_rays

    calm = synthetic_inputs(64, 48)
    calm = dataclasses.replace(calm, normal_map=np.broadcast_to(FLAT_NORMAL, calm.normal_map.shape))
    calm = sun_mirrored_at_the_centre(calm)
    disc = get_variant("water_refraction_disc").render(calm, DISC).numpy()
    none = get_variant("water_refraction_nospecular").render(calm, DISC).numpy()
    water = disc["mask"] > 0
    # independently: the eye ray meets y = 0, is mirrored, and is compared with the light
    eye, d = pixel_rays(calm.view_proj, calm.width, calm.height)
    eye, d = eye[::-1], d[::-1]  # image order, row 0 at the top
    p = eye + (-eye[..., 1:2] / d[..., 1:2]) * d
    V = calm.viewpos - p
    V /= np.linalg.norm(V, axis=-1, keepdims=True)
    L = calm.lightpos - p
    L /= np.linalg.norm(L, axis=-1, keepdims=True)
    cos_to_sun = -V[..., 0] * L[..., 0] + V[..., 1] * L[..., 1] - V[..., 2] * L[..., 2]
    r, s = np.radians(DISC.sun_disc_radius), DISC.sun_disc_softness
    seen = _smoothstep(np.cos(r * (1 + s)), np.cos(r * (1 - s)), cos_to_sun)
    lut = calm.fresnel_lut
    F = lut[np.clip((V[..., 1] * len(lut)).astype(int), 0, len(lut) - 1), 1]
    want = (F * seen * DISC.sun_disc_radiance)[..., None] * calm.lightcolor
    got = disc["color"] - none["color"]
    assert 0.05 < (seen[water] > 0.99).mean() and (seen[water] < 0.01).mean() > 0.2
    assert np.abs(got - want)[water].max() < 2e-3, np.abs(got - want)[water].max()
    assert np.abs(got - want)[water].mean() < 1e-4


@pytest.mark.parametrize(
    "name", ["water_refraction_disc", "water_reflection_beer_disc_walls_secant"]
)
def test_the_disc_matches_opengl(name):
    v = get_variant(name)
    assert "SUN_DISC_SPECULAR" in v.defines
    inputs = sun_mirrored_at_the_centre(synthetic_inputs(96, 72))
    res = compare_or_skip(inputs, DISC, name)
    check_gl_match(res, f"gl_disc_{name}")
    assert res["n_nonfinite"] == 0


def test_the_disc_derivatives_match_central_differences():
    v = get_variant("water_refraction_beer_disc_walls")
    inputs = sun_mirrored_at_the_centre(synthetic_inputs(48, 36))
    assert_variant_jacobian_columns(
        v,
        inputs,
        DISC,
        ["sun_disc_radius", "sun_disc_softness", "sun_disc_radiance", "bumptex_mult"],
    )


def test_the_disc_constants_are_recovered_from_a_synthetic_target():
    from study.fit.calibrate import make_problem
    from study.fit.model import ShaderModel, get_value
    from study.fit.solvers import fit

    inputs = sun_mirrored_at_the_centre(synthetic_inputs(48, 36))
    name = "water_refraction_disc"
    truth = DISC.replace(sun_disc_radius=7.0, sun_disc_softness=0.3, sun_disc_radiance=2.5)
    target = get_variant(name).render(inputs, truth).numpy()["color"]
    model = ShaderModel(name, inputs, target)
    names = ["sun_disc_radius", "sun_disc_softness", "sun_disc_radiance"]
    res = fit(make_problem(model, DISC, names, progress=False), solver="levenberg_marquardt")
    assert res.converged, res.message
    for n in names:
        assert abs(res.constants[n] - get_value(truth, n)) < 1e-3 * get_value(truth, n), (
            n,
            res.constants[n],
        )


def test_the_disc_fits_no_highlight_constant_and_is_in_the_space():
    req = ["attenuation_distance", "bumptex_mult", "water_color", "specular_strength"]
    req += ["specular_exponent"]
    assert get_variant("water_refraction_beer_disc_walls").fit_names(req) == [
        "absorption_r",
        "absorption_g",
        "absorption_b",
        "bumptex_mult",
        "water_color",
    ]
    near = {_space.name_of(n) for n in _space.neighbours(_space.ORIGINAL)}
    assert "water_refraction_disc" in near  # a one-axis neighbour: screened and reported
    assert _space.choices_of("water_refraction_box_disc")["specular"] == "disc"


def test_its_start_constants_are_the_scenes_sun_unless_the_experiment_sets_them():
    from study.fit.model import constants_from_experiment

    exp = small_experiment(**{"sun.radius": "2.5", "sun.radiance": "[3.0, 6.0, 4.0]"})
    c = constants_from_experiment(exp)
    assert (c.sun_disc_radius, c.sun_disc_radiance) == (2.5, 6.0)
    given = small_experiment(**{"sun.radius": "2.5", "constants.sun_disc_radius": "0.27"})
    c = constants_from_experiment(given)
    assert c.sun_disc_radius == 0.27 and c.sun_disc_radiance == max(given.sun.radiance)
