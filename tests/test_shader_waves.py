"""The reference's water surface from a user's shader (``waves.source = "shader"``): the normal
its declaration names read from the executed SPIR-V, integrated (least squares) into a height
field, the curl measured; shaders written for these tests with analytic waves, so the surface
they describe is known."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import REPO
from helpers.experiments import DEFAULT, SMALL_OVERRIDES
from shaders_port.spirv.dialects import ShaderError
from study.config.errors import ExperimentError
from study.scene.shader_waves import angles_deg, integrate, probe_grid, shader_waves

# H(x, z) = A (sin(1.3 x + 0.4) + sin(0.9 z)) + B sin(0.7 x) sin(1.1 z): no symmetry in x, z
A, B = 0.08, 0.05

ANALYTIC = """#version 330 core
// @study constant AMP 0.0 1.0 0.08
// @study normal {name} {frame}
{up}
uniform float AMP;
in vec3 varyingVecWorldPosition;
out vec4 fragColor;
void main() {{
    vec3 p = {position};
    float gx = AMP * 1.3 * cos(1.3 * p.x + 0.4) + 0.05 * 0.7 * cos(0.7 * p.x) * sin(1.1 * p.z);
    float gz = AMP * 0.9 * cos(0.9 * p.z) + 0.05 * 1.1 * sin(0.7 * p.x) * cos(1.1 * p.z);
    vec3 wn = normalize(vec3(-gx, 1.0, -gz));
    vec3 {name} = {expr};
    fragColor = vec4(0.5 * wn + 0.5, 1.0);
}}
"""


def analytic_height(x, z, amp=A):
    return amp * (np.sin(1.3 * x + 0.4) + np.sin(0.9 * z)) + B * np.sin(0.7 * x) * np.sin(1.1 * z)


Y_UP = "varyingVecWorldPosition"
Z_UP = "vec3(varyingVecWorldPosition.x, varyingVecWorldPosition.z, -varyingVecWorldPosition.y)"


def _experiment(tmp_path, frame="world", expr="wn", up="", name="nrm", *sets):
    path = tmp_path / "analytic.frag"
    position = Z_UP if up else Y_UP  # the study's (x, y, z) of a Z-up world's position
    path.write_text(ANALYTIC.format(name=name, frame=frame, expr=expr, up=up, position=position))
    from study import load_experiment

    over = SMALL_OVERRIDES + [f"fit.shader={path}", "waves.source=shader",
                              "waves.shader_grid=160", *sets]  # fmt: skip
    return load_experiment(DEFAULT, over)


def _grid(exp):
    hx, hz = exp.pool.half_extent
    nx, nz = probe_grid(exp)
    x = -hx + (np.arange(nx) + 0.5) * 2 * hx / nx
    z = -hz + (np.arange(nz) + 0.5) * 2 * hz / nz
    return np.meshgrid(x, z)


# ---- the least-squares integration ----------------------------------------------------------


def test_integration_recovers_a_surface_from_its_slopes():
    nz, nx, dx, dz = 90, 120, 0.05, 0.07
    x, z = np.meshgrid(np.arange(nx) * dx, np.arange(nz) * dz)
    h = analytic_height(x, z)
    gx = A * 1.3 * np.cos(1.3 * x + 0.4) + B * 0.7 * np.cos(0.7 * x) * np.sin(1.1 * z)
    gz = A * 0.9 * np.cos(0.9 * z) + B * 1.1 * np.sin(0.7 * x) * np.cos(1.1 * z)
    got = integrate(gx, gz, dx, dz)
    err = np.abs(got - (h - h.mean())).max()
    assert err < 2e-4 * np.ptp(h), err  # the trapezoid rule's error, O(dx^2)
    assert abs(got.mean()) < 1e-12


def test_integration_of_a_rotation_is_flat_and_its_curl_is_measured():
    """A field with no potential part, the rotation of the stream function
    ``0.2 sin(pi x) sin(pi z)`` on [0, 1]^2 (no divergence, no flux through the edges): the
    least-squares surface is flat, and the field's normals differ from it."""
    c = (np.arange(64) + 0.5) / 64
    x, z = np.meshgrid(c, c)
    gx = 0.2 * np.pi * np.sin(np.pi * x) * np.cos(np.pi * z)
    gz = -0.2 * np.pi * np.cos(np.pi * x) * np.sin(np.pi * z)
    h = integrate(gx, gz, 1 / 64, 1 / 64)
    assert np.abs(h).max() < 1e-3 * 0.2 * np.pi, np.abs(h).max()
    n = np.stack([-gx, np.ones_like(x), -gz], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    flat = np.broadcast_to([0.0, 1.0, 0.0], n.shape)
    assert angles_deg(n, flat).mean() > 10.0


# ---- the shader's normals -----------------------------------------------------------------


@pytest.mark.parametrize(
    "frame, expr, up",
    [
        ("world", "wn", ""),
        ("tangent", "wn.xzy", ""),  # tangent frame: x along u (world x), y along v (world z)
        ("world", "vec3(wn.x, -wn.z, wn.y)", "// @study up z"),  # a Z-up world's normal
    ],
    ids=["world", "tangent", "z-up"],
)
def test_the_shaders_surface_is_the_one_its_normals_describe(tmp_path, frame, expr, up):
    exp = _experiment(tmp_path, frame, expr, up)
    s = shader_waves(exp)
    x, z = _grid(exp)
    want = analytic_height(x, z)
    want -= want.mean()
    err = np.abs(s.h - want).max()
    assert err < 2e-3 * np.ptp(want), (err, np.ptp(want))
    got_h, got_gx, _ = s.height_and_gradient(x, z)
    np.testing.assert_allclose(got_h, s.h, atol=1e-12)  # at the grid's points, its own values
    gx = A * 1.3 * np.cos(1.3 * x + 0.4) + B * 0.7 * np.cos(0.7 * x) * np.sin(1.1 * z)
    inner = (slice(2, -2), slice(2, -2))
    assert np.abs(got_gx - gx)[inner].max() < 0.02 * np.abs(gx).max()
    assert s.stats["curl_mean_deg"] < 0.05, s.stats  # a gradient field: no curl
    assert s.stats["normal"] == ["nrm", frame]


def test_a_vertex_shader_that_displaces_the_surface_displaces_the_reference(tmp_path):
    """A pair whose vertex shader lifts the grid by H = 0.35 sin(2.1 x + 0.4) cos(1.7 z) and
    hands its normal on: the reference's surface is H, read where the displaced surface is
    drawn."""
    from study import load_experiment

    shaders = REPO / "tests" / "shaders"
    (tmp_path / "displaced_water.vert").write_text((shaders / "displaced_water.vert").read_text())
    frag = (shaders / "displaced_water.frag").read_text()
    frag = frag.replace("const float BUMP = 0.5;", "const float BUMP = 0.0;")
    (tmp_path / "displaced_water.frag").write_text(frag + "// @study normal n\n")
    exp = load_experiment(DEFAULT, SMALL_OVERRIDES + [
        f"fit.shader={tmp_path / 'displaced_water.frag'}", "fit.vertex=auto",
        "waves.source=shader", "waves.shader_grid=160"])  # fmt: skip
    s = shader_waves(exp)
    x, z = _grid(exp)
    want = 0.35 * np.sin(2.1 * x + 0.4) * np.cos(1.7 * z)
    want -= want.mean()
    err = np.abs(s.h - want).max()
    assert err < 0.02 * np.ptp(want), (err, np.ptp(want))
    assert s.stats["curl_mean_deg"] < 0.5, s.stats  # the grid's interpolated normals: nearly none


def test_the_height_scale_scales_heights_and_slopes(tmp_path):
    one = shader_waves(_experiment(tmp_path))
    more = shader_waves(_experiment(tmp_path, "world", "wn", "", "nrm", "waves.height_scale=1.3"))
    np.testing.assert_allclose(more.h, 1.3 * one.h, rtol=1e-12, atol=1e-15)
    assert more.stats["slope_rms"] == pytest.approx(1.3 * one.stats["slope_rms"], rel=1e-9)
    assert more.stats["curl_mean_deg"] == one.stats["curl_mean_deg"]


def test_a_normal_field_with_curl_is_measured(tmp_path):
    """A normal tilted by a rotation field on top of the waves: no surface has it; the angle
    between the shader's normals and the integrated surface's says by how much."""
    exp = _experiment(tmp_path, "world", "normalize(wn + vec3(0.1 * p.z, 0.0, -0.1 * p.x))")
    s = shader_waves(exp)
    assert s.stats["curl_mean_deg"] > 3.0, s.stats


def test_the_cache_key_follows_the_shader(tmp_path):
    """The reference of a shader's waves is cached under what makes them: the same file in
    another folder is the same scene; a changed start value or another normal variable is a new
    one; the study's waves keep their keys."""
    from study import load_experiment

    a = _experiment(tmp_path)
    (tmp_path / "moved").mkdir()
    assert _experiment(tmp_path / "moved").scene_hash() == a.scene_hash()
    b = _experiment(tmp_path, "world", "wn", "", "nrm2")
    path = tmp_path / "analytic.frag"
    path.write_text(path.read_text().replace("1.0 0.08", "1.0 0.09"))
    c = load_experiment(DEFAULT, SMALL_OVERRIDES + [f"fit.shader={path}", "waves.source=shader",
                                                    "waves.shader_grid=160"])  # fmt: skip
    assert len({a.scene_hash(), b.scene_hash(), c.scene_hash()}) == 3
    study = load_experiment(DEFAULT, SMALL_OVERRIDES)
    same = load_experiment(DEFAULT, SMALL_OVERRIDES + ["waves.source=study", "waves.time=0"])
    assert study.scene_hash() == same.scene_hash()


def test_errors_name_the_problem(tmp_path):
    from study import load_experiment

    with pytest.raises(ShaderError, match="not a variable of main"):
        shader_waves(_broken(tmp_path, "// @study normal nowhere"))
    with pytest.raises(ExperimentError, match="// @study normal NAME"):
        _broken(tmp_path, "")
    with pytest.raises(ExperimentError, match="own fit.shader"):
        load_experiment(DEFAULT, SMALL_OVERRIDES + ["waves.source=shader"])
    with pytest.raises(ShaderError, match="points down"):
        shader_waves(_experiment(tmp_path, "world", "-wn"))


def _broken(tmp_path, pragma):
    text = ANALYTIC.format(name="nrm", frame="world", expr="wn", up="", position=Y_UP)
    path = tmp_path / "broken.frag"
    path.write_text(text.replace("// @study normal nrm world", pragma))
    from study import load_experiment

    return load_experiment(DEFAULT, SMALL_OVERRIDES + [f"fit.shader={path}", "waves.source=shader",
                                                       "waves.shader_grid=64"])  # fmt: skip


@pytest.mark.slow  # about 50 s on 2 cores, nearly all the executor's compile of the shader
def test_an_engine_shader_names_its_normal():
    """The shipped three.js-style water declares its normal; its field's curl is measured."""
    from study import load_experiment

    exp = load_experiment(REPO / "experiments" / "webgl_mirror_water.toml",
                          ["waves.source=shader", "waves.shader_grid=96"])  # fmt: skip
    s = shader_waves(exp)
    assert s.stats["normal"] == ["n", "world"] and s.stats["grid"] == [96, 96]
    assert 0.0 < s.stats["curl_mean_deg"] < 20.0 and s.stats["slope_rms"] > 0.05


SHADED = """#version 330 core
// @study constant AMP 0.0 1.0 0.08
// @study constant DISTORT 0.0 0.5 0.1
// @study constant TINT 0.0 1.0 0.5,0.5,0.5
// @study constant F0 0.0 0.2 0.02
// @study normal wn
uniform float AMP;
uniform float DISTORT;
uniform vec3 TINT;
uniform float F0;
uniform mat4 uTextureMatrix0;
uniform sampler2D refractionTexture;
uniform samplerCube reflectionTexture;
in vec3 varyingVecWorldPosition;
in vec3 varyingVecEye;
out vec4 fragColor;
void main() {
    vec3 p = varyingVecWorldPosition;
    float gx = AMP * 1.3 * cos(1.3 * p.x + 0.4);
    float gz = AMP * 0.9 * cos(0.9 * p.z);
    vec3 wn = normalize(vec3(-gx, 1.0, -gz));
    vec3 e = normalize(varyingVecEye);
    vec2 st = (uTextureMatrix0 * vec4(p, 1.0)).xy + DISTORT * wn.xz;
    vec3 ground = TINT * texture(refractionTexture, st).rgb;
    vec3 sky = texture(reflectionTexture, reflect(-e, wn) * vec3(1.0, -1.0, 1.0)).rgb;
    float f = F0 + (1.0 - F0) * pow(1.0 - clamp(dot(wn, e), 0.0, 1.0), 5.0);
    fragColor = vec4(mix(ground, sky, f), 1.0);
}
"""


def test_constants_recovered_on_inputs_lit_through_the_shaders_surface(tmp_path, mi):
    """Parameter recovery on a synthetic target: a shader of analytic waves with a distorted
    refraction, a tint and a Fresnel sky, its inputs built through its own surface (the floor
    lit through it, small sizes), its own image at known constants as the target, plus Gaussian
    noise (sigma 0.01, seeded): every constant is recovered from the clean target, and lands
    within two standard errors of the truth from the noisy one."""
    from study import load_experiment
    from study.config.user_shader import load_user_shader
    from study.fit.calibrate import calibrate_model
    from study.fit.model import get_value
    from study.fit.spirv_model import SpirvModel
    from study.scene.shader_inputs import load_or_build_shader_inputs

    (tmp_path / "shaded.frag").write_text(SHADED)
    exp = load_experiment(DEFAULT, SMALL_OVERRIDES + [
        f"fit.shader={tmp_path / 'shaded.frag'}", "waves.source=shader", "waves.shader_grid=128",
        "resolution=[48, 40]", "fit.resolution=[48, 40]"])  # fmt: skip
    inputs = load_or_build_shader_inputs(exp, "llvm_ad_rgb", cache=tmp_path, log=lambda *a: None)
    assert shader_waves(exp).stats["normal"] == ["wn", "world"]
    shader = load_user_shader(exp.values)
    truth = {"AMP": 0.11, "DISTORT": 0.2, "TINT": (0.7, 0.8, 0.9), "F0": 0.04}
    clean = shader.render(inputs, truth).numpy()["color"]
    noise = np.random.default_rng(7).normal(0.0, 0.01, clean.shape).astype(np.float32)
    for target, exact in ((clean, True), (clean + noise, False)):
        model = SpirvModel(shader, inputs, target)
        cal = calibrate_model(model, model.start_constants(), sorted(truth),
                              "levenberg_marquardt", 40)  # fmt: skip
        for name, p in cal.parameters.items():
            base, _, idx = name.partition("[")
            want = truth[base][int(idx[:-1])] if idx else truth[base]
            got = get_value(cal.fitted, name)
            assert p["status"] == "fitted", (name, p)
            if exact:
                assert abs(got - want) <= 1e-4 * abs(want), (name, got, want, cal.fit_summary)
            else:
                se = p["rel_std_error"] * abs(got)
                assert abs(got - want) <= 2 * se, (name, got, want, se)


@pytest.mark.slow
def test_normal_strength_recovers_a_known_factor_on_the_waves(tmp_path):
    """Against path-traced references of the Z-up engine water's own waves, as they are and 1.3
    times as steep (``waves.height_scale``): its ``bumpscale`` (a factor on its normals'
    slopes) fitted against the steeper one, divided by the one fitted against its own, is 1.3
    within 2 % (two calibrations of experiments/zup_water.toml, minutes)."""
    import json
    import subprocess
    import sys

    from helpers.experiments import sets

    fitted = []
    for scale in (1.0, 1.3):
        out = tmp_path / f"x{scale}"
        # the experiment as it ships (256x256, fit at 128x128): at 128x128 (fit at 64x64) the
        # ratio was measured at 1.10, the waves' glints too few pixels to pin bumpscale
        over = ["waves.source=shader", f"waves.height_scale={scale}"]
        exp = str(REPO / "experiments" / "zup_water.toml")
        args = [sys.executable, "-m", "study.cli", "calibrate", exp, "--out", str(out)]
        run = subprocess.run(
            args + sets(over), capture_output=True, text=True, timeout=1800, cwd=tmp_path
        )
        assert run.returncode == 0, run.stderr[-3000:]
        p = json.loads((out / "constants.json").read_text())["parameters"]["bumpscale"]
        assert p["status"] == "fitted", p
        fitted.append(p["fitted"])
    ratio = fitted[1] / fitted[0]
    assert abs(ratio / 1.3 - 1.0) <= 0.02, (fitted, ratio)
