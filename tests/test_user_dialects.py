"""A user's shader as engines write it: GLSL 1.20, WebGL 1 (GLSL ES 1.00) and WebGL 2 (GLSL ES
3.00) files translated to GLSL 330 core (``shaders_port.spirv.dialects``) render the image of
their core equivalent through the executor and on llvmpipe; ``#include`` files and defines from
the experiment; uniforms without initializers as constants; and hostile shaders (a loop that
never ends, NaN pixels, an instruction the executor lacks, a dialect OpenGL cannot run, a
compile error) stop with one error naming the user's file and line."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from helpers import REPO
from helpers.experiments import TINY, sets
from helpers.gl import assert_ran_as_written
from helpers.synthetic import synthetic_inputs
from shaders_port.spirv.dialects import ShaderError, detect, front_end
from shaders_port.spirv.loops import MAX_PASSES
from shaders_port.spirv.support import check_supported, supported_opcodes, supported_std450
from shaders_port.spirv.translated import builtin_spec, module_of
from shaders_port.spirv.user_shader import UserShader
from shaders_port.spirv.vertex import VertexShader
from shaders_port.variants import VARIANTS
from study.cli import main
from study.config.errors import ExperimentError
from study.export.gl_check import GL_MEAN, GL_P999, gl_check_user
from study.fit.spirv_model import SpirvModel

SHADERS = Path(__file__).parent / "shaders"
INCLUDE = SHADERS / "include"
DIALECTS = {
    "schlick_fog_webgl1": ("GLSL ES 1.00", {}),
    "schlick_fog_es300": ("GLSL ES 3.00", {}),
    "schlick_fog_120": ("GLSL 1.20", {"defines": ["WATER_FOG=1"], "include_paths": [INCLUDE]}),
}


@pytest.fixture(scope="module")
def inputs():
    return synthetic_inputs(width=48, height=36)


@pytest.fixture(scope="module")
def core_image(inputs):
    return UserShader.from_file(SHADERS / "schlick_fog.frag").render(inputs).numpy()


@pytest.mark.parametrize("name", sorted(DIALECTS))
def test_each_dialect_renders_its_core_equivalent(name, inputs, core_image):
    """The same water in three dialects: the executor's image equals the core file's exactly
    (the translation changes names, not arithmetic); the written file on llvmpipe, as written
    on a context of its dialect (OpenGL compatibility profile for GLSL 1.20, OpenGL ES for
    GLSL ES), matches the executor within the GL check's thresholds."""
    dialect, kw = DIALECTS[name]
    shader = UserShader.from_file(SHADERS / f"{name}.frag", **kw).check()
    assert shader.dialect.name == dialect
    ours = shader.render(inputs).numpy()
    np.testing.assert_array_equal(ours["color"], core_image["color"])
    check = gl_check_user(shader, inputs, shader.defaults(), ours)
    assert check["ran"] and check["passed"], check
    assert check["mean_abs"] <= GL_MEAN and check["p999"] <= GL_P999
    assert_ran_as_written(check, "es" if shader.dialect.es else "compatibility")


def test_compatibility_built_ins_run_as_written_from_the_fixed_function_state(inputs, monkeypatch):
    """A GLSL 1.10 file reading gl_TexCoord[0], gl_NormalMatrix and gl_ModelViewProjectionMatrix
    runs as written on a compatibility-profile context (the matrices loaded as its
    fixed-function modelview and projection) and matches the executor (which reads them as the
    translation's study inputs); without such a context its core-profile translation runs,
    and the record says why."""
    from shaders_port.spirv import gl_run
    from study.report.calibration import _export_lines

    shader = UserShader.from_file(SHADERS / "compat_builtins_110.frag").check()
    assert shader.dialect.name == "GLSL 1.10"
    ours = shader.render(inputs).numpy()
    check = gl_check_user(shader, inputs, shader.defaults(), ours)
    assert check["ran"] and check["passed"], check
    assert_ran_as_written(check, "compatibility")
    report = "\n".join(_export_lines(check, "`shaders/core/compat_builtins_110.frag`"))
    assert f"the GL check ran {check['text']} on {check['context']}, vs the Dr.Jit" in report
    monkeypatch.setattr(gl_run, "context_support", lambda kind: (0, "EGL: none, for the test"))
    check = gl_check_user(shader, inputs, shader.defaults(), ours)
    assert check["ran"] and check["passed"], check
    assert check["text"] == "its core-profile translation (GLSL 330 core)"
    assert check["why_translation"] == (
        "no OpenGL compatibility-profile context here (EGL: none, for the test)"
    )
    report = "\n".join(_export_lines(check, "`shaders/core/compat_builtins_110.frag`"))
    assert f"core-profile translation (GLSL 330 core) on {check['context']} (not" in report
    assert "(not as written: no OpenGL compatibility-profile context here" in report


@pytest.mark.parametrize(
    "version", ["130", "140", "150 compatibility", "330 compatibility", "460 compatibility"]
)
def test_each_desktop_version_runs_as_written_where_the_context_runs_it(version, inputs):
    """The GLSL 1.10 file under each later desktop #version: as written on the compatibility
    profile (after the study's vertex shader in GLSL 1.20 or 1.50 compatibility, which link
    with it), except a version newer than the context, whose translation runs, saying why."""
    from shaders_port.spirv.gl_run import context_support

    src = f"#version {version}\n" + (SHADERS / "compat_builtins_110.frag").read_text()
    shader = UserShader(src, "v.frag").check()
    check = gl_check_user(shader, inputs, shader.defaults(), shader.render(inputs).numpy())
    assert check["ran"] and check["passed"], check
    newest, about = context_support("compatibility")
    if newest and shader.dialect.version > newest:
        assert check["why_translation"] == f"{shader.dialect.name} is newer than {about} runs"
    else:
        assert_ran_as_written(check, "compatibility")


def test_a_file_the_driver_rejects_as_written_runs_as_its_translation(inputs, capsys):
    """A WebGL 1 file with GL_EXT_shader_texture_lod (GLSL 330 has textureLod built in): where
    the ES driver lacks the extension (Mesa's ES 3 context offers it no GLSL ES 1.00 shader),
    the check runs the translation and quotes the driver; the #extension line comes before the
    precision lines the highp text adds (GLSL ES takes no #extension after a statement)."""
    src = (
        "#extension GL_EXT_shader_texture_lod : enable\nprecision highp float;\n"
        "// @study constant K 0.1 2.0 1.0\nuniform float K;\nuniform sampler2D normalMap;\n"
        "varying vec4 vTexCoord0;\n"
        "void main() { gl_FragColor = K * texture2DLodEXT(normalMap, vTexCoord0.xy, 0.0); }\n"
    )
    shader = UserShader(src, "lod.frag").check()
    check = gl_check_user(shader, inputs, shader.defaults(), shader.render(inputs).numpy())
    assert check["ran"] and check["passed"], check
    if check["text"].startswith("its core-profile translation"):
        why = check["why_translation"]
        assert why.startswith("OpenGL ES 3.") and "rejected your file as written: " in why
        assert "texture2DLodEXT" in why and "its translation runs" in capsys.readouterr().err
    else:
        assert_ran_as_written(check, "es")


def test_an_es_file_runs_at_highp_and_its_own_precision_is_measured(inputs, capsys):
    """The WebGL 1 file samples at lowp (GLSL ES's default for samplers): on OpenGL ES its check
    runs it with every value at highp, which matches the executor (32-bit); the file at its own
    precision is measured beside it, and where llvmpipe computes lowp at 16-bit float (on a
    CPU with F16C) and the difference passes the thresholds the record says why."""
    shader = UserShader.from_file(SHADERS / "schlick_fog_webgl1.frag").check()
    assert "precision highp sampler2D" not in shader.source
    ours = shader.render(inputs).numpy()
    check = gl_check_user(shader, inputs, shader.defaults(), ours)
    assert check["ran"] and check["passed"], check
    assert_ran_as_written(check, "es")
    from shaders_port.spirv.gl_run import context_support

    if not context_support("es")[0]:
        pytest.skip("no OpenGL ES context here: the file ran as its translation")
    assert check["text"].endswith(", every value at highp (lowp and mediump read as highp)")
    own = check["own_precision"]
    assert own["mean_abs"] >= check["mean_abs"] and own["within"] == ("note" not in own), own
    if not own["within"]:
        assert "16-bit float" in own["note"] and "precision highp sampler2D" in own["note"]
        # on the command line too, not in the report alone
        assert own["note"] in capsys.readouterr().err
    # the text at highp: lowp and mediump defined as highp after #version, the lines kept
    with shader.gl_renderer(inputs, shader.defaults()) as r:
        text = r.gl_run.text
    assert text.startswith("#version 100\n#define lowp highp\n#define mediump highp\n")
    assert text.split("#line 1\n", 1)[1] == shader.source


def _core_with_uniforms(tmp_path) -> Path:
    """schlick_fog.frag (GLSL 330 core) with its fog constants as uniforms with initializers."""
    src = (SHADERS / "schlick_fog.frag").read_text()
    for name in ("FOG_DENSITY", "FOG_COLOR"):
        kind = "float" if name == "FOG_DENSITY" else "vec3"
        assert f"const {kind} {name} = " in src
        src = src.replace(f"const {kind} {name} = ", f"uniform {kind} {name} = ")
    path = tmp_path / "schlick_fog_uniforms.frag"
    path.write_text(src)
    return path


@pytest.mark.parametrize("name", [*sorted(DIALECTS), "schlick_fog_uniforms"])
def test_each_dialect_exports_to_the_engine_targets(name, tmp_path, inputs):
    """The file is exported as it was written (fitted numbers in place); the engine targets are
    translated from its GLSL 330 core translation (glslang makes no SPIR-V of the older
    dialects: the export of a WebGL 1 file failed there after its fit), every uniform of a
    fitted constant declared without initializer there (GLSL ES refuses the initializers of
    GLSL 1.20 and 330 files, HLSL ignores them) and its fitted value in the binding sheets, for
    the material to set; the HLSL run back on llvmpipe with those values matches."""
    from shaders_port.spirv.tools import missing_tools
    from study.export.gl_check import gles_check_user, hlsl_check_user
    from study.export.shaders import export_user_shader

    if missing_tools():
        pytest.skip(f"the engine targets need {', '.join(missing_tools())}")
    path = _core_with_uniforms(tmp_path) if name not in DIALECTS else SHADERS / f"{name}.frag"
    kw = DIALECTS.get(name, ("", {}))[1]
    shader = UserShader.from_file(path, **kw).check()
    values = {"FOG_DENSITY": 0.8, "FOG_COLOR": (0.1, 0.25, 0.3)}  # fitted, not the start values
    out = tmp_path / "shaders"
    export_user_shader(shader, values, out, ["hlsl", "gles300"])
    written = (out / "core" / f"{name}.frag").read_text()
    assert written == shader.written(values)
    for target in ("hlsl/{}.frag.hlsl", "gles300/{}.frag"):
        text = (out / target.format(name)).read_text()
        assert re.search(r"\bFOG_DENSITY\s*=", text) is None, target  # no initializer
        sheet = (out / target.split("/")[0] / "BINDINGS.md").read_text()
        assert "## Uniforms the material sets" in sheet
        assert "| `FOG_DENSITY` | float | 0.8 |" in sheet, sheet
        assert "| `FOG_COLOR` | vec3 | vec3(0.1, 0.25, 0.3) |" in sheet, sheet
    # the HLSL runs back on llvmpipe (its colour output is the translation's _study_FragColor),
    # the GLSL ES on an OpenGL ES context, each with the sheet's values set as uniforms
    ours = shader.render(inputs, values).numpy()
    check = hlsl_check_user(shader, inputs, values, ours, out)
    if not check.get("ran"):
        pytest.skip(f"the HLSL round trip did not run here: {check.get('why')}")
    assert check["passed"], check
    check = gles_check_user(shader, inputs, values, ours, out)
    if not check.get("ran"):
        pytest.skip(f"no OpenGL ES context here: {check.get('why')}")
    assert check["passed"] and check["context"].startswith("OpenGL ES 3."), check
    # the fitted values are what the GLSL ES needs: the start values give another image
    other = gles_check_user(shader, inputs, shader.defaults(), ours, out)
    assert other["ran"] and not other["passed"], other


def test_dialects_are_detected_and_unknown_versions_refused():
    cases = {
        "precision mediump float;\nvoid main() {}\n": "GLSL ES 1.00",
        "void main() { gl_FragColor = vec4(1.0); }\n": "GLSL 1.10",
        "// head\n#version 100\nvoid main() {}\n": "GLSL ES 1.00",
        "#version 150 compatibility\n": "GLSL 1.50",
        "#version 300 es\n": "GLSL ES 3.00",
        "#version 460 core\n": "GLSL 460 core",
    }
    for src, name in cases.items():
        assert detect(src, "a.frag").name == name, src
    with pytest.raises(ShaderError, match=r"a\.frag:2: '#version 200' is no version"):
        detect("// x\n#version 200\n", "a.frag")
    with pytest.raises(ShaderError, match=r"a\.frag:2: #version must come before"):
        detect("float x;\n#version 330\n", "a.frag")


def test_translation_keeps_the_users_line_numbers():
    """An undeclared name on line 6 of a WebGL 1 file, behind comments, a precision block and
    an #include: glslang's message quotes that line of the user's file, and no built-in."""
    src = (
        "// a WebGL 1 material\n#ifdef GL_ES\nprecision mediump float;\n#endif\n"
        '#include "water_common.glsl"\nvoid main() { gl_FragColor = vec4(waterTint, 1.0); }\n'
    )
    with pytest.raises(ShaderError) as err:
        front_end(src, "tint.frag", include_paths=[INCLUDE])
    msg = str(err.value)
    assert msg.startswith("tint.frag does not compile (GLSL ES 1.00):\ntint.frag:6: 'waterTint'")
    assert len(msg.splitlines()) <= 3 and "gl_MaxDrawBuffers" not in msg


def test_a_legacy_file_is_preprocessed_in_its_own_version(tmp_path):
    """An engine's compatibility include that switches on ``__VERSION__`` (as jMonkeyEngine's
    GLSLCompat does) takes the GLSL 1.20 branch, where ``texture`` is a user's name; a refused
    form after the include is named at its own line."""
    (tmp_path / "compat.glsllib").write_text(
        "#if __VERSION__ >= 130\n#define texture2D texture\nout vec4 outColor;\n"
        "#define gl_FragColor outColor\n#else\n#define LEGACY_BRANCH 1\n#endif\n"
    )
    src = (
        '#version 120\n#import "compat.glsllib"\n#ifndef LEGACY_BRANCH\n#error not 1.20\n'
        "#endif\nuniform sampler2D tex;\nvarying vec2 uv;\nvoid main() {\n"
        "  float texture = 0.5;\n  gl_FragColor = texture2D(tex, uv) * texture;\n%s}\n"
    )
    text = front_end(src % "", "legacy.frag", include_paths=[tmp_path])
    assert "_u_texture" in text and "LEGACY_BRANCH" not in text
    with pytest.raises(ShaderError, match=r"^legacy\.frag:11: gl_Color: a compatibility"):
        front_end(src % "  gl_FragColor = gl_Color;\n", "legacy.frag", include_paths=[tmp_path])


def test_es_functions_glslang_holds_as_extension_built_ins_and_unread_bool_uniforms(inputs):
    """A GLSL ES 3.00 file defining its own `average` (three.js's `common` chunk), which
    glslang's ES tables hold as an extension built-in, compiles and runs; an unread `uniform
    bool` (three.js's `isOrthographic`, which SPIR-V for OpenGL cannot hold) is left aside and a
    read one is refused with the fix."""
    src = (
        "#version 300 es\nprecision highp float;\nuniform bool isOrthographic;\n%s"
        "// @study constant GAIN 0.5 2.0\nconst float GAIN = 1.0;\n"
        "in vec3 varyingVecWorldPosition;\nout vec4 color;\n"
        "float average( const in vec3 v ) { return dot( v, vec3( 0.3333333 ) ); }\n"
        "void main() { color = vec4(GAIN * vec3(average(fract(varyingVecWorldPosition))), 1.0); }\n"
    )
    out = UserShader(src % "", "avg.frag").render(inputs).numpy()
    m = out["mask"] > 0
    assert m.sum() > 100 and np.all(np.isfinite(out["color"][m]))
    assert 0.05 < out["color"][m].mean() < 0.95 and out["color"][m].std() > 0.01
    read = src % "float ortho() { return isOrthographic ? 1.0 : 0.0; }\n"
    read = read.replace("1.0); }", "ortho()); }")
    with pytest.raises(ShaderError, match="uniform bool isOrthographic: SPIR-V for OpenGL"):
        UserShader(read, "avg.frag").render(inputs)


def test_the_version_line_an_engine_puts_before_the_file_is_a_define(inputs):
    """A file without #version that its engine compiles as GLSL 1.50 (Urho3D's GL3 path puts
    `#version 150` before it) takes the define `#version 150`: read as GLSL 1.50, its line
    numbers kept; a file with its own #version refuses the define."""
    src = (
        "// no version line: the engine gives it\nin vec3 varyingVecWorldPosition;\n"
        "out vec4 color;\n// @study constant GAIN 0.5 2.0\nconst float GAIN = 1.0;\n"
        "void main() { color = vec4(GAIN * fract(varyingVecWorldPosition), 1.0); }\n"
    )
    with pytest.raises(ShaderError):  # GLSL 1.10, as the file reads without the define
        UserShader(src, "v.frag").check()
    shader = UserShader(src, "v.frag", defines=["#version 150"])
    assert shader.dialect.name == "GLSL 1.50" and shader.dialect.line == 0
    m = shader.render(inputs).numpy()["mask"] > 0
    assert m.sum() > 100
    with pytest.raises(ShaderError, match=r"\(GLSL 1\.50\):\nv\.frag:6: 'nope'"):
        front_end(src.replace("GAIN *", "nope *"), "v.frag", ["#version 150"])
    with pytest.raises(ShaderError, match="has its own #version; remove the define"):
        front_end("#version 330 core\n" + src, "v.frag", ["#version 150"])


def test_refused_legacy_forms_name_their_line():
    base = "#version 120\nvarying vec3 varyingVecEye;\nvoid main() {\n%s\n}\n"
    for body, why in (
        ("gl_FragData[1] = vec4(1.0);", r"gl_FragData\[1\]: the study compares one colour"),
        ("gl_FragColor = gl_Color;", r"gl_Color: a compatibility built-in"),
        ("gl_FragColor = gl_TexCoord[5];", r"gl_TexCoord: only gl_TexCoord\[0\]"),
    ):
        with pytest.raises(ShaderError, match=rf"^legacy\.frag:4: {why}"):
            front_end(base % body, "legacy.frag")


def test_include_and_define_errors_name_the_file_and_the_search_path(tmp_path):
    src = (SHADERS / "schlick_fog_120.frag").read_text()
    with pytest.raises(ShaderError) as err:
        UserShader(src, "schlick_fog_120.frag", include_paths=[tmp_path]).check()
    assert "schlick_fog_120.frag:11: '#include' : Could not process include directive" in str(
        err.value
    )
    assert f"water_common.glsl (searched {tmp_path}" in str(err.value)
    with_fog = UserShader.from_file(SHADERS / "schlick_fog_120.frag", None, ["WATER_FOG=1"],
                                    [INCLUDE])  # fmt: skip
    without = UserShader.from_file(SHADERS / "schlick_fog_120.frag", None, (), [INCLUDE])
    inputs = synthetic_inputs(width=16, height=12)
    a, b = with_fog.render(inputs).numpy()["color"], without.render(inputs).numpy()["color"]
    assert np.abs(a - b).max() > 0.01  # `#if WATER_FOG`: the define switches the fog on


def test_bare_uniforms_take_declared_start_values_and_are_written_back_by_dialect():
    """WebGL 1: no uniform initializers, so the written file is the user's byte for byte (the
    fitted values go to constants.json and the GL check sets them); GLSL 1.20 takes an
    initializer, which the written file gets."""
    webgl = UserShader.from_file(SHADERS / "schlick_fog_webgl1.frag")
    assert webgl.defaults()["FOG_COLOR"] == (0.05, 0.2, 0.25)
    assert webgl.written({"FOG_DENSITY": 0.8}) == webgl.source
    assert webgl.declared_range("FOG_DENSITY") == [0.01, 4.0, 0.35]
    src = "#version 120\n// @study constant K 0.0 2.0 0.5\nuniform float K;\nvoid main() {\n"
    src += "gl_FragColor = vec4(K);\n}\n"
    assert "uniform float K = 0.8;\n" in UserShader(src, "k.frag").written({"K": 0.8})
    with pytest.raises(ValueError, match=r"k\.frag:3: the uniform K has no initializer"):
        UserShader(src.replace(" 0.5\n", "\n"), "k.frag")


@pytest.mark.timeout(120)
def test_a_loop_that_never_ends_is_stopped_with_its_line(inputs):
    shader = UserShader.from_file(SHADERS / "hostile_loop.frag").check()
    with pytest.raises(ShaderError, match=rf"^hostile_loop\.frag:12: a loop did not end within "
                       rf"{MAX_PASSES} passes for \d+ pixel"):  # fmt: skip
        shader.render(inputs)


def test_non_finite_pixels_are_one_error_with_their_places(inputs):
    shader = UserShader.from_file(SHADERS / "hostile_nan.frag")
    with pytest.warns(RuntimeWarning, match="non-finite"):  # a model built directly warns
        model = SpirvModel(shader, inputs, np.zeros((36, 48, 3), np.float32))
    with pytest.raises(ShaderError) as err:
        model.check_finite()
    msg = str(err.value)
    assert msg.startswith("hostile_nan.frag: the shader's colour is not finite (NaN or inf) on ")
    assert "pixel (x, y) from the top left: (" in msg and "all within x " in msg


def test_non_finite_pixels_at_a_trial_step_name_the_constants_and_the_fix(inputs):
    """Finite at its start values, the shader goes NaN where a constant's declared range lets a
    step reach (sqrt of K - 1.2 below 1.2): the model's error names the pixels, the constants'
    values there and what to change; the fit never goes on with NaN."""
    src = (
        "#version 330 core\n// @study constant K 0.0 2.0\nconst float K = 1.5;\n"
        "in vec3 varyingVecWorldPosition;\nout vec4 color;\n"
        "void main() { color = vec4(fract(varyingVecWorldPosition) + sqrt(K - 1.2), 1.0); }\n"
    )
    model = SpirvModel(UserShader(src, "k.frag"), inputs, np.zeros((36, 48, 3), np.float32))
    assert np.all(np.isfinite(model.residual({"K": 1.5})))
    with pytest.raises(FloatingPointError) as err:
        model.residual({"K": 1.0})
    msg = str(err.value)
    assert "non-finite water pixels (first at pixel (" in msg and "at K=1.0" in msg
    assert "narrow the range of the constant" in msg


def test_an_unsupported_instruction_is_one_error_line(inputs):
    # found by the check when the shader loads (spirv.support), and by the executor itself
    shader = UserShader.from_file(SHADERS / "hostile_unsupported.frag")
    with pytest.raises(ValueError, match=r"OpBitReverse, at hostile_unsupported\.frag:11$"):
        shader.check()
    with pytest.raises(ValueError, match=r"OpBitReverse, at hostile_unsupported\.frag:11$"):
        shader.render(inputs)


def test_an_unsupported_instruction_is_refused_when_the_experiment_loads(tmp_path, capsys):
    from study import load_experiment

    exp_file = tmp_path / "e.toml"
    exp_file.write_text(f'[fit]\nshader = "{SHADERS / "hostile_unsupported.frag"}"\n')
    want = (
        "fit.shader: the SPIR-V executor does not support OpBitReverse, at "
        "hostile_unsupported.frag:11"
    )
    with pytest.raises(ExperimentError) as err:
        load_experiment(exp_file)
    assert str(err.value) == want
    cache = tmp_path / "cache"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("STUDY_CACHE", str(cache))
        rc = main(["calibrate", str(exp_file), "--out", str(tmp_path / "out"), *sets(TINY)])
    err = capsys.readouterr().err
    assert rc == 2 and f"study calibrate: error: {want}\n" in err and "Traceback" not in err
    assert not cache.exists() or not any(cache.rglob("*.exr"))


def test_the_load_check_passes_every_shader_the_executor_runs():
    # the supported set is read from the executor's dispatch: no shader it runs is refused
    for variant in VARIANTS.values():
        check_supported(module_of(builtin_spec(variant.shader, variant.defines)))
    for path in sorted(SHADERS.glob("*.frag")):
        if path.stem == "hostile_unsupported":
            continue
        opts = DIALECTS.get(path.stem, ("", {}))[1]
        shader = UserShader.from_file(path, None, opts.get("defines", ()),
                                      opts.get("include_paths", ()))  # fmt: skip
        check_supported(module_of(shader.spec()))
    for path in sorted(SHADERS.glob("*.vert")):
        check_supported(VertexShader.from_file(path).module)
    assert {"OpPhi", "OpSwitch", "OpKill", "OpMatrixTimesVector"} <= supported_opcodes()
    assert "OpBitReverse" not in supported_opcodes()
    assert {"Cross", "Reflect", "Normalize", "FMix", "Pow"} <= supported_std450()


def test_gl_check_of_a_dialect_no_context_runs_fails_with_its_reason(inputs, capsys, monkeypatch):
    """GLSL ES 3.10 runs as written on an OpenGL ES context; where none is made it has no
    translation to fall back to: a failed check naming the reason."""
    from shaders_port.spirv import gl_run

    shader = UserShader.from_file(SHADERS / "water_es310.frag").check()
    ours = shader.render(inputs).numpy()
    if gl_run.context_support("es")[0] >= 310:
        check = gl_check_user(shader, inputs, {}, ours)
        assert check["ran"] and check["passed"], check
        assert_ran_as_written(check, "es")
    monkeypatch.setattr(gl_run, "context_support", lambda kind: (0, "EGL: none, for the test"))
    check = gl_check_user(shader, inputs, {}, ours)
    assert check["passed"] is False and check["ran"] is False
    assert check["why"] == (
        "water_es310.frag is GLSL ES 3.10, which no context here runs (no OpenGL ES context "
        "here (EGL: none, for the test)) and which has no core-profile translation; glslang "
        "compiled it with its ES profile"
    )
    assert "the GL check failed: water_es310.frag" in capsys.readouterr().err


def test_experiment_keys_and_a_broken_shader_refused_before_any_reference(tmp_path, capsys):
    """fit.include_paths (relative to the experiment) and fit.defines reach the compiler; a
    shader that does not compile stops `study calibrate` when the experiment loads, before a
    reference is rendered (the cache stays empty), with glslang's line."""
    from study import load_experiment

    (tmp_path / "inc").mkdir()
    (tmp_path / "inc" / "water_common.glsl").write_text((INCLUDE / "water_common.glsl").read_text())
    shader = tmp_path / "w.frag"
    shader.write_text((SHADERS / "schlick_fog_120.frag").read_text())
    exp_file = tmp_path / "e.toml"
    exp_file.write_text(
        '[fit]\nshader = "w.frag"\ninclude_paths = ["inc"]\ndefines = ["WATER_FOG=1"]\n'
    )
    exp = load_experiment(exp_file)
    assert exp.values["fit.include_paths"] == [str(tmp_path / "inc")]
    with pytest.raises(ExperimentError, match=r"fit.defines: 'GL_X' is not"):
        load_experiment(exp_file, ['fit.defines=["GL_X"]'])
    shader.write_text(shader.read_text().replace("n.x * BUMP", "n.x * BUMPS"))
    cache = tmp_path / "cache"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("STUDY_CACHE", str(cache))
        rc = main(["calibrate", str(exp_file), "--out", str(tmp_path / "out"), *sets(TINY)])
    err = capsys.readouterr().err
    assert rc == 2
    assert "study calibrate: error: fit.shader: w.frag does not compile (GLSL 1.20):\n" in err
    assert "w.frag:26: 'BUMPS' : undeclared identifier" in err and "Traceback" not in err
    assert not cache.exists() or not any(cache.rglob("*.exr"))


def test_study_calibrate_reports_nan_pixels_not_a_json_error(tmp_path, capsys):
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("STUDY_CACHE", str(tmp_path / "cache"))
        shader = f'fit.shader="{SHADERS / "hostile_nan.frag"}"'
        out = str(tmp_path / "out")
        rc = main(["calibrate", str(REPO / "experiments" / "default.toml"), "--out", out,
                   *sets([*TINY, shader])])  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 2
    assert "study calibrate: error: fit.shader" not in err  # the file compiles
    assert "study calibrate: error: hostile_nan.frag: the shader's colour is not finite" in err
    assert "JSON" not in err and "Traceback" not in err
