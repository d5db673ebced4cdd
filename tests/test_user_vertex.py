"""A user's own vertex shader (``fit.vertex``): run per vertex of a tessellated water grid
through SPIR-V, its triangles rasterised and its outputs interpolated as GL does, with
vertex/fragment pairs written for these tests (``tests/shaders/``) in the names of three.js,
Babylon.js, jMonkeyEngine and Urho3D; each pair compared with llvmpipe drawing the same grid,
differentiated (central differences) and calibrated through ``study calibrate``."""

from __future__ import annotations

import json
import shutil
from collections import OrderedDict
from pathlib import Path

import drjit as dr
import numpy as np
import pytest

from helpers import REPO
from helpers.experiments import TINY, sets
from helpers.gl import user_gl_render_or_skip
from helpers.port_checks import assert_user_jacobian
from helpers.synthetic import synthetic_baseline_inputs, synthetic_inputs
from shaders_port.pipeline.interpolate import interpolate, rasterize_triangles, water_grid
from shaders_port.pipeline.raster import rasterize_water
from shaders_port.spirv import translated as spirv_port
from shaders_port.spirv import user_vertex
from shaders_port.spirv.dialects import ShaderError
from shaders_port.spirv.user_shader import UserShader
from shaders_port.spirv.user_vertex import UserVertex
from shaders_port.spirv.vertex import VertexShader
from study.export.gl_check import GL_MEAN, GL_P999, hlsl_check_user
from study.export.shaders import export_user_shader
from study.export.targets import resolve_targets, target_file

SHADERS = Path(__file__).parent / "shaders"
MY_WATER = REPO / "experiments" / "my_water.toml"
PAIRS = ("projective_water", "flat_noperspective", "displaced_water")


@pytest.fixture(scope="module")
def inputs():
    return synthetic_inputs(width=64, height=48)


def _pair(name: str, cells=(24, 24), frag: str | None = None) -> UserShader:
    vertex = UserVertex.from_file(SHADERS / f"{name}.vert", cells)
    return UserShader.from_file(SHADERS / (frag or f"{name}.frag"), vertex=vertex)


def _gl_compare(shader: UserShader, inputs):
    ours = shader.render(inputs).numpy()
    rgba, mask = user_gl_render_or_skip(shader, inputs)
    mine = ours["mask"] > 0.5
    both = mask & mine
    d = np.abs(rgba[..., :3] - ours["color"]).max(-1)[both]
    return ours, mask, float(d.mean()), float(np.percentile(d, 99.9)), int((mask ^ mine).sum())


@pytest.mark.parametrize("name", PAIRS)
def test_pair_matches_llvmpipe(name, inputs):
    shader = _pair(name)
    ours, mask, mean, p999, differ = _gl_compare(shader, inputs)
    assert mask.sum() > 800 and differ <= 0.001 * mask.sum(), (int(mask.sum()), differ)
    assert mean <= GL_MEAN and p999 <= GL_P999, (mean, p999)
    # measured on llvmpipe: means 1.5e-7 .. 7.5e-7; far below the GL check's thresholds
    assert mean <= 1e-5, mean
    plane = rasterize_water(inputs).mask
    if name == "displaced_water":  # the coverage is the displaced surface's, not the plane's
        assert (plane ^ mask).sum() > 10
    else:
        assert (plane ^ mask).sum() <= 0.002 * mask.sum()


def test_interpolation_is_perspective_correct_flat_and_noperspective(inputs):
    """On the plane, a perspective-correct world position is the ray-plane intersection the
    study's raster computes; a noperspective window position is the pixel centre; a flat
    value is the provoking (last) vertex's."""
    grid = water_grid(inputs.water_rect, inputs.normal_tile, (16, 16))
    vp = inputs.view_proj.astype(np.float64)
    clip = np.c_[grid.position, np.ones(len(grid.position))] @ vp.T
    W, H = inputs.width, inputs.height
    cov = rasterize_triangles(clip, grid.triangles, W, H)
    ref = rasterize_water(inputs)
    assert np.array_equal(cov.mask, ref.mask)
    world = interpolate(grid.position, cov, grid.triangles, "smooth")
    assert np.abs(world - ref.world).max() < 1e-5
    ndc = clip[:, :2] / clip[:, 3:]
    win = (ndc + 1.0) * 0.5 * np.array([W, H])
    got = interpolate(win, cov, grid.triangles, "noperspective")
    col, row = cov.index % W + 0.5, H - cov.index // W - 0.5
    assert np.abs(got - np.c_[col, row]).max() < 1e-6
    ids = np.arange(len(grid.position), dtype=np.float64)
    flat = interpolate(ids, cov, grid.triangles, "flat")
    assert np.array_equal(flat, grid.triangles[cov.triangle, 2])


def test_the_studys_water_vert_through_the_grid_gives_the_studys_image(inputs):
    """The study's own water.vert as the user's vertex shader: the worked example's fragment
    shader gives the image of the study's quad (its varyings computed per pixel)."""
    frag = REPO / "experiments" / "shaders" / "my_water.frag"
    decl = {"constants": {"F0": [0.0, 0.2]}}
    alone = UserShader.from_file(frag, decl).render(inputs).numpy()
    vert = VertexShader.from_file(REPO / "shaders_port" / "glsl" / "core" / "water.vert")
    paired = UserShader.from_file(frag, decl, vertex=UserVertex(vert, (8, 8))).render(inputs)
    paired = paired.numpy()
    both = (alone["mask"] > 0) & (paired["mask"] > 0)
    assert both.sum() >= 0.998 * (alone["mask"] > 0).sum()
    d = np.abs(alone["color"] - paired["color"]).max(-1)[both]
    assert d.mean() < 1e-5 and np.percentile(d, 99.9) < 1e-3, (d.mean(), d.max())


def test_derivatives_after_the_vertex_shader_match_llvmpipe(inputs):
    # dFdx/dFdy of a displaced surface's world position (a faceted normal), fwidth of a
    # varying and of gl_FragCoord.z: the helper pixels of each triangle's quads extrapolate its
    # interpolants, as llvmpipe's do
    shader = _pair("displaced_water", frag="faceted_water.frag")
    ours, mask, mean, p999, differ = _gl_compare(shader, inputs)
    assert mask.sum() > 800 and differ == 0, (int(mask.sum()), differ)
    # measured on llvmpipe: mean 1.2e-6, 99.9th percentile 1.1e-5 (the differences of
    # float32 interpolants); one quad invocation per quad instead of one per triangle gives
    # a mean of 1.2e-2 and a 99.9th percentile of 0.22
    assert mean <= 1e-5 and p999 <= 1e-4, (mean, p999)
    assert mean <= GL_MEAN and p999 <= GL_P999, (mean, p999)


def test_mip_lookups_and_derivatives_after_a_flat_grid_equal_the_study_quads(inputs, monkeypatch):
    # urho_water.vert writes vTexCoord0 as the study's water.vert does: on the flat grid the
    # helper pixels' extrapolated interpolants give the study quad's derivatives and implicit
    # levels of detail (the study quad's are compared with llvmpipe in test_spirv_instructions)
    study = spirv_port.study_bindings

    def mipmapped(m, P, frame, *engine):
        b = study(m, P, frame, *engine)
        b["normalMap"] = b["normalMap"].with_mipmaps(m)
        return b

    frag = SHADERS / "mip_water.frag"
    out = {}
    for mips in (False, True):
        monkeypatch.setattr(spirv_port, "study_bindings", mipmapped if mips else study)
        monkeypatch.setattr(spirv_port, "_BINDINGS", {})
        monkeypatch.setattr(user_vertex, "_FRAMES", OrderedDict())
        alone = UserShader.from_file(frag).render(inputs).numpy()
        pair = _pair("urho_water", frag="mip_water.frag").render(inputs).numpy()
        both = (alone["mask"] > 0.5) & (pair["mask"] > 0.5)
        assert both.sum() >= 0.998 * (alone["mask"] > 0.5).sum()
        d = np.abs(alone["color"] - pair["color"]).max(-1)[both]
        # measured: mean 1.9e-6, largest 1.9e-5 (float32 interpolants), with mipmaps or not
        assert d.mean() <= 1e-5 and d.max() <= 1e-4, (mips, d.mean(), d.max())
        out[mips] = pair["color"][both]
    # the mip levels change every pixel (0.039 on average): the level of detail is used
    assert (np.abs(out[True] - out[False]).max(-1) > 1e-3).mean() > 0.9


@pytest.mark.parametrize("name", PAIRS + ("displaced_water:faceted_water.frag",))
def test_jacobian_matches_central_differences(name, inputs):
    name, _, frag = name.partition(":")
    assert_user_jacobian(_pair(name, cells=(12, 12), frag=frag or None), inputs, 0.95)


MY_FRAG = "../../experiments/shaders/my_water.frag"


@pytest.mark.parametrize(
    "name",
    ("flat_noperspective", "displaced_water:faceted_water.frag", f"urho_water:{MY_FRAG}"),
)
def test_the_hlsl_round_trip_of_a_pair_runs_like_the_executor(name, inputs, tmp_path):
    # the exported fragment HLSL back through glslang and SPIRV-Cross, drawn on llvmpipe over
    # the grid after the user's GLSL vertex shader; every engine target is written for a pair.
    # my_water.frag's uniform block member (uTextureMatrix0) keeps its value when the vertex
    # shader's uniforms are written after it
    name, _, frag = name.partition(":")
    shader = _pair(name, frag=frag or None)
    values = shader.defaults()
    ours = shader.render(inputs, values).numpy()
    export_user_shader(shader, values, tmp_path / "shaders", targets=None)
    for target in resolve_targets(None):
        assert (tmp_path / "shaders" / target_file(target, name, "vert")).is_file(), target
    check = hlsl_check_user(shader, inputs, values, ours, tmp_path / "shaders")
    if not check["ran"]:
        pytest.skip(check["why"])
    # measured on llvmpipe: means 1.7e-7 (flat, noperspective), 1.2e-6 (derivatives), 6.6e-7
    # (my_water.frag; 0.17 with the block's bytes rebuilt from the vertex uniforms alone)
    assert check["passed"] and check["pixels"] > 800, check
    assert check["mean_abs"] <= 1e-5, check


def test_a_vertex_shader_with_glsl_compatibility_names(inputs, tmp_path):
    # GLSL 1.20 with ftransform(), gl_Vertex, gl_MultiTexCoord0, gl_Normal, gl_ModelViewMatrix,
    # gl_NormalMatrix and gl_TexCoord[0], after a GLSL 1.20 fragment shader reading them
    shader = _pair("legacy_water")
    assert "ftransform" in shader.vertex.shader.original
    assert shader.vertex.shader.source.startswith("#version 330 core")
    ours, mask, mean, p999, differ = _gl_compare(shader, inputs)
    assert mask.sum() > 800 and differ <= 0.001 * mask.sum(), (int(mask.sum()), differ)
    # measured on llvmpipe: mean 5.2e-8
    assert mean <= 1e-5 and p999 <= GL_P999, (mean, p999)
    # ftransform() is the study's world -> clip matrix on the grid's positions
    assert (rasterize_water(inputs).mask ^ mask).sum() <= 0.002 * mask.sum()
    assert np.std(ours["color"][mask], 0).min() > 0.01  # the varyings vary over the water
    # a compatibility name the grid gives no value of: refused at its line
    (tmp_path / "c.vert").write_text(
        "#version 120\nvarying vec4 c;\nvoid main() {\n  gl_Position = ftransform();\n"
        "  c = gl_Color;\n}\n"
    )
    with pytest.raises(ValueError, match=r"c.vert:5: gl_Color: a compatibility built-in"):
        UserVertex.from_file(tmp_path / "c.vert")


def test_errors_name_the_problem(inputs, tmp_path):
    frag = SHADERS / "projective_water.frag"
    head = "#version 330 core\nin vec3 position;\n"

    def vert(body: str, name="v.vert"):
        (tmp_path / name).write_text(head + body)
        return UserVertex.from_file(tmp_path / name, (4, 4))

    # a fragment input the vertex shader does not write (GL would not link the pair)
    v = vert(
        "uniform mat4 viewProjection;\nout vec4 vProj;\n"
        "void main() { vProj = vec4(position, 1.0); gl_Position = viewProjection * vProj; }"
    )
    with pytest.raises(
        ValueError, match="reads `in vUv0`, which the vertex shader v.vert does not write"
    ):
        UserShader.from_file(frag, vertex=v).render(inputs)
    # a uniform nothing binds: the engine names are listed
    v = vert(
        "uniform mat4 myCamera;\nvoid main() { gl_Position = myCamera * vec4(position, 1.0); }"
    )
    with pytest.raises(ValueError, match="myCamera.*g_WorldViewProjectionMatrix"):
        v.shader.run(dr.llvm.ad, inputs, v.grid(inputs), {})
    # a recognised name declared with the wrong type
    v = vert(
        "uniform vec2 cameraPosition;\nout vec2 c;\n"
        "void main() { c = cameraPosition; gl_Position = vec4(position, 1.0); }"
    )
    with pytest.raises(ValueError, match="cameraPosition is the cameraPosition.*vec2"):
        v.shader.run(dr.llvm.ad, inputs, v.grid(inputs), {})
    # a pragma a vertex shader does not take, a binding to nothing known, a shader that does not
    # compile
    with pytest.raises(ValueError, match="bind NAME MEANING"):
        vert("// @study up z\nvoid main() { gl_Position = vec4(position, 1.0); }")
    with pytest.raises(ValueError, match="names no meaning"):
        vert(
            "// @study bind position somewhere\nvoid main() { gl_Position = vec4(position, 1.0); }"
        )
    with pytest.raises(ValueError, match="glslangValidator failed on the vertex shader"):
        vert("void main() { gl_Position = undeclared; }")
    with pytest.raises(ValueError, match="fit.vertex_grid"):
        UserVertex(v.shader, (0, 4))
    # a binding of the shader's own name makes it bind
    v = vert(
        "// @study bind camera viewProjection\nuniform mat4 camera;\n"
        "void main() { gl_Position = camera * vec4(position, 1.0); }"
    )
    clip, _ = v.shader.run(dr.llvm.ad, inputs, v.grid(inputs), {})
    want = np.c_[v.grid(inputs).position, np.ones(25)] @ inputs.view_proj.T.astype(np.float64)
    assert np.abs(clip - want).max() < 1e-4


def test_experiment_keys(tmp_path):
    from study import load_experiment
    from study.config.errors import ExperimentError

    frag = tmp_path / "w.frag"
    shutil.copy(REPO / "experiments" / "shaders" / "my_water.frag", frag)
    with pytest.raises(ExperimentError, match='"auto": no vertex shader w.vert'):
        load_experiment(MY_WATER, [f'fit.shader="{frag}"', 'fit.vertex="auto"'])
    shutil.copy(SHADERS / "urho_water.vert", tmp_path / "w.vert")
    exp = load_experiment(MY_WATER, [f'fit.shader="{frag}"', 'fit.vertex="auto"',
                                     "fit.vertex_grid=[8, 6]"])  # fmt: skip
    assert exp["fit.vertex"] == str(tmp_path / "w.vert") and exp["fit.vertex_grid"] == [8, 6]
    with pytest.raises(ExperimentError, match="fit.vertex is the vertex shader of your own"):
        load_experiment(MY_WATER, ['fit.shader="water_refraction"', 'fit.vertex="w.vert"'])
    with pytest.raises(ExperimentError) as err:
        load_experiment(MY_WATER, [f'fit.vertex="{tmp_path / "none.vert"}"'])
    assert str(err.value) == f"fit.vertex: no file {str(tmp_path / 'none.vert')!r}"


@pytest.mark.slow
def test_study_calibrate_with_the_users_vertex_shader(tmp_path, monkeypatch):
    """``study calibrate`` of the worked example's fragment shader after a vertex shader in
    Urho3D's names (``fit.vertex``) on the tiny pool: it fits, its statuses are the
    calibration's, the written pair runs on llvmpipe like the executor, and so does the HLSL
    round trip of the fragment shader after the vertex shader."""
    from study.cli import main

    monkeypatch.setenv("STUDY_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "c"
    args = sets(TINY) + sets([f'fit.vertex="{SHADERS / "urho_water.vert"}"',
                             "fit.vertex_grid=[16, 16]"])  # fmt: skip
    assert main(["calibrate", str(MY_WATER), "--out", str(out)] + args) == 0
    res = json.loads((out / "constants.json").read_text())
    assert res["error"]["rmse"]["fitted"] < res["error"]["rmse"]["default"], res["error"]
    assert {p["status"] for p in res["parameters"].values()} <= {"fitted", "bound", "frozen"}
    assert any(p["status"] == "fitted" for p in res["parameters"].values())
    if res["gl_check"]["ran"]:
        assert res["gl_check"]["passed"], res["gl_check"]
    assert (out / "shaders" / "core" / "urho_water.vert").is_file()
    hlsl = res["engine_targets"]["hlsl"]["llvmpipe"]
    if hlsl["ran"]:
        assert hlsl["passed"] and hlsl["pixels"] > 100, hlsl


def test_explicit_locations_after_a_line_comment():
    """A ``//`` comment ends at its line: the locations placed after it are read (a pattern
    with ``.`` matching newlines dropped the rest of the file)."""
    from shaders_port.spirv.vertex import explicit_locations

    src = "// a comment\nlayout(location = 3) out vec4 vA;\n/* b\n c */\n"
    src += "layout(location = 5) flat out vec2 vB;\nlayout(location = 1) in vec4 aPos;\n"
    assert explicit_locations(src, "out") == {"vA": 3, "vB": 5}
    assert explicit_locations(src, "in") == {"aPos": 1}


def _one_file(cells=(24, 24)) -> UserShader:
    path = SHADERS / "one_file_water.glsl"
    vertex = UserVertex.from_file(path, cells, ("COMPILEVS", "VS=main"), (), shared=True)
    return UserShader.from_file(path, None, ("COMPILEPS", "PS=main"), (), vertex=vertex)


def test_one_file_for_both_stages_as_urho3d_compiles_it(inputs, tmp_path):
    # one file, a define per stage, uniforms (and two constants to fit) in an #include, the
    # engine's row-major matrices (`p * cViewProj`), `value` pragmas, an output array
    shader = _one_file()
    assert set(shader.constants) == {"cTint", "cShine"}
    assert shader.values == shader.vertex.shader.values == {"cTiling": (0.5,), "cBias": (0.25, 0.5)}
    ours, mask, mean, p999, differ = _gl_compare(shader, inputs)
    assert mask.sum() > 800 and differ <= 0.001 * mask.sum(), (int(mask.sum()), differ)
    assert mean <= 1e-5 and p999 <= GL_P999, (mean, p999)
    # the transposed matrices project the grid onto the study's water quad
    assert (rasterize_water(inputs).mask ^ mask).sum() <= 0.002 * mask.sum()
    # an included uniform is not written back (the engine's file); the export names the stages
    values = shader.defaults()
    assert shader.written(values) == shader.source
    export_user_shader(shader, values, tmp_path / "shaders", targets=None)
    assert (tmp_path / "shaders" / "core" / "one_file_water.frag").is_file()
    assert (tmp_path / "shaders" / "core" / "one_file_water.vert").is_file()
    check = hlsl_check_user(shader, inputs, values, ours, tmp_path / "shaders")
    if not check["ran"]:
        pytest.skip(check["why"])
    assert check["passed"] and check["mean_abs"] <= 1e-5, check


def test_chunks_imports_and_engine_inputs_in_a_vertex_shader():
    # `#include <chunk>`, jMonkeyEngine's `#import "..."`, and three.js's textureMatrix read
    # by the vertex shader, in the executor and on llvmpipe alike (a frame with the mirrored
    # camera's image)
    inputs = synthetic_baseline_inputs(64, 48)
    vertex = UserVertex.from_file(SHADERS / "chunked_water.vert", (24, 24))
    shader = UserShader.from_file(SHADERS / "chunked_water.frag", vertex=vertex)
    ours, mask, mean, p999, differ = _gl_compare(shader, inputs)
    assert mask.sum() > 800 and differ <= 0.001 * mask.sum(), (int(mask.sum()), differ)
    assert mean <= 1e-5 and p999 <= GL_P999, (mean, p999)
    assert np.std(ours["color"][mask], 0).max() > 0.01  # the mirrored image varies


def test_one_file_experiment_keys(tmp_path):
    from study import load_experiment
    from study.config.errors import ExperimentError
    from study.config.user_shader import load_user_shader

    path = SHADERS / "one_file_water.glsl"
    keys = [f'fit.shader="{path}"', f'fit.vertex="{path}"', 'fit.defines=["COMPILEPS", "PS=main"]',
            'fit.vertex_defines=["COMPILEVS", "VS=main"]', "fit.vertex_grid=[8, 6]",
            "fit.declare=[]"]  # fmt: skip
    exp = load_experiment(MY_WATER, keys)
    shader = load_user_shader(exp.values)
    assert shader.label == "one_file_water.glsl" and shader.vertex.shader.values["cTiling"] == (
        0.5,
    )
    with pytest.raises(ExperimentError, match="fit.vertex_defines is for your own fit.vertex"):
        load_experiment(MY_WATER, keys[:1] + keys[2:4] + keys[5:])
    with pytest.raises(ExperimentError, match="fit.vertex_defines: '1X' is not \"NAME\""):
        load_experiment(MY_WATER, keys[:3] + ['fit.vertex_defines=["1X"]'] + keys[5:])


def test_a_one_file_pairs_constants_json_keeps_its_stages_defines(tmp_path):
    """``study export`` of a one-file pair reads its vertex stage with that stage's defines
    (``vertex_defines``) and as the shared file it is, as the calibration compiled it."""
    from study.export.shaders import user_shader_of

    path = SHADERS / "one_file_water.glsl"
    data = {"shader": path.name, "shader_file": str(path), "defines": ["COMPILEPS", "PS=main"],
            "vertex_file": str(path), "vertex_grid": [8, 6],
            "vertex_defines": list(_one_file().vertex.shader.defines)}  # fmt: skip
    (tmp_path / "constants.json").write_text(json.dumps(data))
    shader = user_shader_of(tmp_path / "constants.json")
    assert shader.vertex.shader.defines == ("COMPILEVS", "VS=main")
    assert shader.vertex.shader.values == {"cTiling": (0.5,), "cBias": (0.25, 0.5)}
    del data["vertex_defines"]  # unset, as fit.vertex_defines: the fragment stage's
    (tmp_path / "constants.json").write_text(json.dumps(data))
    assert user_shader_of(tmp_path / "constants.json").vertex.shader.defines == (
        "COMPILEPS", "PS=main")  # fmt: skip


def test_a_shared_file_without_stage_guards_leaves_the_other_entry_point_out(inputs, tmp_path):
    """Urho3D's own Water.glsl defines VS() and PS() unguarded; its loader comments out the
    other stage's function. `!NAME` among a stage's defines does the same, every line keeping
    its number; the pair renders as the guarded file does."""
    text = (SHADERS / "one_file_water.glsl").read_text()
    bare = "\n".join(
        "" if ln.strip() in ("#ifdef COMPILEVS", "#ifdef COMPILEPS", "#endif") else ln
        for ln in text.split("\n")
    )
    path = tmp_path / "bare_water.glsl"
    path.write_text(bare)
    incs = [SHADERS]  # include/one_file_uniforms.glsl
    with pytest.raises(ShaderError, match="sWaves"):
        UserVertex.from_file(path, (24, 24), ("COMPILEVS", "VS=main"), incs, shared=True)
    vertex = UserVertex.from_file(path, (24, 24), ("COMPILEVS", "VS=main", "!PS"), incs, True)
    shader = UserShader.from_file(path, None, ("COMPILEPS", "PS=main", "!VS"), incs, vertex=vertex)
    a = shader.render(inputs).numpy()
    b = _one_file().render(inputs).numpy()
    assert np.array_equal(a["mask"], b["mask"]) and np.abs(a["color"] - b["color"]).max() == 0.0
    with pytest.raises(ShaderError, match="no function NOPE"):
        UserShader.from_file(path, None, ("COMPILEPS", "PS=main", "!NOPE"), incs, vertex=vertex)


def test_a_vertex_uniform_nothing_binds_is_refused_at_load_with_its_file_and_line(tmp_path):
    """A vertex shader's uniform with no value, meaning or input stops the experiment when it
    loads (before any reference), naming the included file and line that reads it."""
    from study import load_experiment
    from study.config.errors import ExperimentError

    (tmp_path / "include").mkdir()
    (tmp_path / "include" / "one_file_uniforms.glsl").write_text(
        (SHADERS / "include" / "one_file_uniforms.glsl").read_text()
    )
    inc = tmp_path / "include" / "tiling.glsl"
    inc.write_text("float tiling()\n{\n    return cTiling;\n}\n")
    src = (SHADERS / "one_file_water.glsl").read_text()
    src = src.replace("// @study value cTiling 0.5\n", "")
    src = src.replace('#include "include/one_file_uniforms.glsl"\n',
                      '#include "include/one_file_uniforms.glsl"\n'
                      '#ifdef COMPILEVS\n#include "include/tiling.glsl"\n#endif\n')  # fmt: skip
    src = src.replace("vUv = iTexCoord * cTiling;", "vUv = iTexCoord * tiling();")
    path = tmp_path / "w.glsl"
    path.write_text(src)
    keys = [f'fit.shader="{path}"', f'fit.vertex="{path}"', 'fit.defines=["COMPILEPS", "PS=main"]',
            'fit.vertex_defines=["COMPILEVS", "VS=main"]', "fit.vertex_grid=[8, 6]",
            "fit.declare=[]"]  # fmt: skip
    with pytest.raises(ExperimentError, match=r"reads 'cTiling' \(at .*tiling\.glsl:3\)"):
        load_experiment(MY_WATER, keys)
    load_experiment(MY_WATER, [*keys[:-1], 'fit.declare=["value cTiling 0.5"]'])


def test_a_target_the_pair_cannot_be_written_in_is_left_out_and_said(tmp_path):
    """A vertex shader writing gl_ClipDistance has no GLSL ES 3.00: the export leaves that
    target out with glslang's reason, the others are written, constants.json records why, the
    report says it and the viewer (which runs the GLSL ES export) names that reason."""
    from study.calibration.shader import _export_user
    from study.export.viewer import ViewerUnsupported, calibration_viewer
    from study.report.calibration import engine_targets_section

    vert = (SHADERS / "projective_water.vert").read_text()
    vert = vert.replace("    vScreen = gl_Position;", "    vScreen = gl_Position;\n"
                        "    gl_ClipDistance[0] = world.y + 10.0;")  # fmt: skip
    (tmp_path / "clipped.vert").write_text(vert)
    vertex = UserVertex.from_file(tmp_path / "clipped.vert", (8, 8))
    shader = UserShader.from_file(SHADERS / "projective_water.frag", vertex=vertex)
    left = _export_user(shader, shader.defaults(), tmp_path / "shaders", None, {})
    assert set(left) == {"gles300"} and "gl_ClipDistance" in left["gles300"]
    assert (tmp_path / "shaders" / "hlsl").is_dir() and not (
        tmp_path / "shaders" / "gles300"
    ).exists()
    lines = engine_targets_section({"gles300": {"left_out": left["gles300"]}}, "as written")
    assert any(ln.startswith("| gles300 | - | left out: ") for ln in lines)
    summary = {"shader": "projective_water.frag",
               "shader_file": str(SHADERS / "projective_water.frag"),
               "vertex_file": str(tmp_path / "clipped.vert"), "vertex_grid": [8, 8],
               "engine_targets": {"gles300": {"left_out": left["gles300"]}}}  # fmt: skip
    (tmp_path / "constants.json").write_text(json.dumps(summary))
    with pytest.raises(ViewerUnsupported, match="which projective_water.frag has none of"):
        calibration_viewer(tmp_path, None, None)
