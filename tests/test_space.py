"""The shader space: names, realisation, refusals, neighbours, and a sample of configurations
nobody registered by hand against OpenGL."""

import random

import numpy as np

import pytest

from shaders_port import space as _space
from shaders_port.glsl_text import read_source, switches_of
from shaders_port.space import AXES, ORIGINAL, Unrealisable
from shaders_port.ports.switches import decode
from shaders_port.variants import VARIANTS, get_variant
from helpers.gl import check_gl_match, compare_or_skip
from helpers.port_checks import VARIANT_CUSTOM as CUSTOM
from helpers.port_checks import assert_variant_jacobian_columns
from helpers.synthetic import synthetic_baseline_inputs, synthetic_inputs_for


def _ports():
    from shaders_port.ports import water_baseline, water_reflection, water_refraction

    return {
        "water_refraction": water_refraction,
        "water_reflection": water_reflection,
        "water_baseline": water_baseline,
    }


def test_every_shipped_variant_is_a_configuration_of_the_space():
    for name, v in VARIANTS.items():
        c = _space.choices_of(name)
        assert _space.name_of(c) == name
        shader, defines, textures = _space.realise(c)
        assert (shader, set(defines), textures) == (v.shader, set(v.defines), v.textures), name


def test_each_source_technique_alone_is_a_shader_of_the_space():
    alone = {
        "water_baseline_flat_cube": ("planar", "cube"),  # 001's refraction, 000's sky
        "water_baseline_noplanar_cube": ("distorted", "cube"),  # 003's refraction
        "water_baseline_flat_norefraction": ("none", "planar"),  # 004's mirror
        "water_baseline_norefraction": ("none", "planar_distorted"),  # 002 on 004
    }
    for name, (refraction, reflection) in alone.items():
        c = _space.choices_of(name)
        assert (c["refraction"], c["reflection"]) == (refraction, reflection)
        assert get_variant(name).shader == "water_baseline"
    assert "FLAT_WATER" in _space.realise({"refraction": "planar", "reflection": "cube"})[1]


def test_pinned_axes_restrict_the_space():
    fix = {"textures": "float", "layers": 4, "refine": "linear", "normals": "average",
           "parallax": "off"}  # fmt: skip
    pinned = _space.configurations(fix)
    # cube, mirror, raycast, box, ssr; none (no specular); screen space
    assert len(pinned) == 5 * 16 + 4 + 9
    assert all(c["layers"] == 4 and c["textures"] == "float" for c in pinned)
    with pytest.raises(ValueError, match="unknown axis"):
        _space.configurations({"fog": "on"})


def test_every_configuration_compiles_to_names_its_file_and_port_know():
    configs = _space.configurations()
    # 1248 cube, box, ssr, mirror, raycast each + 312 refraction-only + 9 screen
    assert len(configs) == 6561
    ports = _ports()
    names = set()
    for c in configs:
        shader, defines, _ = _space.realise(c)
        assert set(defines) <= set(switches_of(read_source(shader, "frag", "core")))
        decode(shader, ports[shader].DEFINES, defines)  # the port implements every name
        name = _space.name_of(c)
        assert _space.choices_of(name) == c
        names.add(name)
    assert len(names) == len(configs)  # one name per configuration


@pytest.mark.parametrize(
    "choices,reason",
    [
        ({"reflection": "planar"}, "screen-space shader only"),
        ({"reflection": "none"}, "choose specular = none"),
        ({"refraction": "planar_distorted", "attenuation": "beer"}, "not attenuation = beer"),
        ({"refraction": "planar", "reflection": "planar_distorted"}, "is flat water"),
        ({"refraction": "distorted", "reflection": "planar"}, "normal-mapped reflections"),
        ({"refraction": "none", "reflection": "raycast"}, "neither the raycast reflection"),
        ({"refraction": "planar", "reflection": "box"}, "nor the local cube map"),
        ({"refraction": "distorted", "reflection": "ssr"}, "the screen-space reflection of the"),
        ({"refraction": "raycast", "reflection": "planar"}, "reflect_distortion = 0 is the flat"),
    ],
)
def test_unrealisable_configurations_are_refused_with_the_reason(choices, reason):
    with pytest.raises(Unrealisable, match=reason):
        _space.realise(choices)


def test_bad_names_and_axes_say_what_is_wrong():
    with pytest.raises(ValueError, match="two choices of attenuation"):
        _space.choices_of("water_refraction_beer_beer")
    with pytest.raises(ValueError, match="canonical form.*water_refraction_beer_walls"):
        _space.choices_of("water_refraction_walls_beer")
    with pytest.raises(ValueError, match="'glossy' is not a choice"):
        _space.choices_of("water_refraction_glossy")
    with pytest.raises(ValueError, match="screen-space shaders are water_baseline"):
        _space.choices_of("water_baseline_beer")
    with pytest.raises(ValueError, match="unknown axis"):
        _space.checked({"fog": "on"})
    with pytest.raises(ValueError, match="layers = 3"):
        _space.checked({"layers": 3})
    with pytest.raises(ValueError, match="unknown shader variant.*choose specular = none"):
        get_variant("water_refraction_noreflection_ggx")


def test_neighbours_change_one_axis_or_its_coupled_one():
    for c in random.Random(3).sample(_space.configurations(), 25) + [ORIGINAL]:
        for n in _space.neighbours(c):
            _space.realise(n)
            diff = {a for a in AXES if n[a] != c[a]}
            screen_space = "raycast" not in (n["refraction"], c["refraction"])
            assert (
                len(diff) == 1
                or diff == {"reflection", "specular"}
                or "refraction" in diff
                or screen_space
            ), (c, n)
    near = {_space.name_of(n) for n in _space.neighbours(ORIGINAL)}
    assert {"water_reflection", "water_refraction_beer", "water_baseline"} <= near
    fixed = _space.neighbours(ORIGINAL, {"textures": "float", "refraction": "raycast"})
    assert all(n["textures"] == "float" and n["refraction"] == "raycast" for n in fixed)


def test_parse_fix():
    assert _space.parse_fix(["layers=2", " textures = float "]) == {
        "layers": 2,
        "textures": "float",
    }
    with pytest.raises(ValueError, match="expected axis=choice"):
        _space.parse_fix(["fog=on"])
    with pytest.raises(ValueError, match="layers has the choices 4, 2, 1"):
        _space.parse_fix(["layers=3"])


def test_a_generated_configuration_is_a_full_variant():
    v = get_variant("water_reflection_beer_ggx_walls_secant_2layers")
    assert v.defines == (
        "BEER_ATTENUATION",
        "GGX_SPECULAR",
        "WALL_FACES",
        "SECANT_REFINE",
        "TWO_NORMAL_LAYERS",
    )
    assert "refine_steps" in v.schedule and "refl_loop_cap" in v.schedule
    assert set(v.replaces) == {"attenuation_distance", "specular_exponent"}
    assert "absorption_r" in v.fit_names(["attenuation_distance"])


@pytest.mark.parametrize("seed", range(4))
def test_configurations_nobody_registered_match_opengl(seed):
    """Four configurations drawn from the space (fixed seeds): port and llvmpipe agree within
    the GL check's thresholds, and the configuration renders differently from the original."""

    raycast = _space.configurations({"refraction": "raycast"})
    assert len(raycast) == 6552
    c = random.Random(100 + seed).choice(raycast)
    name = _space.name_of(c)
    inputs = synthetic_inputs_for(name, 96, 72)
    res = compare_or_skip(inputs, CUSTOM, name)
    check_gl_match(res, f"gl_space_{name}")


def test_the_baseline_configurations_match_opengl():

    inputs = synthetic_baseline_inputs(64, 48)
    planar = _space.configurations({"refraction": "planar"})
    assert [_space.name_of(c) for c in planar] == [
        "water_baseline_flat_cube",
        "water_baseline_flat",
    ]
    for c in _space.configurations({"attenuation": "linear", "specular": "phong", "walls": "off"}):
        if c["refraction"] == "raycast":
            continue
        check_gl_match(compare_or_skip(inputs, CUSTOM, _space.name_of(c)), "gl_space_planar")


@pytest.mark.parametrize(
    "name", ["water_refraction_mirror", "water_refraction_mirror_beer_ggx_walls_2layers"]
)
def test_the_raycast_with_the_mirror_matches_opengl(name):

    v = get_variant(name)
    assert "PLANAR_REFLECTION" in v.defines and "reflect_distortion" in v.reads()
    res = compare_or_skip(synthetic_baseline_inputs(64, 48), CUSTOM, name)
    check_gl_match(res, f"gl_space_{name}")
    assert res["n_nonfinite"] == 0


def test_the_mirror_derivatives_match_central_differences():
    v = get_variant("water_refraction_mirror")
    inputs = synthetic_baseline_inputs(48, 36)
    names = ["reflect_distortion", "reflect_color[1]"]
    out, water = assert_variant_jacobian_columns(v, inputs, CUSTOM, names)
    fetches = out["fetches"][water]
    plain = get_variant("water_refraction").render(inputs, CUSTOM).numpy()["fetches"][water]
    assert np.array_equal(fetches, plain + 1)  # the mirrored camera's pass


def test_an_overlong_name_is_refused_in_a_short_message():
    """A name no shader of the space can have (longer than any, quoted) is refused without
    echoing it whole: a pasted file or binary garbage must not flood the error."""
    from shaders_port.space import configurations, name_of
    from shaders_port.variants import MAX_NAME, get_variant

    assert max(len(repr(name_of(c))) for c in configurations()) <= MAX_NAME
    with pytest.raises(ValueError, match="no name of the shader space is that long") as err:
        get_variant("abé\n\x00\"'" * 500)
    assert len(str(err.value)) < 300
