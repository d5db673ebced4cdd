"""The OpenGL runner (headless EGL) on the synthetic inputs."""

from __future__ import annotations

import numpy as np
import pytest

from shaders_port import Constants
from shaders_port.gl.renderer import (
    GLRenderer,
    alternate_frames,
    create_egl_context,
    run_glsl,
    time_glsl,
)
from shaders_port.glsl_text import read_source, write_constants
from helpers.images import FAILURES, save_comparison
from helpers.synthetic import synthetic_inputs

VARIANTS = [
    ("water_refraction", ()),
    ("water_refraction", ("NOREFLECTION",)),
    ("water_reflection", ()),
]


@pytest.fixture(scope="module")
def inputs():
    try:
        create_egl_context().release()
    except RuntimeError as exc:
        pytest.skip(str(exc))
    return synthetic_inputs(width=64, height=48)


def assert_images_close(tag, actual, expected, atol):
    err = np.abs(actual - expected).max()
    if not err <= atol:
        save_comparison(tag, actual[..., :3], expected[..., :3])
    assert err <= atol, f"{tag}: max |difference| {err} > {atol}; images in {FAILURES}"


def projected_quad_mask(inp):
    """(H, W) bool of pixel centres inside the projected water quad, and (H, W) bool of pixel
    centres within 1e-3 px of its edges (where rasterisation rules decide)."""
    x0, z0, x1, z1 = inp.water_rect
    corners = np.array([[x0, 0, z0, 1], [x1, 0, z0, 1], [x1, 0, z1, 1], [x0, 0, z1, 1]], float)
    clip = corners @ inp.view_proj.astype(float).T
    assert np.all(clip[:, 3] > 0), "test scene: quad must lie in front of the camera"
    ndc = clip[:, :2] / clip[:, 3:4]
    win = np.stack([(ndc[:, 0] + 1) * inp.width / 2, (1 - ndc[:, 1]) * inp.height / 2], 1)
    px, py = np.meshgrid(np.arange(inp.width) + 0.5, np.arange(inp.height) + 0.5)
    signed = []
    for k in range(4):
        a, b = win[k], win[(k + 1) % 4]
        e = b - a
        signed.append((e[0] * (py - a[1]) - e[1] * (px - a[0])) / np.hypot(*e))
    signed = np.stack(signed)
    if signed.sum() < 0:
        signed = -signed
    return np.all(signed > 0, 0), np.any(np.abs(signed) < 1e-3, 0)


@pytest.mark.parametrize("name,defines", VARIANTS)
def test_finite_inside_zero_outside(inputs, name, defines):
    rgba, mask = run_glsl(name, inputs, Constants(), defines=defines)
    assert rgba.shape == (48, 64, 4) and rgba.dtype == np.float32 and mask.dtype == bool
    assert mask.sum() > 0.2 * mask.size
    assert np.all(np.isfinite(rgba[mask]))
    assert np.all(rgba[~mask] == 0.0)
    # refraction colour of a checker floor in [0.2, 0.9] mixed with water colour: plausible range
    assert 0.05 < rgba[mask][:, :3].mean() < 1.5


def test_mask_matches_projected_quad(inputs):
    _, mask = run_glsl("water_refraction", inputs, Constants())
    inside, edge = projected_quad_mask(inputs)
    bad = (mask != inside) & ~edge
    assert not bad.any(), f"{bad.sum()} pixels differ from the projected quad"
    # row 0 is the top: the camera looks down at the pool, the far edge is near the top
    assert mask[:, inputs.width // 2].argmax() > 0


def _attenuation(renderer, base: Constants) -> np.ndarray:
    """Per-pixel attenuation a = clamp(travelLength / ATTENUATION_DISTANCE, 0, 1) from the
    linearity of the NOREFLECTION output in waterColor:
    out = (1 - a) * vRefraction + a * waterColor."""
    black, _ = renderer.render(base.replace(water_color=(0.0, 0.0, 0.0, 1.0)))
    white, _ = renderer.render(base.replace(water_color=(1.0, 1.0, 1.0, 1.0)))
    return white[..., :3] - black[..., :3]


def test_water_color_and_attenuation_distance(inputs):
    with GLRenderer("water_refraction", inputs, defines=("NOREFLECTION",)) as r:
        mask = r.render(Constants())[1]
        a = _attenuation(r, Constants())
        # same weight in every channel, in [0, 1], positive on every water pixel
        assert np.allclose(a[..., 0], a[..., 1], atol=1e-5) and np.allclose(
            a[..., 0], a[..., 2], atol=1e-5
        )
        a = a[..., 0]
        assert np.all(a[~mask] == 0)
        assert np.all((a[mask] > 0.01) & (a[mask] <= 1 + 1e-6))
        # doubling ATTENUATION_DISTANCE halves the (unclamped) weight: the ray is unchanged
        a2 = _attenuation(r, Constants(attenuation_distance=15.0))[..., 0]
        unclamped = mask & (a < 0.99)
        assert unclamped.sum() > 0.5 * mask.sum()
        assert np.allclose(a2[unclamped], a[unclamped] / 2, rtol=1e-4, atol=1e-6)
        # a short distance saturates the weight: output = waterColor exactly
        out, _ = r.render(Constants(attenuation_distance=1e-3, water_color=(0.1, 0.4, 0.7, 1.0)))
        assert np.allclose(out[mask], [0.1, 0.4, 0.7, 1.0], atol=1e-6)


def test_reflect_color_and_specular_act_on_reflection_only(inputs):
    with GLRenderer("water_refraction", inputs) as r:
        base, mask = r.render(Constants())
        dark, _ = r.render(Constants(reflect_color=(0.0, 0.0, 0.0, 0.0), specular_strength=0.0))
        no_refl, _ = run_glsl("water_refraction", inputs, Constants(), defines=("NOREFLECTION",))
    # without reflection colour and highlight, out = vRefraction * T(NdotV), T from the LUT
    ratio = dark[mask][:, :3] / no_refl[mask][:, :3]
    assert np.allclose(ratio, ratio[:, :1], atol=1e-5)  # one factor for all channels
    lut_t = inputs.fresnel_lut[:, 0]
    assert np.all((ratio >= lut_t.min() - 1e-6) & (ratio <= lut_t.max() + 1e-6))
    assert np.isclose(dark[mask][:, 3], ratio[:, 0], atol=1e-5).all()  # alpha: 0*g + 1*T
    assert np.all(base[mask][:, :3] > dark[mask][:, :3])  # sky adds light everywhere
    assert np.all(base[~mask] == 0) and np.all(dark[~mask] == 0)


def test_reflection_raycast_sees_the_wall(inputs):
    """water_reflection differs from water_refraction only where the reflected ray hits the
    red wall (x < -1.67): there red rises relative to blue."""
    ref, mask = run_glsl("water_refraction", inputs, Constants())
    rr, _ = run_glsl("water_reflection", inputs, Constants())
    diff = np.abs(rr - ref).max(-1)
    changed = mask & (diff > 1e-5)
    assert 0 < changed.sum() < 0.5 * mask.sum()
    assert (rr - ref)[changed][:, 0].mean() > 0 > (rr - ref)[changed][:, 2].mean()
    assert changed[:, : inputs.width // 2].sum() > changed[:, inputs.width // 2 :].sum()


@pytest.mark.parametrize("name", ["water_refraction", "water_reflection"])
def test_exported_source_renders_like_constants(inputs, name):
    custom = Constants(
        attenuation_distance=4.0,
        steps_grazing=14.0,
        steps_steep=2.0,
        loop_cap=60,
        bumptex_mult=0.5,
        refr_coeff=0.74,
        water_color=(0.02, 0.3, 0.2, 1.0),
        reflect_color=(0.8, 0.9, 1.0, 1.0),
        specular_exponent=128.0,
        refl_height_cut=1.0,
    )
    exported = write_constants(read_source(name, "frag", "core"), custom)
    with GLRenderer(name, inputs, source=exported) as r:
        got, mask = r.render(None)  # the file as an engine would use it: uniforms not set
    with GLRenderer(name, inputs) as r:
        want, _ = r.render(custom)
        default, _ = r.render(None)
    assert_images_close(f"export_{name}", got, want, atol=1e-6)
    assert np.abs(got - default)[mask].max() > 1e-2  # the export really changed the image


@pytest.mark.parametrize("name,defines", VARIANTS)
def test_compat_source_runs_like_core(inputs, name, defines):
    core, _ = run_glsl(name, inputs, Constants(), defines=defines)
    compat, _ = run_glsl(name, inputs, Constants(), defines=defines, dialect="compat")
    assert_images_close(f"compat_{name}_{'_'.join(defines)}", compat, core, atol=0.0)


def test_default_source_without_constants_equals_defaults(inputs):
    with GLRenderer("water_reflection", inputs) as r:
        a, _ = r.render(None)
        b, _ = r.render(Constants())
    assert_images_close("defaults_none", a, b, atol=1e-6)


def test_bad_requests_refused(inputs):
    with pytest.raises(ValueError, match="not a preprocessor name"):
        GLRenderer("water_reflection", inputs, defines=("NO REFLECTION",))
    with pytest.raises(ValueError, match="unknown water shader"):
        GLRenderer("water", inputs)
    with GLRenderer("water_refraction", inputs) as r:
        with pytest.raises(ValueError, match="ATTENUATION_DISTANCE"):
            r.render(Constants(attenuation_distance=float("nan")))
        with pytest.raises(RuntimeError, match="OpenGL rejected"):
            r._program("#version 330 core\nvoid main(void) { undefined_name = 1.0; }\n")


def test_time_glsl_returns_positive_seconds(inputs):
    t = time_glsl(inputs, Constants(), n=3)
    assert len(t) == 3 and all(0 < x < 10 for x in t)


def test_cubemap_faces_filtered_without_seams(inputs):
    """Seamless cube filtering is off: a direction next to the +X/+Y edge reads +X only."""
    import dataclasses

    cube = np.broadcast_to(np.arange(6, dtype=np.float32)[:, None, None, None], (6, 4, 4, 3))
    inp = dataclasses.replace(inputs, cubemap=np.ascontiguousarray(cube), width=4, height=4)
    frag = (
        "#version 330 core\nuniform samplerCube reflectionTexture; out vec4 o;\n"
        "void main(void) { o = texture(reflectionTexture, vec3(1.0, 0.999, 0.2)); }\n"
    )
    vert = "#version 330 core\nin vec2 p; void main(void) { gl_Position = vec4(p, 0, 1); }\n"
    with GLRenderer("water_refraction", inp) as r:
        prog = r.ctx.program(vertex_shader=vert, fragment_shader=frag)
        vbo = r.ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], np.float32).tobytes())
        vao = r.ctx.vertex_array(prog, [(vbo, "2f", "p")])
        prog["reflectionTexture"].value = 3
        r._bind_textures()
        r.fbo.use()
        vao.render()
        out = r._read()
    assert np.all(out[..., :3] == 0.0), out[0, 0]  # face +X holds 0, face +Y holds 2


def test_missing_egl_names_the_packages(monkeypatch):
    import moderngl

    def fail(**kw):
        raise Exception("libEGL.so.1: cannot open shared object file")

    monkeypatch.setattr(moderngl, "create_context", fail)
    with pytest.raises(RuntimeError, match="libegl1 libegl-mesa0 libgl1-mesa-dri"):
        create_egl_context()


def test_renderer_keeps_a_bounded_number_of_programs():
    """Many constant sets through one renderer: compiled programs are released beyond the cap,
    and a constant set seen before still renders the same after its program was dropped."""
    from shaders_port import Constants
    from shaders_port.gl.renderer import GLRenderer
    from helpers.synthetic import synthetic_inputs

    inputs = synthetic_inputs(24, 16)
    with GLRenderer("water_refraction", inputs) as r:
        first, _ = r.render(Constants(attenuation_distance=2.0))
        for k in range(r.MAX_PROGRAMS + 4):
            r.render(Constants(attenuation_distance=3.0 + k))
        assert len(r._programs) == r.MAX_PROGRAMS
        again, _ = r.render(Constants(attenuation_distance=2.0))
    assert np.array_equal(first, again)


@pytest.mark.parametrize("kind", ["compatibility", "es"])
def test_a_renderer_keeps_drawing_after_another_kind_of_context_is_released(kind, inputs):
    """moderngl draws on the current context: a compatibility or ES context made and released
    while a core renderer is open hands the current context back to it."""
    from shaders_port import Constants
    from shaders_port.gl.contexts import create_context, describe

    with GLRenderer("water_refraction", inputs) as r:
        before = r.render(Constants())[0]
        try:
            other = create_context(kind)
        except RuntimeError as exc:
            pytest.skip(f"no {kind} context here: {exc}")
        assert ("OpenGL ES" in describe(other)) == (kind == "es")
        other.release()
        after = r.render(Constants())[0]
    assert np.abs(before).max() > 0.1
    np.testing.assert_array_equal(after, before)


def test_alternate_frames_times_two_contexts_in_turn_and_leaves_each_drawing_its_own(inputs):
    """Frames timed in turn on two renderers (each on its own context, made current frame by
    frame): n times each, and afterwards each still draws what a renderer of its own draws,
    one on a core and one on a compatibility-profile context."""
    c = Constants(water_color=(0.1, 0.3, 0.2, 1.0))
    with (
        GLRenderer("water_refraction", inputs) as a,
        GLRenderer("water_reflection", inputs, dialect="compat") as b,
    ):
        ta, tb = alternate_frames([(a, Constants()), (b, c)], 3, warmup=2)
        assert len(ta) == len(tb) == 3 and min(ta + tb) > 0
        with b.ctx:
            after_b = b.render(c)[0]
        with a.ctx:
            after_a = a.render(Constants())[0]
    alone_a = run_glsl("water_refraction", inputs, Constants())[0]
    alone_b = run_glsl("water_reflection", inputs, c, dialect="compat")[0]
    assert_images_close("alternate_a", after_a, alone_a, 0.0)
    assert_images_close("alternate_b", after_b, alone_b, 0.0)


def test_the_maps_derived_from_the_normal_map_are_uploaded_for_a_program_that_reads_them(inputs):
    """The slope moments (mipmapped) and the heights exist only on a renderer whose shader
    reads them (each renderer uploads nothing else it would not bind)."""
    with GLRenderer("water_refraction", inputs) as plain:
        plain.render(Constants())
        assert not {"slopeMoments", "heightMap"} & set(plain.texture_units())
    with GLRenderer("water_refraction", inputs, defines=("PARALLAX_OFFSET",)) as parallax:
        parallax.render(Constants())
        units = parallax.texture_units()
        assert "heightMap" in units and "slopeMoments" not in units
    with GLRenderer("water_refraction", inputs, defines=("LEAN_NORMALS",)) as lean:
        lean.render(Constants())
        _, tex, _ = lean.texture_units()["slopeMoments"]
        assert tex.width == inputs.normal_map.shape[1] and tex.components == 4
