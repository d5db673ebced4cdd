"""The variants of the seed's refraction shader (shaders_port.variants): each GLSL switch
against its Dr.Jit option on llvmpipe (the thresholds of test_gl_differential), the diagnostics
count what each variant does, central differences of every constant a variant adds, and the
fit substitutes a variant's constants for the seed's it replaces."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.gl import check_gl_match, compare_or_skip
from helpers.port_checks import FD_CONSTANTS, FD_EPS, check_jacobian_column
from helpers.port_checks import VARIANT_CUSTOM as CUSTOM
from helpers.synthetic import synthetic_inputs
from shaders_port import Constants
from shaders_port.ports import water_refraction
from shaders_port.variants import VARIANTS, get_variant

SEED = "water_refraction"
NEW = [
    n
    for n, v in VARIANTS.items()
    if v.shader == SEED and n not in (SEED, "water_refraction_noreflection")
]


@pytest.fixture(scope="module")
def inputs():
    return synthetic_inputs(width=96, height=72)


@pytest.fixture(scope="module")
def seed_out(inputs):
    return get_variant(SEED).render(inputs, CUSTOM).numpy()


def test_registered_variants():
    assert {
        "water_refraction_beer",
        "water_refraction_ggx",
        "water_refraction_beer_ggx",
        "water_refraction_binary",
        "water_refraction_secant",
        "water_refraction_2layers",
        "water_refraction_1layer",
        "water_refraction_nospecular",
    } <= set(NEW)
    for n in NEW:
        v = get_variant(n)
        assert (v.defines or v.textures == "game") and v.description
        water_refraction.options_of(v.defines)  # the port implements every name
        assert v.source().split("\n")[1].startswith("#define ") or not v.defines


@pytest.mark.parametrize("name", NEW)
def test_variant_port_matches_gl(inputs, seed_out, name):

    res = compare_or_skip(inputs, CUSTOM, name)
    check_gl_match(res, f"gl_{name}_custom")
    # the switch does something: the variant's image is not the seed's
    water = seed_out["mask"] > 0
    assert np.abs(res["port"] - seed_out["color"]).max(-1)[water].mean() > 1e-3, name


def test_diagnostics_count_what_each_variant_does(inputs, seed_out):
    water = seed_out["mask"] > 0
    for name in NEW + [SEED]:
        v = get_variant(name)
        out = v.render(inputs, CUSTOM).numpy()
        opts = water_refraction.options_of(v.defines)
        layers = opts.normal_layers
        # fetches: normal-map layers, the start depth, one per iteration (linear search and
        # refinement), the refraction colour, cube map and Fresnel LUT
        np.testing.assert_array_equal(
            out["fetches"][water], layers + 1 + out["iterations"][water] + 1 + 2
        )
        if opts.refine:
            np.testing.assert_array_equal(
                out["iterations"][water], seed_out["iterations"][water] + CUSTOM.refine_steps
            )
        elif layers == 4 and v.textures == "float":  # same normals, same depths: same search
            np.testing.assert_array_equal(out["iterations"][water], seed_out["iterations"][water])


def test_refinement_finds_the_crossing_closer_than_the_seed():
    """On a flat floor seen through a flat surface, the crossing is exact in closed form: the
    seed's linear interpolation on a nearest-filtered depth already is, so put the floor on
    a slope where the bracket matters and compare the refraction positions' error through the
    colour: refinement steps give a smaller error against a 64-steps-per-unit reference."""
    inp = synthetic_inputs(width=64, height=48)
    fine = (
        get_variant(SEED)
        .render(inp, Constants(steps_grazing=64.0, steps_steep=64.0, loop_cap=800))
        .numpy()
    )
    water = fine["mask"] > 0
    coarse = Constants(steps_grazing=3.0, steps_steep=1.0)
    err = {}
    for name in (SEED, "water_refraction_binary", "water_refraction_secant"):
        out = get_variant(name).render(inp, coarse.replace(refine_steps=4)).numpy()
        err[name] = float(np.abs(out["color"] - fine["color"]).max(-1)[water].mean())
    assert (
        err["water_refraction_binary"] < err[SEED] and err["water_refraction_secant"] < err[SEED]
    ), err


def test_beer_lambert_is_the_exponential_law():
    """Beer variant with waterColor 0: colour = the seed's unattenuated colour times
    exp(-sigma d), channel by channel (d from the shader's own travel length)."""
    inp = synthetic_inputs(width=48, height=36)
    c = Constants(
        water_color=(0.0, 0.0, 0.0, 1.0),
        absorption_r=0.9,
        absorption_g=0.3,
        absorption_b=0.1,
        attenuation_distance=1e4,
    )
    beer = water_refraction.render(inp, c, defines=("BEER_ATTENUATION", "NOREFLECTION")).numpy()
    clear = water_refraction.render(
        inp, c, defines=("NOREFLECTION",)
    ).numpy()  # mix by d / 1e4 only
    water = beer["mask"] > 0
    ratio = beer["color"][water] / np.maximum(clear["color"][water], 1e-6)
    # -log(ratio) / sigma is the same travel length in all three channels
    d = -np.log(np.clip(ratio, 1e-6, None)) / np.array([0.9, 0.3, 0.1])
    ok = clear["color"][water].min(-1) > 0.02
    assert ok.sum() > 100
    np.testing.assert_allclose(d[ok, 0], d[ok, 2], rtol=2e-2, atol=2e-3)
    np.testing.assert_allclose(d[ok, 1], d[ok, 2], rtol=2e-2, atol=2e-3)
    assert d[ok].mean() > 0.5  # a real path length through the water (world units)


def test_each_port_decodes_exactly_the_names_its_glsl_tests():
    """One table per port (``DEFINES``) holds every switch of its GLSL file and nothing else
    (water_reflection leaves out NOREFLECTION, the other shader's variant), and every registered
    variant's names decode in its port; the registry refuses a name the file does not test."""
    from shaders_port.ports import water_baseline, water_reflection
    from shaders_port.glsl_text import read_source, switches_of
    from shaders_port.ports.switches import decode
    from shaders_port.variants import Variant, register

    ports = {"water_refraction": water_refraction, "water_reflection": water_reflection}
    ports["water_baseline"] = water_baseline
    for name, port in ports.items():
        tested = set(switches_of(read_source(name, "frag", "core")))
        own = set(port.DEFINES) | ({"NOREFLECTION"} if name == "water_reflection" else set())
        assert own == tested, name
    for v in VARIANTS.values():
        decode(v.shader, ports[v.shader].DEFINES, v.defines)
    with pytest.raises(ValueError, match="tests no #define"):
        register(Variant("water_refraction_typo", "water_refraction", defines=("BEER_ATENUATION",)))
    assert "water_refraction_typo" not in VARIANTS


def test_unknown_option_refused(inputs):
    with pytest.raises(ValueError, match="does not implement #define THREE_NORMAL_LAYERS"):
        water_refraction.render(inputs, Constants(), defines=("THREE_NORMAL_LAYERS",))
    with pytest.raises(ValueError, match="GGX_SPECULAR and #define NO_SPECULAR both choose"):
        water_refraction.render(inputs, Constants(), defines=("GGX_SPECULAR", "NO_SPECULAR"))
    with pytest.raises(TypeError, match="tuple of names"):
        water_refraction.render(inputs, Constants(), defines="NOREFLECTION")


# ---- forward-mode derivatives of the variants' constants vs central differences ------------

FD_CASES = [
    ("water_refraction_beer", "absorption_r", 1e-3),
    ("water_refraction_beer", "absorption_g", 1e-3),
    ("water_refraction_beer", "absorption_b", 1e-3),
    ("water_refraction_beer", "water_color[1]", 1e-3),
    ("water_refraction_ggx", "specular_roughness", 1e-3),
    ("water_refraction_ggx", "specular_strength", 1e-3),
    ("water_refraction_ggx", "bumptex_mult", 3e-4),
    ("water_refraction_secant", "steps_steep", 3e-4),
    ("water_refraction_binary", "steps_steep", 3e-4),
    ("water_refraction_secant", "bumptex_mult", 3e-4),
    ("water_refraction_slopes", "bumptex_mult", 3e-4),  # through the slope-blended normal
    # through the lobes LEAN_NORMALS widens by the unresolved slopes' variance (the disc and the
    # strengths with the sun in view: test_lean)
    ("water_refraction_lean", "specular_exponent", 1e-2),
    ("water_refraction_lean", "bumptex_mult", 3e-4),
    ("water_refraction_ggx_lean", "specular_roughness", 1e-3),
]
FD_AT = FD_CONSTANTS.replace(
    absorption_r=0.6,
    absorption_g=0.25,
    absorption_b=0.15,
    specular_roughness=0.3,
    specular_strength=0.5,
)


@pytest.fixture(scope="module")
def variant_jacobians():
    inp = synthetic_inputs(width=48, height=36)
    out = {}
    for name in dict.fromkeys(n for n, _, _ in FD_CASES):
        names = [p for n, p, _ in FD_CASES if n == name]
        o, J = get_variant(name).render_with_jacobian(inp, FD_AT, names)
        out[name] = (o.numpy(), J, names)
    return inp, out


@pytest.mark.parametrize("name,param,eps", FD_CASES, ids=[f"{n[17:]}-{p}" for n, p, _ in FD_CASES])
def test_variant_jacobian_matches_central_differences(variant_jacobians, name, param, eps):
    inp, jac = variant_jacobians
    base, J, names = jac[name]
    v = get_variant(name)
    assert np.array_equal(v.render(inp, FD_AT).numpy()["color"], base["color"])
    check_jacobian_column(
        lambda c: v.render(inp, c).numpy(),
        base,
        J[..., names.index(param)],
        FD_AT,
        param,
        ("iterations",),
        eps=eps,
    )


# ---- the fit: a variant fits its own constants in place of the seed's -------------------------


def test_fit_names_substitute_the_variants_constants():
    req = [
        "attenuation_distance",
        "bumptex_mult",
        "water_color",
        "specular_strength",
        "specular_exponent",
    ]
    assert get_variant(SEED).fit_names(req) == req
    assert get_variant("water_refraction_beer_ggx").fit_names(req) == [
        "absorption_r",
        "absorption_g",
        "absorption_b",
        "bumptex_mult",
        "water_color",
        "specular_strength",
        "specular_roughness",
    ]
    assert get_variant("water_refraction_nospecular").fit_names(req) == req[:3]
    for n in NEW:  # every constant the variant fits is one its shader code reads
        for c in get_variant(n).fit_names(req):
            assert c in (
                "bumptex_mult",
                "water_color",
                "specular_strength",
                "attenuation_distance",
                "specular_exponent",
                "absorption_r",
                "absorption_g",
                "absorption_b",
                "specular_roughness",
            ), (n, c)


# ---- parsimony: information criteria of a fit ---------------------------------------------


def test_information_criteria():
    from study._metrics import information_criteria

    rng = np.random.default_rng(1)
    r = rng.normal(0.0, 0.1, 3000)
    ic = information_criteria(r, 4)
    n = r.size
    assert ic["n"] == n and ic["k"] == 4 and ic["rss"] == pytest.approx(float(r @ r))
    assert ic["aic"] == pytest.approx(n * np.log(ic["rss"] / n) + 8)
    assert ic["bic"] == pytest.approx(n * np.log(ic["rss"] / n) + 4 * np.log(n))
    # same residual, more constants: worse; a residual smaller by 1 % pays for 3 more constants
    assert information_criteria(r, 7)["bic"] > ic["bic"]
    assert information_criteria(0.99 * r, 7)["aic"] < ic["aic"]
    with pytest.raises(ValueError, match="finite residual"):
        information_criteria(r[:3], 4)
    with pytest.raises(ValueError, match="finite residual"):
        information_criteria(np.array([np.nan] * 10), 1)


# ---- the reflection shader (seed section 3) shares blocks [2], [5], [6], [8] and their switches


def test_reflection_variant_registered_matches_gl(inputs):
    from shaders_port.gl.compare import compare_port_gl

    res = compare_port_gl(inputs, CUSTOM, "water_reflection_beer_ggx")
    check_gl_match(res, "gl_water_reflection_beer_ggx_custom")


@pytest.mark.parametrize(
    "defines,options",
    [
        (
            ("TWO_NORMAL_LAYERS", "SECANT_REFINE", "NO_SPECULAR"),
            {"normal_layers": 2, "refine": "secant", "specular": "none"},
        ),
        (("ONE_NORMAL_LAYER", "BINARY_REFINE"), {"normal_layers": 1, "refine": "binary"}),
    ],
    ids=["2layers-secant-nospec", "1layer-binary"],
)
def test_reflection_shader_switches_match_gl(inputs, defines, options):
    """The other switches in water_reflection.frag against the reflection port compiled with the
    same names (the registry ships only its Beer and Beer + GGX variants); the port's table
    decodes them to the expected options."""
    from shaders_port.ports import water_reflection
    from shaders_port.gl.renderer import GLRenderer

    decoded = water_reflection.options_of(defines, "water_reflection", water_reflection.DEFINES)
    assert {k: getattr(decoded, k) for k in options} == options
    out = water_reflection.render(inputs, CUSTOM, defines=defines).numpy()
    with GLRenderer("water_reflection", inputs, defines=defines) as r:
        rgba, gl_mask = r.render(CUSTOM)
    both = (out["mask"] > 0) & gl_mask
    diff = np.abs(out["color"] - rgba[..., :3]).max(-1)[both]
    assert both.sum() > 500
    assert diff.mean() <= 1e-3 and np.percentile(diff, 99.9) <= 1e-2, (diff.mean(), diff.max())
    seed = water_reflection.render(inputs, CUSTOM).numpy()
    assert np.abs(out["color"] - seed["color"]).max(-1)[both].mean() > 1e-3  # the switches act


# ---- WALL_FACES: a crossing into geometry above the water is the geometry's submerged face ----


def walled_inputs(width: int = 96, height: int = 72):
    """The synthetic inputs with the reflection shader's wall (x0 .. x0 + 0.8, 0.6 high) in the
    refraction depth texture too, as the study's top-down textures hold a pool wall: refracted
    rays near it cross into the wall's column."""
    import dataclasses

    inp = synthetic_inputs(width=width, height=height)
    world_y = inp.world_y.copy()
    world_y[:, : world_y.shape[1] // 6] = 0.6
    return dataclasses.replace(inp, world_y=world_y)


@pytest.fixture(scope="module")
def walled():
    return walled_inputs()


def _wall_lanes(out):
    """Water pixels whose refraction crossing lies in the wall's column: with NOREFLECTION the
    WALL_FACES variant's colour there is waterColor (float32)."""
    water = out["mask"] > 0
    return water & (np.abs(out["color"] - np.float32(CUSTOM.water_color[:3])).max(-1) <= 1e-7)


def _refraction_only(name, inputs, constants) -> dict:
    """The water_refraction variant ``name`` compiled with NOREFLECTION too, as numpy arrays."""
    defines = get_variant(name).defines + ("NOREFLECTION",)
    return water_refraction.render(inputs, constants, defines=defines).numpy()


def test_wall_faces_shade_the_submerged_face_as_water(walled):
    beer = _refraction_only("water_refraction_beer", walled, CUSTOM)
    walls = _refraction_only("water_refraction_beer_walls", walled, CUSTOM)
    water = beer["mask"] > 0
    at_wall = _wall_lanes(walls)
    changed = water & (np.abs(walls["color"] - beer["color"]).max(-1) > 0.0)
    # the switch acts on the lanes whose crossing is in the wall's column, and only there
    assert 200 <= at_wall.sum() <= 0.5 * water.sum(), at_wall.sum()
    assert changed.sum() > 0.9 * at_wall.sum() and not (changed & ~at_wall).any()
    # those lanes showed the wall's top (the texture there) before; their crossing is at the wall
    assert np.abs(beer["color"][at_wall] - np.array(CUSTOM.water_color[:3])).max(-1).mean() > 0.05
    # no extra texture fetch, the same search
    np.testing.assert_array_equal(walls["fetches"][water], beer["fetches"][water])
    np.testing.assert_array_equal(walls["iterations"][water], beer["iterations"][water])
    # without a wall in the depth texture it is the Beer-Lambert variant, bit for bit
    plain = synthetic_inputs(width=96, height=72)
    np.testing.assert_array_equal(
        get_variant("water_refraction_beer_walls").render(plain, CUSTOM).numpy()["color"],
        get_variant("water_refraction_beer").render(plain, CUSTOM).numpy()["color"],
    )


def test_wall_faces_port_matches_gl_where_it_acts(walled):

    res = compare_or_skip(walled, CUSTOM, "water_refraction_beer_walls")
    check_gl_match(res, "gl_water_refraction_beer_walls_walled")
    beer = get_variant("water_refraction_beer").render(walled, CUSTOM).numpy()
    water = beer["mask"] > 0
    assert (
        np.abs(res["port"] - beer["color"]).max(-1)[water] > 1e-3
    ).sum() > 200  # the switch acts


def test_wall_faces_in_the_reflection_shader_match_gl(walled):
    """water_reflection.frag shares block [6] and its WALL_FACES switch with the refraction
    shader."""
    from shaders_port.ports import water_reflection
    from shaders_port.gl.renderer import GLRenderer

    defines = ("BEER_ATTENUATION", "WALL_FACES")
    out = water_reflection.render(walled, CUSTOM, defines=defines).numpy()
    with GLRenderer("water_reflection", walled, defines=defines) as r:
        rgba, gl_mask = r.render(CUSTOM)
    both = (out["mask"] > 0) & gl_mask
    diff = np.abs(out["color"] - rgba[..., :3]).max(-1)[both]
    assert both.sum() > 500
    assert diff.mean() <= 1e-3 and np.percentile(diff, 99.9) <= 1e-2, (diff.mean(), diff.max())
    beer = water_reflection.render(walled, CUSTOM, defines=("BEER_ATTENUATION",)).numpy()
    assert (np.abs(out["color"] - beer["color"]).max(-1)[both] > 1e-3).sum() > 200


@pytest.mark.parametrize(
    "param", ["water_color[1]", "water_color[2]", "absorption_g", "bumptex_mult"]
)
def test_wall_faces_jacobian_matches_central_differences(param):
    """waterColor now also enters where the switch acts (derivative F_T there); the others are
    those of the Beer-Lambert variant, the select carrying none."""
    inp = walled_inputs(width=48, height=36)
    v = get_variant("water_refraction_beer_walls")
    base, J = v.render_with_jacobian(inp, FD_AT, [param])
    base = base.numpy()
    assert _wall_lanes_at(base, inp).sum() > 20
    check_jacobian_column(
        lambda c: v.render(inp, c).numpy(),
        base,
        J[..., 0],
        FD_AT,
        param,
        ("iterations",),
        eps=FD_EPS.get(param, 1e-3),
    )


def _wall_lanes_at(out, inp):
    """Lanes where the switch acts, from the refraction-only render at FD_AT."""
    o = _refraction_only("water_refraction_beer_walls", inp, FD_AT)
    return (o["mask"] > 0) & (
        np.abs(o["color"] - np.float32(FD_AT.water_color[:3])).max(-1) <= 1e-7
    )
