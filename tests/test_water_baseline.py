"""The baseline water shader (seeds 001-004, ``water_baseline`` and its variants): the Dr.Jit
port against the core GLSL on llvmpipe (same bounds as tests/test_gl_differential.py), its
forward-mode derivatives against central differences, its diagnostics and input checks."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.synthetic import synthetic_baseline_inputs, synthetic_inputs
from shaders_port import Constants
from shaders_port.ports import water_baseline
from shaders_port.variants import VARIANTS, get_variant
from helpers.gl import check_gl_match, compare_or_skip
from helpers.port_checks import FD_NOISE, FD_RTOL, perturbed

BASELINES = ("water_baseline", "water_baseline_flat", "water_baseline_noplanar")
CUSTOM = Constants(
    refraction_index=0.6,
    refraction_strength=0.05,
    chromatic_dispersion=0.01,
    reflect_distortion=0.2,
    attenuation_distance=2.0,
    specular_strength=1.3,
    specular_exponent=32.0,
    water_color=(0.1, 0.3, 0.25, 1.0),
    reflect_color=(0.9, 0.95, 1.0, 1.0),
)
FD_CONSTANTS = Constants(
    attenuation_distance=2.0,
    specular_exponent=32.0,
    refraction_strength=0.05,
    chromatic_dispersion=0.01,
)
FD_EPS = {
    "refraction_index": 3e-4,
    "refraction_strength": 2e-4,
    "chromatic_dispersion": 2e-4,
    "reflect_distortion": 1e-3,
    "attenuation_distance": 1e-3,
    "specular_strength": 1e-3,
    "specular_exponent": 1e-3,
    "water_color[0]": 1e-3,
    "water_color[2]": 1e-3,
    "reflect_color[1]": 1e-3,
}


@pytest.fixture(scope="module")
def inputs():
    return synthetic_baseline_inputs(width=96, height=72)


@pytest.fixture(scope="module")
def small():
    return synthetic_baseline_inputs(width=48, height=36)


# ---- port vs GLSL on llvmpipe ------------------------------------------------------------


@pytest.mark.parametrize("which", ["default", "custom"])
@pytest.mark.parametrize("variant", BASELINES)
def test_port_matches_gl(inputs, variant, which):
    pytest.importorskip("moderngl")

    constants = Constants() if which == "default" else CUSTOM
    res = compare_or_skip(inputs, constants, variant)
    check_gl_match(res, f"gl_{variant}_{which}")
    assert res["n_nonfinite"] == 0
    # measured: max |diff| ~1e-5 (float32 rounding); a systematic difference must not pass
    assert res["mean_abs"] <= 1e-4 and res["p999"] <= 1e-3, (res["mean_abs"], res["p999"])


def test_compat_source_runs_like_core(inputs):
    pytest.importorskip("moderngl")
    from shaders_port.gl.renderer import GLRenderer

    try:
        with (
            GLRenderer("water_baseline", inputs, dialect="core") as g1,
            GLRenderer("water_baseline", inputs, dialect="compat") as g2,
        ):
            a, _ = g1.render(CUSTOM)
            b, _ = g2.render(CUSTOM)
    except RuntimeError as exc:
        if "EGL" in str(exc) or "context" in str(exc).lower():
            pytest.skip(f"no headless OpenGL here: {exc}")
        raise
    assert np.array_equal(a, b)


# ---- derivatives ------------------------------------------------------------------------

_FD_NAMES = list(FD_EPS)


@pytest.fixture(scope="module")
def jacobian(small):
    out, J = water_baseline.render_with_jacobian(small, FD_CONSTANTS, _FD_NAMES)
    return out.numpy(), J


@pytest.mark.parametrize("name", _FD_NAMES)
def test_jacobian_matches_central_differences(small, jacobian, name):
    base, J = jacobian
    render = lambda c: water_baseline.render(small, c).numpy()  # noqa: E731
    assert np.array_equal(render(FD_CONSTANTS)["color"], base["color"])
    cp, h = perturbed(FD_CONSTANTS, name, FD_EPS[name])
    cm, _ = perturbed(FD_CONSTANTS, name, -FD_EPS[name])
    p, m = render(cp), render(cm)
    fd = (p["color"] - m["color"]) / (2 * h)
    fp, fm = (p["color"] - base["color"]) / h, (base["color"] - m["color"]) / h
    noise = FD_NOISE / h
    water = base["mask"] > 0
    # pixels whose one-sided slopes agree
    # (no texel edge of a bilinear lookup or clamp in the stencil)
    smooth = water & (np.abs(fp - fm) <= 0.2 * np.abs(fd) + 2 * noise).all(-1)
    assert smooth.sum() >= 0.8 * water.sum(), (
        f"{name}: only {smooth.sum()} of {water.sum()} comparable"
    )
    Jn = J[..., _FD_NAMES.index(name)]
    err = np.abs(Jn - fd)
    bad = smooth & ~(err <= 2 * noise + FD_RTOL * np.abs(fd)).all(-1)
    assert np.abs(fd[smooth]).max() > 10 * noise, f"{name}: colour does not depend on it here"
    assert not bad.any(), (
        f"{name}: forward-mode derivative differs from central differences at "
        f"{bad.sum()} pixels (worst |err| {err.max(-1)[bad].max():.3g})"
    )


def test_flat_variant_refraction_index_derivative(small):
    out, J = water_baseline.render_with_jacobian(
        small, FD_CONSTANTS, ["refraction_index"], defines=("FLAT_WATER",)
    )
    cp, h = perturbed(FD_CONSTANTS, "refraction_index", 3e-4)
    cm, _ = perturbed(FD_CONSTANTS, "refraction_index", -3e-4)
    r = lambda c: water_baseline.render(small, c, defines=("FLAT_WATER",)).numpy()["color"]  # noqa: E731
    fd = (r(cp) - r(cm)) / (2 * h)
    water = out.numpy()["mask"] > 0
    err = np.abs(J[..., 0] - fd).max(-1)[water]
    scale = np.abs(fd).max(-1)[water]
    assert scale.max() > 1e-2
    # bilinear texel edges make a few pixels' central differences straddle a kink
    assert np.mean(err <= 2 * FD_NOISE / h + FD_RTOL * scale) >= 0.9


@pytest.mark.parametrize("name", ["reflect_color[1]", "water_color[2]", "specular_strength"])
def test_cube_map_without_refraction_derivatives(small, name):
    defines = ("NO_REFRACTION", "CUBE_REFLECTION")
    out, J = water_baseline.render_with_jacobian(small, FD_CONSTANTS, [name], defines=defines)
    cp, h = perturbed(FD_CONSTANTS, name, FD_EPS[name])
    cm, _ = perturbed(FD_CONSTANTS, name, -FD_EPS[name])
    r = lambda c: water_baseline.render(small, c, defines=defines).numpy()["color"]  # noqa: E731
    fd = (r(cp) - r(cm)) / (2 * h)
    water = out.numpy()["mask"] > 0
    err = np.abs(J[..., 0] - fd).max(-1)[water]
    scale = np.abs(fd).max(-1)[water]
    assert scale.max() > 1e-2
    # linear in these constants: no kink in the stencil
    assert (err <= 2 * FD_NOISE / h + FD_RTOL * scale).all(), err.max()


def test_no_refraction_reads_no_refraction_constant():
    reads = set(get_variant("water_baseline_norefraction_cube").reads())
    assert not reads & {"refraction_index", "refraction_strength", "chromatic_dispersion"}
    assert not reads & {"attenuation_distance", "reflect_distortion"}
    assert {"water_color", "reflect_color", "specular_strength"} <= reads


def test_constants_not_read_are_rejected_by_the_jacobian(small):
    with pytest.raises(ValueError, match=r"does not read \['bumptex_mult'\]"):
        water_baseline.render_with_jacobian(
            small, FD_CONSTANTS, ["bumptex_mult", "refraction_index"]
        )


# ---- diagnostics, registry, inputs -------------------------------------------------------


def test_diagnostics_count_fetches_and_no_iterations(small):
    expected = {
        "water_baseline": 4 + 1 + 3 + 1 + 1,
        "water_baseline_flat": 1 + 1 + 1 + 1,
        "water_baseline_noplanar": 4 + 1 + 3 + 1 + 1,
    }
    # the cube map needs no mirrored-camera pass; without refraction no depth or scene reads
    cube = {
        "water_baseline_cube": 4 + 1 + 3 + 1 + 1,
        "water_baseline_flat_cube": 1 + 1 + 1 + 1,
        "water_baseline_norefraction_cube": 4 + 1 + 1,
    }
    expected.update({k: n - water_baseline.PASS_FETCHES for k, n in cube.items()})
    expected["water_baseline_flat_norefraction"] = 1 + 1
    for name, n in expected.items():
        out = get_variant(name).render(small).numpy()
        water = out["mask"] > 0
        assert (out["fetches"][water] == n + water_baseline.PASS_FETCHES).all(), name
        assert (out["iterations"] == 0).all() and (out["nonfinite"] == 0).all()
        assert np.isfinite(out["color"]).all() and out["color"][water].min() >= 0


def test_frozen_replay_at_another_resolution(small, monkeypatch):
    # a recorded kernel replayed for another lane count must not reuse the old sizes
    from shaders_port.pipeline import frame as _frame

    monkeypatch.setattr(_frame, "USE_FROZEN", True)
    for (w, h), d in (
        ((48, 36), ()),
        ((40, 30), ()),
        ((48, 36), ("FLAT_WATER",)),
        ((48, 36), ()),
        ((48, 36), ("NO_PLANAR_REFRACTION",)),
    ):
        inp = small.with_resolution(w, h)
        out = water_baseline.render(inp, CUSTOM, defines=d).numpy()
        monkeypatch.setattr(_frame, "USE_FROZEN", False)
        traced = water_baseline.render(inp, CUSTOM, defines=d).numpy()
        monkeypatch.setattr(_frame, "USE_FROZEN", True)
        for k in ("color", "fetches", "iterations", "nonfinite"):
            assert np.array_equal(out[k], traced[k]), (w, h, k)


def test_flat_normal_map_is_finite_and_undistorted(small):
    # calm water: every wave normal is the mirror normal; seed 002's offset must vanish (fix 15)
    import dataclasses

    calm = dataclasses.replace(small, normal_map=np.tile(np.float32([0.5, 1.0, 0.5]), (8, 8, 1)))
    c = CUSTOM.replace(chromatic_dispersion=0.0)  # FLAT_WATER has no dispersion either
    with_waves = get_variant("water_baseline").render(calm, c).numpy()
    flat = get_variant("water_baseline_flat").render(calm, c).numpy()
    assert (with_waves["nonfinite"] == 0).all()
    assert np.abs(with_waves["color"] - flat["color"]).max() < 1e-5


def test_variants_differ_where_they_should(small):
    full = get_variant("water_baseline").render(small, CUSTOM).numpy()["color"]
    flat = get_variant("water_baseline_flat").render(small, CUSTOM).numpy()["color"]
    noplanar = get_variant("water_baseline_noplanar").render(small, CUSTOM).numpy()["color"]
    assert np.abs(full - flat).max() > 1e-2 and np.abs(full - noplanar).max() > 1e-2
    # refraction_index = 1 is no refraction: the planar term is the identity map
    c1 = CUSTOM.replace(refraction_index=1.0)
    a = get_variant("water_baseline").render(small, c1).numpy()["color"]
    b = get_variant("water_baseline_noplanar").render(small, c1).numpy()["color"]
    assert np.abs(a - b).max() < 1e-3


def test_reads_are_the_constants_the_active_code_uses():
    assert set(VARIANTS["water_baseline"].reads()) == set(water_baseline.READS)
    assert set(VARIANTS["water_baseline_noplanar"].reads()) == set(water_baseline.READS) - {
        "refraction_index"
    }
    assert set(VARIANTS["water_baseline_flat"].reads()) == set(water_baseline.READS) - {
        "reflect_distortion",
        "refraction_strength",
        "chromatic_dispersion",
    }
    assert "bumptex_mult" not in VARIANTS["water_baseline"].reads()
    assert "reflect_distortion" not in VARIANTS["water_refraction"].reads()
    # NOREFLECTION drops the reflection, its colour and the highlight
    assert not {"reflect_color", "specular_strength", "specular_exponent"} & set(
        VARIANTS["water_refraction_noreflection"].reads()
    )
    assert {"reflect_color", "specular_strength"} <= set(VARIANTS["water_refraction"].reads())
    with pytest.raises(ValueError, match="does not read"):
        water_baseline.render_with_jacobian(
            synthetic_baseline_inputs(16, 12),
            Constants(),
            ["refraction_strength"],
            defines=("FLAT_WATER",),
        )


def test_missing_screen_buffers_are_a_clear_error():
    with pytest.raises(ValueError, match="scene_color.*with_baseline_inputs"):
        water_baseline.render(synthetic_inputs(32, 24))


def test_unknown_define_is_rejected(small):
    with pytest.raises(ValueError, match="does not implement #define NOREFLECTION"):
        water_baseline.render(small, defines=("NOREFLECTION",))


def test_optional_inputs_survive_save_and_load(small, tmp_path):
    from shaders_port import ShaderInputs

    small.save(tmp_path / "i.npz")
    back = ShaderInputs.load(tmp_path / "i.npz")
    assert np.array_equal(back.scene_depth, small.scene_depth)
    assert np.array_equal(back.reflection_view_proj, small.reflection_view_proj)
    plain = synthetic_inputs(16, 12)
    plain.save(tmp_path / "p.npz")
    assert ShaderInputs.load(tmp_path / "p.npz").scene_color is None


# ---- the GLSL text: banners, the seeds' code kept, the constants block -----------------------

BANNERS = [
    "Eye and light vectors",
    "Normal map: average four layers",
    "Planar refraction (seed 001)",
    "Normal-map distortion and chromatic dispersion (seed 003)",
    "Depth tint",
    "Planar reflection (seed 004), distorted by the wave normal (seed 002)",
    "Specular highlight",
    "Fresnel combine",
]


def test_banners_in_order_in_glsl_and_port():
    import inspect
    from shaders_port.glsl_text import read_source

    for text in (read_source("water_baseline"), inspect.getsource(water_baseline)):
        pos = [text.find(f"[{i}] {t}") for i, t in enumerate(BANNERS, 1)]
        assert all(p >= 0 for p in pos) and pos == sorted(pos), dict(zip(BANNERS, pos))


def test_seed_code_kept():
    from shaders_port.glsl_text import read_source

    code = "\n".join(ln.split("//")[0] for ln in read_source("water_baseline").split("\n"))
    # 001 (float3 -> vec3, _WorldSpaceCameraPos -> viewpos)
    for line in (
        "vec3 refraction = refract(worldRayDir, normalize(worldPlaneNormal), refractionIndex);",
        "float denom = dot(-worldPlaneNormal, -refraction);",
        "float t = dot(p010, -worldPlaneNormal) / denom;",
        "vec3 intersection = vertexPosition + refraction * -t;",
        "return viewerPosition + normalize(originToIntersection) * length(worldRay);",
        # 002
        "vec3 flatNormal = vBumpTex - dot (vBumpTex, mirrorNormal) * mirrorNormal;",
        "vec3 eyeNormal = gl_NormalMatrix * flatNormal;",
        "normalize (eyeNormal.xy) * length (flatNormal) * REFLECT_DISTORTION : vec2(0.0, 0.0);",
        # 003 (the red and blue channels shifted alike: kept)
        "vec2 newUV = refractedUV + bump * refractionStrength;",
        "texture2D(sceneColor, newUV - chromaticDispersion).r,",
        "texture2D(sceneColor, newUV).g, texture2D(sceneColor, newUV - chromaticDispersion).b);",
        # 004
        "vec2 vDeviceReflection = vClipReflection.st / vClipReflection.q;",
        "vec2 vTextureReflection = vec2(0.5, 0.5) + 0.5 * vDeviceReflection;",
        "reflectionTextureColor.a = 1.0;",
    ):
        assert line in code, line


@pytest.mark.parametrize("dialect", ["compat", "core"])
def test_block_holds_the_defaults_and_round_trips(dialect):
    from shaders_port.glsl_text import (
        compile_check,
        declared_constants,
        read_constants,
        read_source,
        with_define,
        write_constants,
    )

    src = read_source("water_baseline", "frag", dialect)
    assert set(declared_constants(src)) == set(water_baseline.READS)
    assert write_constants(src, Constants()) == src
    back = read_constants(write_constants(src, CUSTOM))
    for k in water_baseline.READS:
        assert np.allclose(np.float32(getattr(back, k)), np.float32(getattr(CUSTOM, k))), k
    import shutil

    if shutil.which("glslangValidator"):
        for d in water_baseline.DEFINES:
            compile_check(with_define(src, d), "frag")


def test_reflection_offset_moves_the_image_as_source_002_does():
    """Source 004's mirrored camera is flipped in y: its projective coordinate is
    ``(s, 1 - t)`` of the window coordinate ``(s, t) = gl_FragCoord.xy / screenSize`` on every
    water pixel. Source 002 adds its offset in window coordinates, so the shader adds
    ``(offset.x, -offset.y)`` to 004's coordinate: in window terms, the sample moves by +offset."""
    import drjit as dr

    from shaders_port.pipeline.frame import resolve_constants
    from shaders_port.pipeline.raster import prepare
    from shaders_port.pipeline.texture import backend_types
    from shaders_port.ports.water_baseline import MIRROR_NORMAL, mat4_vec4, planar_reflection

    inp = synthetic_baseline_inputs(64, 48)
    m = backend_types("llvm")
    P = prepare(inp, m)
    S = water_baseline.screen_state(m, P, inp)
    wp = P.varyingVecWorldPosition
    clip = mat4_vec4(m, S.o2v_projection_reflection, wp.x, 0.0, wp.z, 1.0)
    s_refl = (0.5 + 0.5 * clip.x / clip.w).numpy()
    t_refl = (0.5 + 0.5 * clip.y / clip.w).numpy()
    s_win, t_win = S.bumpUV[0].numpy(), S.bumpUV[1].numpy()
    np.testing.assert_allclose(s_refl, s_win, atol=1e-6)
    np.testing.assert_allclose(t_refl, 1.0 - t_win, atol=1e-6)
    # a tilted wave normal: the window-space displacement of the sample is 002's offset
    C = resolve_constants(m, Constants(reflect_distortion=0.1), "replay")
    normal = dr.normalize(m.Array3f(0.3, 1.0, -0.2))
    mirror = m.Array3f(*MIRROR_NORMAL)
    _, (s_tex, t_tex) = planar_reflection(m, P, S, C, normal, mirror, False)
    flat = normal - dr.dot(normal, mirror) * mirror
    N = S.normal_matrix
    eye = [sum(N[i][j] * flat[j] for j in range(3)) for i in range(2)]
    length = dr.sqrt(eye[0] * eye[0] + eye[1] * eye[1])
    offset = [float((e / length * dr.norm(flat) * 0.1).numpy()[0]) for e in eye]
    np.testing.assert_allclose(s_tex.numpy() - s_win, offset[0], atol=1e-5)
    np.testing.assert_allclose((1.0 - t_tex.numpy()) - t_win, offset[1], atol=1e-5)
    assert abs(offset[1]) > 1e-3  # the vertical part is there to be checked
