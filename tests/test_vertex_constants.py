"""Constants of a user's own vertex shader (``fit.vertex``) fitted in one parameter vector with
its fragment shader's: a pair written for these tests (``tests/shaders/swell_water.*``: a
swell's height that displaces the vertices, a normal-map tiling declared as a uniform without
initializer, a glint strength both stages declare), differentiated through the per-vertex
execution and the interpolation (central differences), recovered from synthetic targets, run
on llvmpipe at the fitted values, written back into the vertex file and exported."""

from __future__ import annotations

import json
import shutil
import re
from pathlib import Path

import numpy as np
import pytest

from helpers.experiments import TINY, sets
from helpers.gl import user_gl_render_or_skip
from helpers.port_checks import FD_NOISE, FD_RTOL, assert_user_jacobian
from helpers.synthetic import synthetic_inputs
from shaders_port.spirv.dialects import ShaderError
from shaders_port.spirv.user_shader import UserShader
from shaders_port.spirv.user_vertex import UserVertex
from study.export.gl_check import GL_MEAN, GL_P999, hlsl_check_user
from study.export.shaders import export_user_shader
from study.fit.calibrate import calibrate_model
from study.fit.model import get_value
from study.fit.spirv_model import SpirvModel

SHADERS = Path(__file__).parent / "shaders"
VERT, FRAG = SHADERS / "swell_water.vert", SHADERS / "swell_water.frag"
TRUTH = {"AMPLITUDE": 0.38, "uTiling": 1.65, "SCROLL": (0.13, -0.03), "SHINE": 0.35, "BUMP": 0.8}
STAGES = {"AMPLITUDE": "vertex", "uTiling": "vertex", "SCROLL": "vertex", "SHINE": "both",
          "BUMP": "fragment"}  # fmt: skip


@pytest.fixture(scope="module")
def inputs():
    return synthetic_inputs(width=48, height=36)


def _pair(tmp_path=None, vert=None, frag=None, decl=None, cells=(8, 8)) -> UserShader:
    """The swell pair, or with the texts ``vert`` / ``frag`` in place of its files."""
    vpath, fpath = VERT, FRAG
    if vert is not None:
        vpath = tmp_path / "v.vert"
        vpath.write_text(vert)
    if frag is not None:
        fpath = tmp_path / "f.frag"
        fpath.write_text(frag)
    return UserShader.from_file(fpath, decl, vertex=UserVertex.from_file(vpath, cells))


def test_the_constants_of_both_stages_are_one_parameter_vector(inputs, tmp_path):
    shader = _pair()
    assert {n: shader.stage_of(n) for n in shader.constants} == STAGES
    assert {n: c.stage for n, c in shader.constants.items()} == STAGES
    # a vec2's both components
    assert sorted(shader.scalar_names()) == ["AMPLITUDE", "BUMP", "SCROLL[0]", "SCROLL[1]",
                                             "SHINE", "uTiling"]  # fmt: skip
    start = {"AMPLITUDE": 0.3, "uTiling": 1.5, "SCROLL": (0.1, -0.05), "SHINE": 0.6, "BUMP": 0.5}
    assert shader.defaults() == start
    assert sorted(shader.vertex.shader.constants) == ["AMPLITUDE", "SCROLL", "SHINE", "uTiling"]
    # the vertex shader's constants change the image: the swell moves the coverage too
    a = shader.render(inputs).numpy()
    b = shader.render(inputs, {"AMPLITUDE": 0.42, "uTiling": 1.8}).numpy()
    assert ((a["mask"] > 0) ^ (b["mask"] > 0)).sum() > 10
    both = (a["mask"] > 0) & (b["mask"] > 0)
    assert np.abs(a["color"] - b["color"]).max(-1)[both].mean() > 1e-2
    # a `constant` line of fit.declare applies to whichever stage declares the uniform
    text = VERT.read_text().replace("// @study constant AMPLITUDE 0.0 1.0\n", "")
    shader = _pair(tmp_path, vert=text, decl={"constants": {"AMPLITUDE": [0.1, 0.8]}})
    c = shader.constants["AMPLITUDE"]
    assert (c.stage, c.lo, c.hi, c.default) == ("vertex", 0.1, 0.8, (0.3,))


def test_declaration_errors_name_the_problem(tmp_path):
    vert, frag = VERT.read_text(), FRAG.read_text()
    # a uniform of both stages: one start value (GL links it), one type
    both = frag.replace("SHINE 0.0 1.0 0.6", "SHINE 0.0 1.0").replace("SHINE;", "SHINE = 0.6;")
    with pytest.raises(ValueError, match=r"SHINE starts at \(0.6,\) in one stage and \(0.5,\)"):
        _pair(tmp_path, vert=vert.replace("SHINE;", "SHINE = 0.5;"), frag=both)
    with pytest.raises(ValueError, match="SHINE is declared float and vec3"):
        _pair(tmp_path, vert=vert.replace("uniform float SHINE", "uniform vec3 SHINE")
              .replace("glint = SHINE *", "glint = SHINE.x *"))  # fmt: skip
    with pytest.raises(ValueError, match="NOPE to fit has no one-line declaration in "
                                         "swell_water.frag or swell_water.vert"):  # fmt: skip
        _pair(decl={"constants": {"NOPE": [0.0, 1.0]}})
    match = r"v.vert:6: the constant AMPLITUDE is declared with the range \[0.0, 1.0\] here and "
    with pytest.raises(ValueError, match=match + r"\[0.0, 2.0\]"):
        _pair(tmp_path, vert=vert, frag=frag.replace("BUMP 0.0 2.0", "AMPLITUDE 0.0 2.0"))
    with pytest.raises(ValueError, match="v.vert:16: the uniform uTiling has no initializer"):
        _pair(tmp_path, vert=vert.replace("uTiling 0.25 4.0 1.5", "uTiling 0.25 4.0"))


def test_a_vertex_constant_that_only_moves_the_coverage_is_refused(inputs, tmp_path):
    """A constant that spreads the grid while the fragment shader reads only a flat colour: its
    derivative at a fixed coverage is 0 on every pixel, its effect only which pixels are
    covered."""
    vert = (
        "#version 330 core\n// @study constant SPREAD 0.5 1.5\nin vec3 inPosition;\n"
        "uniform mat4 g_WorldViewProjectionMatrix;\nflat out vec3 tint;\n"
        "const float SPREAD = 0.8;\nvoid main() {\n    tint = vec3(0.2, 0.4, 0.6);\n"
        "    vec3 p = vec3(SPREAD, 1.0, SPREAD) * inPosition;\n"
        "    gl_Position = g_WorldViewProjectionMatrix * vec4(p, 1.0);\n}\n"
    )
    frag = (
        "#version 330 core\nflat in vec3 tint;\nout vec4 fragColor;\n"
        "void main() { fragColor = vec4(tint, 1.0); }\n"
    )
    shader = _pair(tmp_path, vert=vert, frag=frag)
    assert shader.vertex_motion(inputs, None, ["SPREAD"])[0] > 0.1
    target = shader.render(inputs).numpy()["color"]
    match = "v.vert: the constant SPREAD moves the vertices .* changes only which pixels"
    with pytest.raises(ShaderError, match=match):
        SpirvModel(shader, inputs, target)


def test_jacobian_matches_central_differences(inputs):
    """Every constant of the pair, the vertex shader's included: through the per-vertex outputs
    and the interpolation weights (a displaced vertex moves the plane a pixel interpolates on),
    ``gl_FragCoord`` and the fragment shader; the coverage held fixed."""
    assert_user_jacobian(_pair(cells=(12, 12)), inputs, 0.9, moves_coverage=True)


def test_constants_of_both_stages_recovered_from_a_synthetic_target(inputs):
    """The pair rendered at known constants is the target, fitted from the start values: the
    clean target to 1e-4, a noisy one (sigma 0.01, seeded) within three standard errors. The
    scored pixels are those the target covers too (``study calibrate`` scores those the
    reference sees water at): between the start and the truth the swell changes the coverage
    of some pixels, which the fixed-coverage derivatives do not see."""
    shader = _pair()
    clean = shader.render(inputs, TRUTH).numpy()
    start = shader.render(inputs).numpy()
    assert ((clean["mask"] > 0) ^ (start["mask"] > 0)).sum() > 20
    noise = np.random.default_rng(7).normal(0.0, 0.01, clean["color"].shape).astype(np.float32)
    for target, exact in ((clean["color"], True), (clean["color"] + noise, False)):
        model = SpirvModel(shader, inputs, target, reference_mask=clean["mask"] > 0)
        cal = calibrate_model(model, model.start_constants(), sorted(TRUTH),
                              "levenberg_marquardt", 40)  # fmt: skip
        for name, p in cal.parameters.items():
            got, want = get_value(cal.fitted, name), get_value(TRUTH, name)
            assert p["status"] == "fitted", (name, p)
            if exact:
                assert abs(got - want) <= 1e-4 * abs(want), (name, got, want, cal.fit_summary)
            else:
                se = p["rel_std_error"] * abs(got)
                assert abs(got - want) <= 3 * se, (name, got, want, se)


def test_the_pair_at_other_values_runs_on_llvmpipe_like_the_executor(inputs, tmp_path):
    """The written-back pair (the vertex file's constants and the uniform of both stages with
    the values, the uniform without initializer set) on llvmpipe, and the fragment shader's
    HLSL round trip after the fitted vertex shader, against the executor at those values."""
    shader = _pair(cells=(16, 16))
    ours = shader.render(inputs, TRUTH).numpy()
    rgba, mask = user_gl_render_or_skip(shader, inputs, TRUTH)
    mine = ours["mask"] > 0.5
    both = mask & mine
    d = np.abs(rgba[..., :3] - ours["color"]).max(-1)[both]
    assert (mask ^ mine).sum() <= 0.002 * mask.sum(), int((mask ^ mine).sum())
    assert d.mean() <= 1e-5 and np.percentile(d, 99.9) <= GL_P999, (d.mean(), d.max())
    # at the start values the image differs: the GL check would see unfitted vertex constants
    start = shader.render(inputs).numpy()
    assert np.abs(start["color"] - ours["color"]).max(-1)[both & (start["mask"] > 0)].mean() > 1e-2
    export_user_shader(shader, TRUTH, tmp_path / "shaders", targets=("hlsl",))
    check = hlsl_check_user(shader, inputs, TRUTH, ours, tmp_path / "shaders")
    if not check["ran"]:
        pytest.skip(check["why"])
    assert check["passed"] and check["mean_abs"] <= GL_MEAN and check["pixels"] > 500, check


def _differs_only_in_numbers(before: str, after: str, values: dict) -> None:
    """Every line of ``after`` is ``before``'s, but the declarations of ``values``' constants,
    whose initializer is the value (a uniform without one gets one)."""
    a, b = before.split("\n"), after.split("\n")
    assert len(a) == len(b)
    for old, new in zip(a, b):
        if old == new:
            continue
        name = next(n for n in values if re.search(rf"\b{n}\b", old))
        v = values[name]
        lit = (f"vec2({', '.join(str(np.float32(x)) for x in v)})" if isinstance(v, (list, tuple))
               else str(np.float32(v)))  # fmt: skip
        want = (
            re.sub(r"=\s*[^;]*;", f"= {lit};", old)
            if "=" in old
            else old.replace(";", f" = {lit};")
        )
        assert new == want, (old, new)


def test_written_back_and_exported_with_the_fitted_values(inputs, tmp_path):
    """The vertex file written back differs from it only in the fitted numbers; the export
    writes it so, its engine targets carry the values, and ``study export`` of the
    calibration's ``constants.json`` writes the same."""
    from study.commands.export import run_export

    shader = _pair()
    vtext = shader.vertex_written(TRUTH)
    _differs_only_in_numbers(VERT.read_text(), vtext, TRUTH)
    _differs_only_in_numbers(FRAG.read_text(), shader.written(TRUTH), TRUTH)
    assert "const float AMPLITUDE = 0.38;" in vtext and "uniform float uTiling = 1.65;" in vtext
    assert "const vec2 SCROLL = vec2(0.13, -0.03);" in vtext
    export_user_shader(shader, TRUTH, tmp_path / "a" / "shaders", targets=("gles300", "hlsl"))
    core = tmp_path / "a" / "shaders" / "core"
    assert (core / "swell_water.vert").read_text() == vtext
    for target in ("gles300/swell_water.vert", "hlsl/swell_water.vert.hlsl"):
        text = (tmp_path / "a" / "shaders" / target).read_text()
        assert "0.3799999952316284" in text, target  # the fitted float32, folded in
        assert "0.300000011920928955078125" not in text, target  # the start value, nowhere
    # the uniforms without initializer: the binding sheets give the values to set
    sheet = (tmp_path / "a" / "shaders" / "gles300" / "BINDINGS.md").read_text()
    assert "| `uTiling` | uniform | float | by name | fitted constant: set it to 1.65 |" in sheet
    assert "| `SHINE` | uniform | float | by name | fitted constant: set it to 0.35 |" in sheet
    # study export of the calibration's record: the files of the pair, its declaration
    data = {"shader": "swell_water.frag", "shader_file": str(FRAG), "vertex_file": str(VERT),
            "vertex_grid": [8, 8], "constants": dict(TRUTH),
            "declaration": {"constants": {n: shader.declared_range(n) for n in shader.constants},
                            "bindings": {}}}  # fmt: skip
    (tmp_path / "constants.json").write_text(json.dumps(data))
    run_export(tmp_path / "constants.json", tmp_path / "b", targets="none")
    assert (tmp_path / "b" / "shaders" / "core" / "swell_water.vert").read_text() == vtext


@pytest.mark.slow
def test_study_calibrate_fits_the_vertex_shaders_constants(tmp_path, monkeypatch):
    """``study calibrate`` of the pair on the tiny pool: every constant in one fit, each with
    its stage in constants.json and the report, the written pair checked on llvmpipe, and
    ``fit.write_back = "file"`` writing the vertex file's fitted numbers into a copy of it."""
    from study.cli import main

    monkeypatch.setenv("STUDY_CACHE", str(tmp_path / "cache"))
    for f in (VERT, FRAG):
        (tmp_path / f.name).write_text(f.read_text())
    out = tmp_path / "c"
    args = sets(TINY) + sets([f'fit.shader="{tmp_path / FRAG.name}"', "fit.declare=[]",
                              f'fit.vertex="{tmp_path / VERT.name}"', "fit.vertex_grid=[16, 16]",
                              'fit.write_back="file"'])  # fmt: skip
    experiment = Path(__file__).parent.parent / "experiments" / "my_water.toml"
    assert main(["calibrate", str(experiment), "--out", str(out)] + args) == 0
    res = json.loads((out / "constants.json").read_text())
    assert {n.split("[")[0]: p["stage"] for n, p in res["parameters"].items()} == STAGES
    assert any(p["status"] == "fitted" for p in res["parameters"].values())
    assert "| stage |" in (out / "report.md").read_text()
    if res["gl_check"]["ran"]:
        assert res["gl_check"]["passed"], res["gl_check"]
    # the const's initializer replaced; the uniforms without one left so (the engine sets them)
    written = (tmp_path / VERT.name).read_text()
    _differs_only_in_numbers(VERT.read_text(), written, res["constants"])
    if res["parameters"]["AMPLITUDE"]["status"] in ("fitted", "bound"):
        assert written != VERT.read_text()
    assert "uniform float uTiling;" in written and "uniform float SHINE;" in written


def test_a_constant_of_the_vertex_stage_of_one_file_for_both_stages(inputs, tmp_path):
    """Urho3D's one file for both stages (``one_file_water.glsl``) with its grid tiling fitted:
    a uniform without initializer that an ``#include`` declares for the vertex stage only. Its
    derivative matches central differences; written back and on llvmpipe, the file stays as
    it is (the engine's include holds the uniform) and the GL check sets the value."""
    shutil.copytree(SHADERS / "include", tmp_path / "include")
    text = (SHADERS / "one_file_water.glsl").read_text()
    path = tmp_path / "one_file_water.glsl"
    path.write_text(
        text.replace("// @study value cTiling 0.5", "// @study constant cTiling 0.1 2.0 0.5")
    )
    vertex = UserVertex.from_file(path, (12, 12), ("COMPILEVS", "VS=main"), (), shared=True)
    shader = UserShader.from_file(path, None, ("COMPILEPS", "PS=main"), (), vertex=vertex)
    assert (shader.constants["cTiling"].stage, shader.stage_of("cTiling")) == ("vertex", "vertex")
    assert shader.stage_of("cTint") == "fragment"
    values = {**shader.defaults(), "cTiling": 0.7}
    base = shader.render(inputs, values).numpy()
    _, J = shader.render_with_jacobian(inputs, values, ["cTiling"])
    h = 3e-4  # 1e-3 puts a texel edge of the normal map inside one pixel's stencil undetected
    p = shader.render(inputs, {**values, "cTiling": 0.7 + h}).numpy()
    m = shader.render(inputs, {**values, "cTiling": 0.7 - h}).numpy()
    fd, water = (p["color"] - m["color"]) / (2 * h), base["mask"] > 0
    fp, fm = (p["color"] - base["color"]) / h, (base["color"] - m["color"]) / h
    smooth = water & (np.abs(fp - fm) <= 0.2 * np.abs(fd) + 2 * FD_NOISE / h).all(-1)
    assert smooth.sum() >= 0.9 * water.sum() and np.abs(fd[water]).max() > 0.1
    bad = smooth & ~(np.abs(J[..., 0] - fd) <= 2 * FD_NOISE / h + FD_RTOL * np.abs(fd)).all(-1)
    assert not bad.any(), int(bad.sum())
    assert shader.vertex_written(values) == shader.written(values) == path.read_text()
    rgba, mask = user_gl_render_or_skip(shader, inputs, values)
    d = np.abs(rgba[..., :3] - base["color"]).max(-1)[mask & water]
    assert d.mean() <= 1e-5, d.mean()


def test_values_a_declaration_gives_the_vertex_stage_survive_its_constants():
    """The vertex shader is compiled again once its constants are known; the uniforms a
    declaration's `value` lines set on it (fit.declare, after it was read) stay set."""
    from shaders_port.spirv.vertex import VertexShader

    v = VertexShader.from_file(SHADERS / "swell_water.vert")
    v.values["cEngineSet"] = (0.25, 0.5)
    w = v.with_constants(("AMPLITUDE",))
    assert w.constants == ("AMPLITUDE",) and w.values["cEngineSet"] == (0.25, 0.5)
