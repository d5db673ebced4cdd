"""A level-of-detail policy as one shader (``study.export.policy_shader``,
``study.studies.lod_export``): the composition of the bands' GLSL, the blend's weights, the seam
strips, and the policy's shader on OpenGL (llvmpipe) against the port's mix of its bands."""

import numpy as np
import pytest

from helpers.gl import check_gl_match
from helpers.port_checks import small_inputs
from shaders_port.inputs import Constants
from study.export import policy_shader as ps
from study.studies import lod, lod_export

SNIPPET = """#version 330 core
uniform mat4 uModelViewProjectionMatrixInverse;
uniform vec4 waterColor = vec4(0.1, 0.2, 0.3, 1.0);
uniform sampler2D normalMap;
in vec4 vTexCoord0;
out vec4 fragColor;
const float SCALE = 2.0;
struct Hit { float t; vec3 SCALE2; };
vec3 lift(vec3 v) { Hit h; h.t = SCALE; return v * h.t; }
void main(void) { vec3 c = lift(waterColor.rgb); fragColor = vec4(c . xyz, 1.0); }
"""


def test_global_statements_and_their_names():
    """Statements at global scope split at ';' and at a function's closing brace (a struct's
    brace is not the end); each names what it declares; the tunable uniform with an
    initialiser is the band's own, the other uniforms, inputs and the output are interface."""
    st = ps.top_level(SNIPPET)
    names = [ps.declared_name(s) for s in st]
    assert names == ["uModelViewProjectionMatrixInverse", "waterColor", "normalMap",
                     "vTexCoord0", "fragColor", "SCALE", "Hit", "lift", "main"]  # fmt: skip
    interface = [ps.declared_name(s) for s in st if ps.is_interface(s)]
    assert interface == ["uModelViewProjectionMatrixInverse", "normalMap", "vTexCoord0",
                         "fragColor"]  # fmt: skip


def test_renaming_keeps_fields_and_swizzles():
    """A band's names get its prefix everywhere but after '.' and in a struct's members (a
    member named like a global of the band), and the output becomes the policy's colour."""
    own = {"SCALE", "Hit", "lift", "main", "waterColor", "xyz", "t"}
    body = ps.renamed(ps.top_level(SNIPPET)[-1], own, "b1_", "fragColor")
    assert "void b1_main(void)" in body
    assert "b1_lift(b1_waterColor.rgb)" in body
    assert "c . xyz" in body  # a swizzle named like a band's name is kept
    assert "policyColour = vec4" in body and "fragColor" not in body
    lift = ps.renamed(ps.top_level(SNIPPET)[-2], own, "b1_", "fragColor")
    assert "h.t = b1_SCALE" in lift and "b1_Hit h;" in lift
    hit = ps.renamed(ps.top_level(SNIPPET)[-3], own, "b1_", "fragColor")
    assert hit == "struct b1_Hit { float t; vec3 SCALE2; };"  # its members keep their names


def test_bands_that_disagree_on_their_interface_are_refused(monkeypatch):
    """Two bands declaring one uniform with two types cannot be one shader: the error names
    the uniform and both declarations."""
    other = SNIPPET.replace("uniform sampler2D normalMap;", "uniform samplerCube normalMap;")
    texts = iter([SNIPPET, other])
    monkeypatch.setattr(ps, "band_source", lambda band: next(texts))
    bands = [ps.Band("water_refraction", Constants()), ps.Band("water_refraction", Constants())]
    with pytest.raises(ValueError, match="normalMap.*samplerCube"):
        ps.compose(bands, "distance", [4.0], 0.05)


@pytest.mark.parametrize(
    "bounds, margin, bands, words",
    [
        ([4.0, 4.2], 0.05, 3, "overlap"),
        ([4.0], 0.0, 2, "margin must be positive"),
        ([4.0, 5.0], 0.05, 2, "need 1 bound"),
        ([-1.0], 0.05, 2, "positive and finite"),
    ],
)
def test_a_policy_that_cannot_be_drawn_is_refused(bounds, margin, bands, words):
    with pytest.raises(ValueError, match=words):
        ps.check_policy("distance", bounds, margin, bands)
    ps.check_policy("distance", [4.0, 4.5], 0.05, 3)  # 0.118 apart in the log: no overlap


def test_weights_blend_over_the_margin_only():
    """The weights sum to one, are one band's alone outside the margins, move smoothly within
    them (no step larger than a fine grid's share) and give each side half at a bound."""
    m = np.exp(np.linspace(np.log(1.0), np.log(10.0), 20001))
    bounds, margin = [2.0, 5.0], 0.1
    w = ps.band_weights(m, bounds, margin)
    np.testing.assert_allclose(w.sum(0), 1.0, atol=1e-12)
    assert (w >= 0).all()
    lm = np.log(m)
    inside = np.abs(lm[None, :] - np.log(bounds)[:, None]).min(0) < margin
    assert ((w[:, ~inside] == 0) | (w[:, ~inside] == 1)).all()
    assert np.abs(np.diff(w, axis=1)).max() < 2e-3
    for j, b in enumerate(bounds):
        np.testing.assert_allclose(ps.band_weights(np.array([b]), bounds, margin)[j : j + 2, 0],
                                   [0.5, 0.5])  # fmt: skip
    assert lod_export.margin_for("distance", [2.0, 2.1]) == pytest.approx(0.45 * np.log(2.1 / 2))


def test_seam_strips_lie_either_side_of_each_boundary():
    """A band map split at column 20 and at column 40: each boundary's strip is the 8 columns
    either side of it, on the water only."""
    h, w = 30, 60
    cols = np.tile(np.arange(w), (h, 1))
    band = np.searchsorted([19.5, 39.5], cols, side="right")
    water = np.ones((h, w), bool)
    water[:5] = False
    first, second = lod_export.strips(band, water, 8)
    np.testing.assert_array_equal(first, water & (cols >= 12) & (cols < 28))
    np.testing.assert_array_equal(second, water & (cols >= 32) & (cols < 48))


def _bands_and_ports(inputs, measure: str):
    """Three bands of two files on the synthetic scene, split at the terciles of ``measure``:
    (bands, bounds in the shader's unit, margin, measure map, ports, uploaded inputs)."""
    from shaders_port.variants import get_variant

    bands = [
        ps.Band("water_refraction_beer_disc", Constants(attenuation_distance=3.0), "near"),
        ps.Band("water_reflection", Constants(specular_strength=4.0), "middle"),
        ps.Band("water_refraction", Constants(water_color=(0.3, 0.1, 0.1, 1.0)), "far"),
    ]
    w, h = inputs.width, inputs.height
    maps = lod.band_measures(inputs.view_proj, inputs.viewpos, w, h)
    m = lod_export.shader_measure(measure, maps, w, h)
    bounds = list(np.nanquantile(m, [1 / 3, 2 / 3]))
    margin = lod_export.margin_for(measure, bounds)
    ports = [get_variant(b.variant).render(inputs, b.constants).numpy() for b in bands]
    uploaded = [get_variant(b.variant).prepare_inputs(inputs) for b in bands]
    return bands, bounds, margin, m, ports, uploaded


@pytest.mark.parametrize("measure, share", [("distance", 1.0), ("footprint", 1.0),
                                            ("footprint", 0.01)])  # fmt: skip
def test_the_policy_shader_draws_the_ports_mix_of_its_bands(measure, share):
    """The composed shader on llvmpipe matches the port's images of its three bands mixed by
    the weights of the measure the study computes (the GL check's thresholds), with pixels in
    every band and in the margins; with a margin of a hundredth, so that the shader's float32
    measure must agree with the study's to about 1e-4 (nearly a hard switch), too. The same
    shader with its bands' order reversed does not match (the check can fail)."""
    pytest.importorskip("moderngl")
    inputs = small_inputs().with_resolution(96, 72)
    bands, bounds, margin, m, ports, uploaded = _bands_and_ports(inputs, measure)
    margin *= share
    weights = ps.band_weights(m, bounds, margin)
    water = np.isfinite(m)
    for k in range(3):
        assert (water & (weights[k] == 1)).sum() > 200
    if share == 1.0:
        assert (water & (weights.max(0) < 1)).sum() > 20  # pixels in a margin
    src = ps.compose(bands, measure, bounds, margin)
    assert src.count("_main();") == 3
    try:
        res = lod_export.gl_check_policy(src, weights, ports, uploaded, water)
    except RuntimeError as exc:
        if "EGL" in str(exc) or "context" in str(exc).lower():
            pytest.skip(f"no headless OpenGL here: {exc}")
        raise
    check_gl_match(res, f"policy_shader_{measure}_{share}")
    wrong = ps.compose(bands[::-1], measure, bounds, margin)
    assert lod_export.gl_check_policy(wrong, weights, ports, uploaded, water)["p999"] > 1e-2


def test_the_bands_inputs_are_merged_and_mixed_precisions_refused():
    """The policy's inputs hold every optional input any band reads (here a local cube map
    only the second band's inputs have), and bands that read the textures at different
    precisions (8-bit 'game' textures beside float ones) cannot be one shader."""
    import dataclasses

    from shaders_port.inputs import game_precision

    base = small_inputs()
    cube = np.ones((6, 4, 4, 3), np.float32)
    boxed = dataclasses.replace(base, box_cubemap=cube, box_min=np.zeros(3, np.float32),
                                box_max=np.ones(3, np.float32))  # fmt: skip
    merged = lod_export.merged_inputs([base, boxed])
    assert merged.box_cubemap is cube and base.box_cubemap is None
    np.testing.assert_array_equal(merged.normal_map, base.normal_map)
    with pytest.raises(ValueError, match="different precisions"):
        lod_export.merged_inputs([base, game_precision(base)])
