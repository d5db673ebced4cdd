"""The SPIR-V executor (``shaders_port.spirv.translated``): the study's GLSL files compiled by
glslang and executed on Dr.Jit types, against the hand ports (images, costs, Jacobians), central
differences and llvmpipe. The default run checks a representative subset; every shipped variant
is checked in the slow tests."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.synthetic import synthetic_baseline_inputs, synthetic_inputs
from shaders_port import Constants
from shaders_port.spirv import translated as spirv_port
from shaders_port.spirv.execute import UnboundVariable, UnsupportedInstruction
from shaders_port.spirv.module import Module, compile_fragment, grammar
from shaders_port.variants import SHIPPED, VARIANTS
from helpers.gl import check_gl_match, compare_or_skip
from helpers.images import save_comparison
from helpers.port_checks import FD_CONSTANTS, check_jacobian_column

CUSTOM = Constants(
    attenuation_distance=3.0, steps_grazing=7.0, steps_steep=2.5, bumptex_mult=0.7,
    specular_exponent=64.0, absorption_r=0.3, refine_steps=2,
)  # fmt: skip
DEFAULT_SET = ["water_refraction", "water_refraction_secant", "water_reflection_beer"]


@pytest.fixture(scope="module")
def small():
    return synthetic_inputs(width=48, height=36)


@pytest.fixture(scope="module")
def baseline_small():
    return synthetic_baseline_inputs(width=48, height=36)


def _inputs_for(variant, small, baseline_small):
    return variant.prepare_inputs(baseline_small if variant.inputs else small)


def _executed(variant, inputs, constants):
    spec = spirv_port.builtin_spec(variant.shader, variant.defines)
    return spirv_port.render(inputs, constants, spec=spec).numpy()


def _port_cost(out: dict) -> tuple:
    iterations = out["iterations"] + out.get("refl_iterations", 0.0)
    passes = 1.0 if "refraction_index" in out else 0.0
    return iterations, out["fetches"] - passes


def check_against_port(name: str, small, baseline_small, constants) -> None:
    """Executor vs hand port: the colour (bit-identical for the raycast shaders, 1e-4 for the
    baseline, whose matrix products the port writes row by row), loop iterations and texture
    fetches per pixel."""
    v = VARIANTS[name]
    inputs = _inputs_for(v, small, baseline_small)
    a, b = _executed(v, inputs, constants), v.render(inputs, constants).numpy()
    tol = 1e-4 if v.shader == "water_baseline" else 0.0
    if not np.abs(a["color"] - b["color"]).max() <= tol:
        save_comparison(f"spirv_{name}", a["color"], b["color"])
    assert np.abs(a["color"] - b["color"]).max() <= tol, name
    iterations, fetches = b["iterations"] + b.get("refl_iterations", 0.0), b["fetches"]
    if v.shader == "water_baseline":  # the port adds the mirrored camera's pass
        from shaders_port.ports.water_baseline import PASS_FETCHES

        fetches = np.where(b["mask"] > 0, fetches - PASS_FETCHES, 0.0)
    assert np.array_equal(a["iterations"], iterations), name
    assert np.array_equal(a["fetches"], fetches), name


@pytest.mark.parametrize("name", DEFAULT_SET + ["water_baseline"])
def test_executor_equals_port(name, small, baseline_small):
    check_against_port(name, small, baseline_small, CUSTOM)


@pytest.mark.slow
@pytest.mark.parametrize("name", SHIPPED)
@pytest.mark.parametrize("which", ["default", "custom"])
def test_every_variant_equals_port(name, which, small, baseline_small):
    check_against_port(name, small, baseline_small, Constants() if which == "default" else CUSTOM)


def check_against_gl(name: str, constants) -> None:
    v = VARIANTS[name]
    inputs = synthetic_baseline_inputs(96, 72) if v.inputs else synthetic_inputs(96, 72)
    inputs = v.prepare_inputs(inputs)
    # the decision diagnostics that explain GL outliers are the port's (the same code path:
    # the colours are equal, see check_against_port); the colour is the executor's
    out = v.render(inputs, constants).numpy()
    out["color"] = _executed(v, inputs, constants)["color"]
    check_gl_match(compare_or_skip(inputs, constants, name, output=out), f"spirv_gl_{name}")


def test_executor_matches_gl():
    pytest.importorskip("moderngl")
    check_against_gl("water_refraction", CUSTOM)


@pytest.mark.slow
@pytest.mark.parametrize("name", SHIPPED)
def test_every_variant_matches_gl(name):
    pytest.importorskip("moderngl")
    check_against_gl(name, CUSTOM)


JAC_NAMES = ["attenuation_distance", "steps_grazing", "bumptex_mult", "water_color[1]"]


@pytest.fixture(scope="module")
def jacobians(small):
    v = VARIANTS["water_refraction_secant"]
    spec = spirv_port.builtin_spec(v.shader, v.defines)
    out, J = spirv_port.render_with_jacobian(small, FD_CONSTANTS, JAC_NAMES, spec=spec)
    _, J_port = v.render_with_jacobian(small, FD_CONSTANTS, JAC_NAMES)
    return spec, out.numpy(), J, J_port


def test_jacobian_equals_port(jacobians):
    spec, out, J, J_port = jacobians
    scale = np.abs(J_port).max(axis=(0, 1, 2))
    assert (scale > 0).all()
    assert (np.abs(J - J_port).max(axis=(0, 1, 2)) <= 1e-4 * scale).all()


@pytest.mark.parametrize("name", ["steps_grazing", "bumptex_mult"])
def test_jacobian_matches_central_differences(jacobians, small, name):
    spec, out, J, _ = jacobians
    plain = spirv_port.render(small, FD_CONSTANTS, spec=spec).numpy()
    assert np.array_equal(plain["color"], out["color"])  # unrolled loops compute the same
    check_jacobian_column(
        lambda c: spirv_port.render(small, c, spec=spec).numpy(),
        out,
        J[..., JAC_NAMES.index(name)],
        FD_CONSTANTS,
        name,
        ("iterations",),
    )


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in SHIPPED if n != "water_refraction_game_textures"])
def test_every_variant_jacobian_equals_port(name, small, baseline_small):
    v = VARIANTS[name]
    inputs = _inputs_for(v, small, baseline_small)
    names = [n for n in ("bumptex_mult", "water_color[2]", "refraction_strength") if
             n.split("[")[0] in v.reads()]  # fmt: skip
    spec = spirv_port.builtin_spec(v.shader, v.defines)
    _, J = spirv_port.render_with_jacobian(inputs, FD_CONSTANTS, names, spec=spec)
    _, J_port = v.render_with_jacobian(inputs, FD_CONSTANTS, names)
    scale = np.abs(J_port).max(axis=(0, 1, 2))
    assert (np.abs(J - J_port).max(axis=(0, 1, 2)) <= 1e-4 * scale + 1e-7).all(), name


# ---- the module, errors ----------------------------------------------------------------------

_SHADER = """#version 330 core
in vec3 varyingVecEye;
out vec4 fragColor;
uniform float GAIN = 2.0;
void main(void)
{
    vec3 e = normalize(varyingVecEye);
    fragColor = vec4(e * GAIN, 1.0);
%s
}
"""


def test_module_is_decoded_with_the_grammar():
    mod = Module(compile_fragment(_SHADER % "", "tiny.frag"), label="tiny.frag")
    ops = {i.opname for b in mod.functions[mod.entry].blocks.values() for i in b.body}
    assert {"OpLoad", "OpExtInst", "OpStore"} <= ops
    assert grammar()["glsl"][69] == "Normalize"
    assert mod.name(mod.interface[0]) in ("varyingVecEye", "fragColor")


def test_unsupported_instruction_names_opcode_and_line(small):
    src = _SHADER % "    fragColor.x += outerProduct(e, e)[0][0];"
    spec = spirv_port.ShaderSpec(src, "deriv.frag")
    with pytest.raises(UnsupportedInstruction, match=r"OpOuterProduct.*deriv\.frag:9"):
        spirv_port.render(small, None, spec=spec)


def test_unbound_uniform_is_named(small):
    src = (_SHADER % "    fragColor.y *= mystery;").replace(
        "void main", "uniform float mystery;\nvoid main"
    )
    with pytest.raises(UnboundVariable, match=r"'mystery.*deriv\.frag:10"):
        spirv_port.render(small, None, spec=spirv_port.ShaderSpec(src, "deriv.frag"))


def test_missing_constant_declaration_is_named():
    spec = spirv_port.ShaderSpec(_SHADER % "", "tiny.frag", constants=(("FOG", "fog"),))
    with pytest.raises(ValueError, match="FOG"):
        spec.prepared_source()


# ---- the fit through SPIR-V -----------------------------------------------------------------


@pytest.mark.slow
def test_default_experiment_fits_the_same_constants(tmp_path, monkeypatch):
    """``study calibrate``'s fit of the default experiment with the shader executed through
    SPIR-V (``ShaderModel(translated=True)``) gives the hand port's fitted constants within
    1e-3 relative."""
    from helpers import REPO
    from study._backend import init_backend
    from study.calibration.frames import load_scene_data
    from study.fit.calibrate import calibrate_experiment
    from study.fit.model import ShaderModel, expand_parameters, get_value
    from study.config.experiment import load_experiment

    monkeypatch.setenv("STUDY_CACHE", str(tmp_path))
    exp = load_experiment(REPO / "experiments" / "default.toml")
    variant = init_backend(exp["variant"])
    ref, inputs, _ = load_scene_data(exp, variant)
    fits = {}
    for translated in (False, True):
        model = ShaderModel.from_experiment(
            exp, inputs, ref.image, stderr_full=ref.stderr, translated=translated
        )
        fits[translated] = calibrate_experiment(model, exp).fitted
    for name in expand_parameters(exp["fit.parameters"]):
        a, b = get_value(fits[False], name), get_value(fits[True], name)
        assert abs(a - b) <= 1e-3 * abs(a), (name, a, b)


def test_translated_model_equals_the_port_model(small):
    """``ShaderModel(translated=True)``: the fit's renders and Jacobians through SPIR-V equal
    the hand port's."""
    from study.fit.model import ShaderModel

    ref = np.zeros((small.height, small.width, 3), np.float32)
    names = ["attenuation_distance", "water_color[1]"]
    port = ShaderModel("water_refraction", small, ref)
    spirv = ShaderModel("water_refraction", small, ref, translated=True)
    c = Constants(attenuation_distance=2.0)
    assert np.array_equal(port.render(c)[0], spirv.render(c)[0])
    (r_p, J_p), (r_s, J_s) = (mod.residual_and_jacobian(c, names) for mod in (port, spirv))
    assert np.array_equal(r_p, r_s)
    assert np.abs(J_p - J_s).max() <= 1e-5 * np.abs(J_p).max()
    with pytest.raises(ValueError, match="diagnose"):
        spirv.variant.render(small, c, diagnose=True)


# ---- loops: replayed (affine state) and unrolled (anything else) for derivatives ------------

_DECAY = """#version 330 core
uniform mat4 uTextureMatrix0;
in vec4 vTexCoord0;
in vec3 varyingVecWorldPosition;
out vec4 fragColor;
uniform sampler2D normalMap;
uniform sampler2D worldYComponent;
const float DECAY = 0.8;
const float STRIDE = 0.05;
void main(void)
{
    vec2 uv = vTexCoord0.xy;
    float acc = 0.0;
    int i = 0;
    while (i < 24)
    {
        acc = acc * DECAY + texture(normalMap, uv).x;
        uv += vec2(STRIDE, 0.5 * STRIDE);
        vec2 st = (uTextureMatrix0 * vec4(varyingVecWorldPosition + vec3(uv.x, 0.0, 0.0), 1.0)).xy;
        if (texture(worldYComponent, st).r > -0.9 + 0.02 * float(i))
        {
            break;
        }
        i++;
    }
    fragColor = vec4(acc, uv, 1.0);
}
"""


def _ran(spec, inputs, shader=None):
    """An executor run with derivatives of ``spec`` (a user ``shader``'s: its start values)."""
    import drjit.llvm.ad as m

    from shaders_port.pipeline.frame import resolve_constants
    from shaders_port.pipeline.raster import prepare
    from shaders_port.spirv.execute import Executor

    P = prepare(inputs, m)
    b = dict(spirv_port.frame_bindings(m, P, inputs, spec))
    C = resolve_constants(m, Constants()) if shader is None else shader._resolved(m, {})
    if shader is not None:
        C.values.update(shader._resolved(m, shader.defaults()).values)
    import drjit as dr

    for v in C.values.values():  # every constant differentiated
        for x in v if isinstance(v, tuple) else (v,):
            if isinstance(x, dr.ArrayBase):
                dr.enable_grad(x)
    b.update(spirv_port.constant_values(spec, C))
    ex = Executor(spirv_port.module_of(spec), m, b, differentiate=True)
    ex.run()
    return ex


@pytest.mark.parametrize(
    "shader, names",
    [
        ("water_refraction", ["bumptex_mult", "steps_grazing"]),
        ("water_reflection", ["bumptex_mult", "refl_steps_grazing"]),  # with a pass's temporary
    ],
)
def test_replayed_loop_equals_unrolled_loop(small, monkeypatch, shader, names):
    from shaders_port.spirv import loops as _spirv_loops

    spec = spirv_port.builtin_spec(shader, ())
    assert not _ran(spec, small).unrolled  # the raycasts' state is affine: replayed
    out, J = spirv_port.render_with_jacobian(small, FD_CONSTANTS, names, spec=spec)
    monkeypatch.setattr(_spirv_loops.LoopRunner, "replay_plan", lambda *a: None)
    monkeypatch.setattr(spirv_port, "_NEEDS_TRIPS", {})
    key = spirv_port._key
    monkeypatch.setattr(spirv_port, "_key", lambda *a: ("unrolled",) + key(*a))
    assert _ran(spec, small).unrolled
    out_u, J_u = spirv_port.render_with_jacobian(small, FD_CONSTANTS, names, spec=spec)
    assert np.array_equal(out.numpy()["color"], out_u.numpy()["color"])
    assert np.abs(J - J_u).max() <= 1e-5 * np.abs(J).max()


def test_temporaries_of_one_pass_are_found():
    """``st`` (declared in the body, stored before it is read) is a temporary of one pass;
    ``uv`` and ``acc`` (read after the loop, carried from pass to pass) and ``i`` are not."""
    import drjit.llvm.ad as m

    from shaders_port.spirv.execute import Executor

    mod = Module(compile_fragment(_DECAY, "decay.frag"), label="decay.frag")
    ex = Executor(mod, m, {})
    (header,) = [b for b in ex.blocks.values() if b.merge and b.merge.opname == "OpLoopMerge"]
    merge = header.merge.operands[0]
    members = ex.loop_members(header.label, merge)
    assert {mod.name(v) for v in ex.written(members)} == {"acc", "uv", "st", "i"}
    assert {mod.name(v) for v in ex.pass_locals(header.label, members, merge)} == {"st"}


def test_loop_with_non_affine_state_is_unrolled_and_differentiated(small):
    from shaders_port.spirv.user_shader import UserShader

    shader = UserShader(
        _DECAY, "decay.frag", {"constants": {"DECAY": [0.1, 0.99], "STRIDE": [0.001, 0.5]}}
    )
    assert _ran(shader.spec(), small, shader).unrolled  # acc = acc * DECAY + ...: not affine
    names = ["DECAY", "STRIDE"]
    base = shader.render(small).numpy()
    out, J = shader.render_with_jacobian(small, None, names)
    assert np.array_equal(out.numpy()["color"], base["color"])
    for j, name in enumerate(names):
        x = shader.defaults()[name]
        h = 1e-3 * x
        p = shader.render(small, {name: x + h}).numpy()
        m = shader.render(small, {name: x - h}).numpy()
        same = (p["iterations"] == m["iterations"]) & (base["mask"] > 0)
        fd = (p["color"] - m["color"]) / (2 * h)
        fp, fm = (p["color"] - base["color"]) / h, (base["color"] - m["color"]) / h
        smooth = same & (np.abs(fp - fm) <= 0.2 * np.abs(fd) + 2e-6 / h).all(-1)
        assert smooth.sum() >= 0.8 * (base["mask"] > 0).sum(), name
        assert np.abs(fd[smooth]).max() > 1e-3, name
        err = np.abs(J[..., j] - fd)
        assert (err[smooth] <= 8e-6 / h + 0.1 * np.abs(fd[smooth])).all(), (name, err.max())
