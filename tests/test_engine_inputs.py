"""The inputs engines' water shaders read (``shaders_port.spirv.engine_inputs``): bound by the
engines' names, their values by their documented conventions, and the executor and llvmpipe
agreeing on small shaders written for these tests in the engines' styles (``tests/shaders/``)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from helpers.gl import user_gl_render_or_skip
from helpers.synthetic import synthetic_baseline_inputs, synthetic_inputs
from shaders_port.inputs import perspective_view_proj
from shaders_port.spirv import engine_inputs as ei
from shaders_port.spirv.translated import STUDY_INPUTS
from shaders_port.spirv.user_shader import UserShader

SHADERS = Path(__file__).parent / "shaders"


def _gl_agrees(shader: UserShader, inputs) -> np.ndarray:
    """The executor's colour (H, W, 3) after checking it against llvmpipe on the covered pixels
    (mean and 99.9th percentile of the per-pixel largest difference)."""
    ours = shader.render(inputs).numpy()
    rgba, mask = user_gl_render_or_skip(shader, inputs)
    both = mask & (ours["mask"] > 0)
    mine = ours["color"]
    d = np.abs(rgba[..., :3] - mine).max(-1)[both]
    assert both.sum() > 500, both.sum()
    assert d.mean() <= 1e-4 and np.percentile(d, 99.9) <= 2e-3, (d.mean(), d.max())
    return mine


def test_every_engine_name_is_an_input_and_every_input_documented():
    for name, (inp, engines) in ei.ENGINE_ALIASES.items():
        assert inp in STUDY_INPUTS and engines, name
    for name in ei.ENGINE_INPUTS:
        assert name in STUDY_INPUTS and STUDY_INPUTS[name].split(":")[0] in (
            "mat4", "float", "vec2", "vec3", "sampler2D", "samplerCube")  # fmt: skip
    assert set(ei.SAME_AS.values()) <= set(STUDY_INPUTS)


def test_values_follow_their_conventions():
    inputs = synthetic_baseline_inputs(32, 24)
    u = ei.uniform_values(inputs)
    # near and far: those perspective_view_proj was built with (near 0.05, far 100)
    vp = perspective_view_proj((0.3, 2.0, 3.0), (0.0, 0.0, 0.0), aspect=4 / 3)
    n, f = ei._near_far(dataclasses.replace(inputs, view_proj=vp, viewpos=np.float32([0.3, 2, 3])))
    assert abs(n - 0.05) < 1e-5 and abs(f - 100.0) < 0.05, (n, f)
    # the projective matrix maps a world point to the bias of the mirrored camera's NDC
    p = np.array([0.2, 0.0, -0.4, 1.0])
    c = inputs.reflection_view_proj.astype(np.float64) @ p
    q = u["reflection_texture_matrix"] @ p
    assert np.allclose(q[:2] / q[3], 0.5 * c[:2] / c[3] + 0.5)
    assert abs(np.linalg.norm(u["sun_direction"]) - 1.0) < 1e-12 and u["sun_direction"][1] > 0
    # Z-up: a right-handed rotation taking +y to +z; a matrix keeps its image of a point
    assert np.allclose(ei.UP_Z @ [0, 1, 0], [0, 0, 1]) and abs(np.linalg.det(ei.UP_Z) - 1) < 1e-12
    M = ei.to_up("z", inputs.view_proj, "matrix")
    assert np.allclose(M[:, :3] @ (ei.UP_Z @ p[:3]) + M[:, 3], inputs.view_proj @ p, atol=1e-5)
    with pytest.raises(ValueError, match="write `// @study up y`"):
        ei.to_up("x", p[:3], "vector")


def test_dudv_map_is_the_slope_of_the_waves():
    h = lambda x, z: 0.1 * np.sin(x) * np.cos(2 * z)  # noqa: E731
    x, z = np.meshgrid(np.linspace(0, 6, 40), np.linspace(0, 6, 30))
    gx, gz = 0.1 * np.cos(x) * np.cos(2 * z), -0.2 * np.sin(x) * np.sin(2 * z)
    n = np.stack([-gx, np.ones_like(gx), -gz], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    d = ei.dudv_map((0.5 * n + 0.5).astype(np.float32))
    assert np.allclose(2 * d[..., 0] - 1, -gx, atol=1e-6) and np.allclose(2 * d[..., 1] - 1, -gz,
                                                                            atol=1e-6)  # fmt: skip
    assert np.all(d[..., 2] == 0) and h(0, 0) == 0
    flat = ei.dudv_map(np.full((2, 2, 3), [0.5, 1.0, 0.5], np.float32))
    assert np.allclose(flat[..., :2], 0.5)


def test_screen_space_inputs_match_llvmpipe():
    """three.js's textureMatrix + mirrorSampler, Babylon.js's refractionSampler, jME's depth
    map with three.js's cameraNear / cameraFar: bound by name, executor = llvmpipe."""
    shader = UserShader.from_file(SHADERS / "engine_screen.frag")
    assert shader.run_bindings()["mirrorSampler"] == "reflection_sampler"
    assert shader.run_bindings()["refractionSampler"] == "sceneColor"
    assert shader.run_bindings()["m_FrustumNearFar"] == "camera_near_far"
    inputs = synthetic_baseline_inputs(48, 36)
    _gl_agrees(shader, inputs)


def _normal_png(path: Path) -> None:
    rng = np.random.default_rng(3)
    a = (rng.random((16, 16, 3)) * 255).astype(np.uint8)
    Image.fromarray(a).save(path)


def test_uniform_inputs_and_user_normal_map_match_llvmpipe(tmp_path):
    """time, sunDirection, sunColor, eye, the inverse view-projection, the DuDv map and the
    user's own (mipmapped) normal-map image bound by the engines' names."""
    _normal_png(tmp_path / "waves.png")
    src = (SHADERS / "engine_uniforms.frag").read_text()
    f = tmp_path / "engine_uniforms.frag"
    f.write_text(
        src.replace(
            "// @study constant GAIN", "// @study normal_map waves.png\n// @study constant GAIN", 1
        )
    )
    shader = UserShader.from_file(f)
    assert shader.engine["normal_map"] == str((tmp_path / "waves.png").resolve())
    inputs = dataclasses.replace(synthetic_inputs(48, 36), time=1.25)
    a = _gl_agrees(shader, inputs)
    b = shader.render(dataclasses.replace(inputs, time=0.0)).numpy()["color"]
    assert np.abs(a - b).max() > 1e-3  # the clock moves the DuDv lookup


def test_an_engine_normal_map_without_an_image_reads_the_waves_in_tangent_space():
    """An engine's normal-map sampler (three.js's normalSampler) with no image declared reads
    the study's waves as engines store a normal map: tangent space (x along u = world +x, y
    along v = world +z, z up), mipmapped; executor = llvmpipe."""
    shader = UserShader.from_file(SHADERS / "engine_uniforms.frag")
    assert shader.run_bindings()["normalSampler"] == "waves_normal_map"
    n = np.array([0.3, 0.9, -0.2])
    n /= np.linalg.norm(n)
    enc = ei.waves_normal_map((0.5 * n + 0.5).astype(np.float32)[None, None])[0, 0]
    assert np.allclose(2 * enc - 1, [n[0], n[2], n[1]], atol=1e-6)
    flat = ei.waves_normal_map(np.full((1, 1, 3), [0.5, 1.0, 0.5], np.float32))
    assert np.allclose(flat, [0.5, 0.5, 1.0])
    inputs = dataclasses.replace(synthetic_inputs(48, 36), time=0.5)
    a = _gl_agrees(shader, inputs)
    assert np.std(a[..., 2], axis=None) > 1e-3  # the waves vary over the water


def test_missing_normal_map_image_is_named(tmp_path):
    f = tmp_path / "w.frag"
    f.write_text(
        (SHADERS / "engine_uniforms.frag")
        .read_text()
        .replace(
            "// @study constant GAIN", "// @study normal_map nope.png\n// @study constant GAIN", 1
        )
    )
    with pytest.raises(ValueError, match="normal_map: no image file .*nope.png"):
        UserShader.from_file(f)


def test_up_z_matches_llvmpipe_and_is_z_up():
    shader = UserShader.from_file(SHADERS / "engine_up_z.frag")
    assert shader.engine["up"] == "z"
    inputs = synthetic_inputs(48, 36)
    rgb = _gl_agrees(shader, inputs)
    src = (SHADERS / "engine_up_z.frag").read_text().replace("// @study up z", "")
    src = src.replace("ground * above + vec3(abs(p.z) + eyeCheck)", "ground")
    ground = UserShader(src, "y_up.frag").render(inputs).numpy()
    covered = ground["mask"] > 0
    # in Z-up the plane is z = 0, the sun and camera above it, varyingVecEye = camera - p,
    # and the texture matrix takes Z-up points to the same ground as the Y-up frame's
    assert ground["color"][covered].max() > 0.05
    assert np.abs(rgb - ground["color"])[covered].max() < 1e-5


def test_sky_cube_is_the_sky_unflipped_and_matches_llvmpipe():
    """``sky_cube`` at ``d`` is ``reflectionTexture`` at ``d * (1, -1, 1)`` (the study's
    shaders' lookup), texel for texel; executor = llvmpipe."""
    shader = UserShader.from_file(SHADERS / "engine_sky.frag")
    inputs = synthetic_inputs(48, 36)
    inputs = dataclasses.replace(
        inputs, cubemap=np.random.default_rng(5).random(inputs.cubemap.shape).astype(np.float32)
    )
    rgb = _gl_agrees(shader, inputs)
    src = (SHADERS / "engine_sky.frag").read_text().replace("samplerCube sky_cube", "samplerCube "
                                                             "reflectionTexture")  # fmt: skip
    src = src.replace("texture(sky_cube, r)", "texture(reflectionTexture, r * vec3(1, -1, 1))")
    study = UserShader(src, "flipped.frag").render(inputs).numpy()
    covered = study["mask"] > 0
    assert np.abs(rgb - study["color"])[covered].max() < 1e-6


def test_docs_page_lists_every_input_with_its_bind_line():
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scripts"))
    from docs_engine_inputs import engine_inputs_page

    page = engine_inputs_page()
    for name, desc in STUDY_INPUTS.items():
        assert f"| `{name}` |" in page, name
        if desc.split(":")[0] in ("sampler2D", "samplerCube", "mat4", "mat3", "vec2", "vec3",
                                  "float"):  # fmt: skip
            assert f"`// @study bind myName {name}`" in page, name
    for alias in ei.ENGINE_ALIASES:
        assert f"`{alias}`" in page, alias


def test_a_frame_without_the_mirrored_camera_names_what_is_missing():
    shader = UserShader.from_file(SHADERS / "engine_screen.frag")
    with pytest.raises(ValueError, match="textureMatrix reads the study input reflection_texture"):
        shader.render(synthetic_inputs(32, 24))


def test_animated_frames_carry_their_clock(monkeypatch):
    """``load_frames`` gives frame ``k`` the ``time`` ``k * animation.time_step`` (the renders
    and the inputs' builds stubbed: only the clock is under test)."""
    from study.config.experiment import load_experiment
    from study.scene import animation_data

    exp = load_experiment(Path(__file__).parent.parent / "experiments" / "animated.toml")
    still = synthetic_inputs(8, 6)
    monkeypatch.setattr(animation_data, "load_or_render", lambda *a, **k: None)
    monkeypatch.setattr(animation_data, "load_or_build_shader_inputs", lambda *a, **k: still)
    monkeypatch.setattr(animation_data, "inputs_for_shader", lambda e, i, *a, **k: i)
    got = animation_data.load_frames(exp, "llvm_ad_rgb")
    dt = float(exp.animation.time_step)
    assert [i.time for i in got["inputs"]] == [k * dt for k in range(int(exp.animation.frames))]
    assert got["inputs"][3].time > 0 and still.time == 0.0


def test_binding_sheets_describe_engine_names():
    from study.export.bindings import _meaning

    assert _meaning("textureMatrix") == ei.ENGINE_INPUTS["reflection_texture_matrix"][1]
    assert "DuDv" in _meaning("dudv_map") and _meaning("viewpos") == "camera position, world units"


def test_export_ships_the_textures_the_executor_binds(tmp_path):
    """A user's shader reading a DuDv map, its own normal-map image and the sky cube, and one
    reading the engine's render targets: the export writes the first three under
    ``shaders/textures/`` with exactly the texels the executor binds (a cube map as its six
    faces), records their sampler state, and lists them in BINDINGS.md by the shader's names;
    the render targets are named there as the engine's own, no file written."""
    from helpers.experiments import small_experiment
    from shaders_port.pipeline.texture import backend_types
    from study import read_exr
    from study.export.shaders import export_user_shader
    from study.export.textures import expects_lines, texture_record, write_textures

    exp, inputs = small_experiment(), synthetic_baseline_inputs(32, 24)
    shader = UserShader.from_file(SHADERS / "engine_textures.frag")
    record = texture_record(exp, inputs, shader)
    out = tmp_path / "shaders"
    export_user_shader(shader, shader.defaults(), out, ("gles300",),
                       (record, lambda f: write_textures(record, inputs, f,
                                                         shader.engine["normal_map"])))  # fmt: skip
    bound = ei.engine_values(backend_types("llvm"), inputs, shader.engine)
    ship = record["shipped"]
    for inp in ("dudv_map", "user_normal_map"):
        tex = bound[inp]
        want = np.asarray(tex.data.numpy()).reshape(tex.height, tex.width, tex.channels)
        got, meta, _ = read_exr(out / "textures" / ship[inp]["file"])
        assert np.array_equal(got, want) and meta["texture"]["input"] == inp
    cube = bound["sky_cube"]
    faces = np.stack([read_exr(out / "textures" / f)[0] for f in ship["sky_cube"]["files"]])
    assert [f[-6:-4] for f in ship["sky_cube"]["files"]] == ["px", "nx", "py", "ny", "pz", "nz"]
    assert np.array_equal(faces.ravel(), np.asarray(cube.data.numpy()))
    assert (ship["user_normal_map"]["mipmaps"], ship["dudv_map"]["mipmaps"]) == (True, False)
    assert ship["sky_cube"]["wrap"] == "clamp" and ship["dudv_map"]["wrap"] == "repeat"
    assert ship["dudv_map"]["bound_as"] == ["m_water_dudvmap"] and "rendered" in record
    sheet = (out / "gles300" / "BINDINGS.md").read_text()
    assert "`m_water_dudvmap` = `dudv_map.exr`" in sheet
    assert "`normalSampler` = `user_normal_map.exr`" in sheet and "water_normals.png" in sheet
    assert "`sky_cube` = `sky_cube_px.exr` ... `sky_cube_nz.exr`" in sheet
    screen = UserShader.from_file(SHADERS / "engine_screen.frag")
    rendered = texture_record(exp, inputs, screen)["rendered"]
    assert {i: r["bound_as"] for i, r in rendered.items()} == {
        "reflection_sampler": ["mirrorSampler"], "sceneColor": ["refractionSampler"],
        "sceneDepth": ["m_water_depthmap"]}  # fmt: skip
    lines = expects_lines(texture_record(exp, inputs, screen))
    assert "* `mirrorSampler` (`reflection_sampler`)" in "\n".join(lines)
    assert any("textures the engine renders itself" in line for line in lines)
    # an engine's normal-map sampler with no image named ships the waves as it read them
    waves = UserShader.from_file(SHADERS / "engine_uniforms.frag")
    rec = texture_record(exp, inputs, waves)
    write_textures(rec, inputs, out, None)
    tex = bound["waves_normal_map"]
    want = np.asarray(tex.data.numpy()).reshape(tex.height, tex.width, tex.channels)
    got, _, _ = read_exr(out / "textures" / rec["shipped"]["waves_normal_map"]["file"])
    assert rec["shipped"]["waves_normal_map"]["bound_as"] == ["normalSampler"]
    assert np.array_equal(got, want) and rec["shipped"]["waves_normal_map"]["mipmaps"]


@pytest.mark.parametrize("eye", [(0.0, 3.2, 6.5), (1.5, 0.8, -4.0), (-3.0, 6.0, 1.0)])
def test_three_reflector_camera_is_the_studys_mirrored_camera_turned(eye):
    """docs/engine-inputs.md: three.js's ``Reflector`` mirrors the camera's position, target and
    up vector in the plane; its view-projection is ``diag(-1, -1, 1, 1)`` times the study's
    ``o2v_projection_reflection`` (the same image turned by 180 degrees), so its texture
    matrix is the study's with s -> q - s, t -> q - t."""
    from shaders_port.inputs import mirrored_view_proj

    def look_at(e, t, up):  # three's Object3D.lookAt for a camera, as a view matrix
        f = (t - e) / np.linalg.norm(t - e)
        s = np.cross(f, up) / np.linalg.norm(np.cross(f, up))
        v = np.eye(4)
        v[0, :3], v[1, :3], v[2, :3] = s, np.cross(s, f), -f
        v[:3, 3] = -v[:3, :3] @ e
        return v

    e, t, m = np.array(eye), np.array([0.2, -1.0, 0.3]), np.diag([1.0, -1.0, 1.0])
    vp = perspective_view_proj(e, t, fov_y_deg=45.0, aspect=1.3, near=0.05, far=100.0)
    proj = np.asarray(vp, np.float64) @ np.linalg.inv(look_at(e, t, np.array([0.0, 1.0, 0.0])))
    reflector = proj @ look_at(m @ e, m @ t, m @ np.array([0.0, 1.0, 0.0]))
    study = np.asarray(mirrored_view_proj(vp), np.float64)
    assert np.allclose(reflector, np.diag([-1.0, -1.0, 1.0, 1.0]) @ study, atol=1e-5)
    bias = np.array([[0.5, 0, 0, 0.5], [0, 0.5, 0, 0.5], [0, 0, 0.5, 0.5], [0, 0, 0, 1]])
    convert = np.array([[-1.0, 0, 0, 1], [0, -1, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1]])
    assert np.allclose(bias @ reflector, convert @ bias @ study, atol=1e-5)
