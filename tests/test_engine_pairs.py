"""The engine-style water shaders shipped with their experiments (``experiments/shaders/``:
a three.js-style WebGL 1 water, a jMonkeyEngine-style GLSL 1.20 water, an Urho3D-style GLSL ES
3.00 water with an ``#include`` and a ``#define``, a Z-up GLSL 1.20 water), each with its own
vertex shader: loaded from its experiment as ``study calibrate`` loads it, executed, and
compared with llvmpipe drawing the same pair; the Z-up one against its Y-up twin; the vertex
shader's uniforms that are study or engine inputs bound by name or by a pragma."""

from __future__ import annotations

import json
import re

import drjit as dr
import numpy as np
import pytest

from helpers import REPO
from helpers.gl import assert_ran_as_written, user_gl_render_or_skip
from helpers.synthetic import synthetic_baseline_inputs
from shaders_port.spirv.engine_inputs import UP_Z
from shaders_port.spirv.user_shader import UserShader
from shaders_port.spirv.user_vertex import UserVertex
from shaders_port.spirv.vertex import VertexShader
from study import load_experiment
from study.config.user_shader import load_user_shader

EXPERIMENTS = REPO / "experiments"
PAIRS = ("webgl_mirror_water", "dudv_depth_water", "fog_cube_water", "zup_water")


@pytest.fixture(scope="module")
def inputs():
    return synthetic_baseline_inputs(64, 48)


def _shader(name: str, cells=(24, 24)) -> UserShader:
    exp = load_experiment(EXPERIMENTS / f"{name}.toml", [f"fit.vertex_grid={list(cells)}"])
    return load_user_shader(exp.values)


@pytest.mark.parametrize("name", PAIRS)
def test_engine_pair_matches_llvmpipe(name, inputs):
    """The pair's GLSL 330 translation on the core context, and the GL check of the pair as
    written (the GLSL 1.20 pairs on the compatibility profile, the GLSL ES ones on OpenGL ES)."""
    from study.export.gl_check import gl_check_user

    shader = _shader(name)
    assert shader.vertex is not None
    ours = shader.render(inputs).numpy()
    rgba, mask = user_gl_render_or_skip(shader, inputs, as_written=False)
    mine = ours["mask"] > 0.5
    assert mask.sum() > 800 and (mask ^ mine).sum() <= 0.001 * mask.sum()
    d = np.abs(rgba[..., :3] - ours["color"]).max(-1)[mask & mine]
    # measured on llvmpipe: means 1e-7 .. 2.4e-6, 99.9th percentiles up to 5e-5
    assert d.mean() <= 1e-5 and np.percentile(d, 99.9) <= 2e-4, (d.mean(), d.max())
    assert np.isfinite(ours["color"][mine]).all() and ours["color"][mine].std() > 0.01
    check = gl_check_user(shader, inputs, shader.defaults(), ours)
    assert check["ran"] and check["passed"], check
    assert_ran_as_written(check, "es" if shader.dialect.es else "compatibility")


def test_experiments_declare_what_the_pairs_need():
    fog = _shader("fog_cube_water")
    assert fog.defines == ("FOG_EXPONENTIAL",) and fog.include_paths
    assert fog.run_bindings()["sEnvCubeMap"] == "sky_cube"
    mirror = _shader("webgl_mirror_water")
    assert mirror.dialect.es and mirror.engine["normal_map"].endswith("water_normals.png")
    assert mirror.run_bindings()["mirrorSampler"] == "reflection_sampler"
    # the vertex shader's engine names and pragmas that are inputs, not attributes or matrices
    # (``time`` is the input's own name)
    assert mirror.vertex.shader.inputs == {
        "textureMatrix": "reflection_texture_matrix", "layerOffset0": "wave1",
        "layerOffset1": "wave2", "layerOffset2": "wave3", "layerOffset3": "wave4",
    }  # fmt: skip
    zup = _shader("zup_water")
    assert zup.engine["up"] == "z" and zup.vertex.shader.inputs["reflectmatrix"] == (
        "reflection_texture_matrix"
    )


def _y_up_twin(text: str) -> str:
    """zup_water.frag rewritten for a Y-up world: its Z-up normal ``(x, -z, y)`` of the study's
    frame and its horizontal components ``n.xy`` written in Y-up terms."""
    text = text.replace("// @study up z\n", "")
    text = text.replace(
        "vec3(bump.x * bumpscale, -bump.z * bumpscale, bump.y)",
        "vec3(bump.x * bumpscale, bump.y, bump.z * bumpscale)",
    )
    text = text.replace("vec2 dxy = n.xy * distortion;", "vec2 dxy = vec2(n.x, -n.z) * distortion;")
    assert text.count("bump.y, bump.z") == 1 and "-n.z" in text
    return text


def test_up_z_pair_equals_its_y_up_twin_and_llvmpipe(inputs, tmp_path):
    """The Z-up pair (positions on z = 0, matrices taking Z-up points, the camera above z = 0)
    draws the same image as the same pair written for the study's Y-up world."""
    zup = _shader("zup_water")
    twin_frag = tmp_path / "zup_water.frag"
    twin_frag.write_text(_y_up_twin((EXPERIMENTS / "shaders" / "zup_water.frag").read_text()))
    vertex = UserVertex.from_file(EXPERIMENTS / "shaders" / "zup_water.vert", (24, 24))
    twin = UserShader.from_file(twin_frag, vertex=vertex)
    assert twin.engine["up"] == "y"
    a, b = zup.render(inputs).numpy(), twin.render(inputs).numpy()
    covered = a["mask"] > 0.5
    assert covered.sum() > 800 and np.array_equal(covered, b["mask"] > 0.5)
    assert np.abs(a["color"] - b["color"])[covered].max() < 1e-5


def test_vertex_values_in_a_z_up_world(inputs, tmp_path):
    """Every attribute and matrix a vertex shader reads, in the Z-up frame: the position on
    z = 0, the normal +z, the camera above the plane, the same clip position as in Y-up."""
    src = (
        "#version 330 core\nin vec4 position;\nin vec3 normal;\nuniform mat4 viewProjection;\n"
        "uniform mat4 viewMatrix;\nuniform mat4 projectionMatrix;\nuniform vec3 cameraPosition;\n"
        "out vec3 vPos;\nout vec3 vNormal;\nout vec3 vCam;\nout vec4 vSplit;\n"
        "void main() { vPos = position.xyz; vNormal = normal; vCam = cameraPosition;\n"
        "  vSplit = projectionMatrix * viewMatrix * position;\n"
        "  gl_Position = viewProjection * position; }\n"
    )
    vs = VertexShader(src, "zup.vert")
    grid = UserVertex(vs, (4, 4)).grid(inputs)
    runs = {up: vs.run(dr.llvm.ad, inputs, grid, {}, up) for up in ("y", "z")}
    (clip_y, out_y), (clip_z, out_z) = runs["y"], runs["z"]
    assert np.abs(clip_y - clip_z).max() < 1e-4 and np.abs(out_z["vSplit"] - clip_z).max() < 1e-4
    assert np.abs(out_z["vPos"][:, 2]).max() == 0.0 and np.ptp(out_z["vPos"][:, 1]) > 1.0
    assert np.abs(out_z["vPos"] - out_y["vPos"] @ UP_Z.T).max() < 1e-6
    assert np.allclose(out_z["vNormal"], [0.0, 0.0, 1.0]) and out_z["vCam"][0, 2] > 0.0


def test_a_vertex_binding_to_nothing_known_is_named(tmp_path):
    src = (
        "#version 330 core\n// @study bind clock nowhere\nin vec3 position;\nuniform float clock;\n"
        "void main() { gl_Position = vec4(position, clock); }\n"
    )
    with pytest.raises(ValueError, match=re.escape("clock -> nowhere names no meaning, engine")):
        VertexShader(src, "v.vert")


def test_export_of_a_pair_reads_its_vertex_shader_back(tmp_path):
    """A pair's ``constants.json`` names its vertex shader (``vertex_file``, ``vertex_grid``):
    ``study export`` takes the pair back, and says so when the file is gone."""
    from study.export.shaders import user_shader_of

    shaders = EXPERIMENTS / "shaders"
    data = {
        "shader": "zup_water.frag", "shader_file": str(shaders / "zup_water.frag"),
        "vertex_file": str(shaders / "zup_water.vert"), "vertex_grid": [8, 6],
        "declaration": {"constants": {}, "bindings": {}}, "constants": {},
    }  # fmt: skip
    (tmp_path / "constants.json").write_text(json.dumps(data))
    shader = user_shader_of(tmp_path / "constants.json")
    assert shader.vertex.label == "zup_water.vert" and shader.vertex.cells == (8, 6)
    data["vertex_file"] = str(tmp_path / "gone.vert")
    (tmp_path / "constants.json").write_text(json.dumps(data))
    with pytest.raises(ValueError, match="the calibrated vertex shader .*gone.vert is gone"):
        user_shader_of(tmp_path / "constants.json")


def test_a_results_normal_map_is_relative_to_its_shader_and_reads_back(tmp_path):
    """The declared normal map a result records is relative to the shader's file, as the
    declaration writes it (no path of the machine that made the result), and ``study export``'s
    reading of the declaration finds the same file, from a copy of the pair elsewhere too."""
    import shutil

    from shaders_port.spirv.user_shader import UserShader
    from study.calibration.shader import _engine_record

    frag = REPO / "experiments" / "shaders" / "webgl_mirror_water.frag"
    shader = UserShader.from_file(frag)
    record = _engine_record(shader.engine, frag)
    assert record["normal_map"] == "../files/water_normals.png"
    declaration = {"constants": {}, "bindings": {}, **record}
    again = UserShader.from_file(frag, declaration)
    assert again.engine["normal_map"] == shader.engine["normal_map"]
    (tmp_path / "shaders").mkdir()
    (tmp_path / "files").mkdir()
    shutil.copy(frag, tmp_path / "shaders" / frag.name)
    shutil.copy(shader.engine["normal_map"], tmp_path / "files" / "water_normals.png")
    moved = UserShader.from_file(tmp_path / "shaders" / frag.name, declaration)
    assert moved.engine["normal_map"] == str((tmp_path / "files" / "water_normals.png").resolve())
