"""Engine pairs declared from outside: two engine-style pairs written for these tests
(``tests/shaders/declared/split_matrices_water.*``, GLSL 1.20 with the model, view and projection
matrices apart and a mirror texture matrix; ``tests/shaders/declared/es_cube_water.*``, GLSL ES 3.00
with a sky cube map), whose files carry no pragma and whose vertex shaders use names no table
of the study holds. Everything is declared in ``fit.declare``: a ``bind`` of a name only the
vertex shader reads binds there; a matrix is given as a ``value``; both files stay byte for
byte as written through a calibration."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from helpers import REPO
from helpers.experiments import DEFAULT, TINY, replaced, sets
from helpers.gl import assert_ran_as_written
from helpers.synthetic import synthetic_baseline_inputs
from study import load_experiment
from study.cli import main
from study.config.errors import ExperimentError
from study.config.user_shader import load_user_shader

SHADERS = REPO / "tests" / "shaders" / "declared"  # no pragma: every line in fit.declare
SPLIT = [
    "constant rippleStrength 0.0 2.0", "constant mirrorDistortion 0.0 0.1",
    "constant glossPower 10 2000", "constant glossStrength 0.0 5.0",
    "bind uMirrorMap reflection_sampler", "bind uRippleMap normalMap",
    "bind uSunDir sun_direction", "bind uModel model", "bind uView view",
    "bind uProjection projection", "bind uMirrorTexMatrix reflection_texture_matrix",
    "bind uEye cameraPosition", "bind uRipple0 wave1", "bind uRipple1 wave3",
    "value uRippleTiling 0.5", "bind inPosition position", "bind inTexCoord uv",
]  # fmt: skip
CUBE = [
    "constant waveScale 0.0 2.0", "constant f0 0.0 0.2", "bind u_waves normalMap",
    "bind u_sky sky_cube", "bind u_objectToWorld model", "bind u_worldToClip viewProjection",
    "bind u_eyeWorld cameraPosition", "bind u_flowA wave2", "bind u_flowB wave4",
    "bind a_pos position", "bind a_uv uv",
]  # fmt: skip
PAIRS = {"split_matrices_water": SPLIT, "es_cube_water": CUBE}
IDENTITY = ",".join(str(float(i == j)) for j in range(4) for i in range(4))


def _overrides(name: str, declare: list[str]) -> list[str]:
    return [
        f'fit.shader="{SHADERS / (name + ".frag")}"',
        f'fit.vertex="{SHADERS / (name + ".vert")}"',
        f"fit.declare={json.dumps(declare)}",
        "fit.vertex_grid=[24, 24]",
    ]


def _shader(name: str, declare: list[str]):
    return load_user_shader(load_experiment(DEFAULT, _overrides(name, declare)).values)


def _digests() -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest()
            for name in PAIRS for p in SHADERS.glob(f"{name}.*")}  # fmt: skip


@pytest.fixture(scope="module")
def inputs():
    return synthetic_baseline_inputs(64, 48)


@pytest.mark.parametrize("name", sorted(PAIRS))
def test_a_pair_declared_from_outside_runs_as_written(name, inputs):
    """Each stage takes the bindings of the names it reads; the executor's render matches the
    pair as written on llvmpipe (GLSL 1.20 on the compatibility profile, GLSL ES 3.00 on
    OpenGL ES)."""
    from study.export.gl_check import gl_check_user

    before = _digests()
    shader = _shader(name, PAIRS[name])
    declared = dict(line.split()[1:] for line in PAIRS[name] if line.startswith("bind"))
    vertex = shader.vertex.shader
    assert set(shader.bindings) | set(vertex.declared) == set(declared)
    for n, target in declared.items():
        stage = shader.bindings if n in shader.bindings else vertex.bindings
        assert stage[n] == target
    assert not set(shader.bindings) & set(vertex.declared)
    assert {"u_objectToWorld", "uModel"} & set(vertex.declared)
    ours = shader.render(inputs).numpy()
    mine = ours["mask"] > 0.5
    assert mine.sum() > 800 and np.isfinite(ours["color"][mine]).all()
    assert ours["color"][mine].std() > 0.01
    check = gl_check_user(shader, inputs, shader.defaults(), ours)
    assert check["ran"] and check["passed"], check
    assert_ran_as_written(check, "es" if shader.dialect.es else "compatibility")
    assert _digests() == before


def test_a_matrix_value_and_bad_declarations(inputs):
    """A ``value`` of a mat4 (16 numbers, column after column): the identity for the model
    matrix draws what ``model`` draws; a translation moves the water; an attribute takes no
    value and a name no stage reads takes no binding, each refused in one line at load."""
    no_model = [line for line in SPLIT if not line.startswith("bind uModel")]
    bound = _shader("split_matrices_water", SPLIT).render(inputs).numpy()
    same = _shader("split_matrices_water", [*no_model, f"value uModel {IDENTITY}"])
    ident = same.render(inputs).numpy()
    assert np.array_equal(ident["mask"], bound["mask"])
    assert np.abs(ident["color"] - bound["color"]).max() < 1e-6
    lifted = "1,0,0,0,0,1,0,0,0,0,1,0,0.4,0,0,1"  # x + 0.4: the last column
    moved = _shader("split_matrices_water", [*no_model, f"value uModel {lifted}"])
    out = moved.render(inputs).numpy()
    assert (out["mask"] != bound["mask"]).sum() > 20
    with pytest.raises(ExperimentError, match="uModel.*16 numbers column after column"):
        _shader("split_matrices_water", [*no_model, "value uModel 1,0,0,1"])
    no_uv = [line for line in SPLIT if not line.startswith("bind inTexCoord")]
    with pytest.raises(ExperimentError, match="inTexCoord is a vertex attribute"):
        _shader("split_matrices_water", [*no_uv, "value inTexCoord 0.5,0.5"])
    with pytest.raises(ExperimentError, match="neither this shader nor its vertex shader"):
        _shader("split_matrices_water", [*SPLIT, "bind uNothing model"])


@pytest.mark.slow  # a calibration of a user's pair (~40 s)
def test_a_declared_pair_calibrates_with_its_files_unchanged(tmp_path, monkeypatch):
    monkeypatch.setenv("STUDY_CACHE", str(tmp_path / "cache"))
    before = _digests()
    out = tmp_path / "out"
    overrides = replaced(TINY, "fit.max_steps=5") + _overrides("split_matrices_water", SPLIT)
    assert main(["calibrate", str(DEFAULT), "--out", str(out)] + sets(overrides)) == 0
    assert _digests() == before
    summary = json.loads((out / "constants.json").read_text())
    assert summary["shader"] == "split_matrices_water.frag"
    check = summary["gl_check"]
    assert check["passed"] is True and check["text"] == "your file as written", check
    assert "compatibility" in check["context"]
    assert summary["engine_targets"]["gles300"]["llvmpipe"]["passed"] is True


def test_a_declared_normal_map_is_relative_to_the_experiment_file(tmp_path, monkeypatch):
    """``normal_map FILE`` in fit.declare names a file beside the experiment file, also when
    the line comes from ``--set`` and the working directory is elsewhere."""
    monkeypatch.chdir(tmp_path)
    line = "normal_map files/water_normals.png"
    exp = load_experiment(REPO / "experiments" / "my_water.toml", [f'fit.declare=["{line}"]'])
    assert exp["fit.declare"] == [
        f"normal_map {REPO / 'experiments' / 'files' / 'water_normals.png'}"
    ]


def _plain_webgl1_pair(tmp_path):
    """The shipped WebGL 1 pair with its vertex file's ``precision`` line removed."""
    text = (REPO / "experiments/shaders/webgl_mirror_water.vert").read_text()
    plain = tmp_path / "plain.vert"
    plain.write_text(text.replace("precision highp float;\n", ""))
    assert "precision" not in plain.read_text() and "#version" not in plain.read_text()
    exp = load_experiment(REPO / "experiments/webgl_mirror_water.toml",
                          [f'fit.vertex="{plain}"', "fit.vertex_grid=[24, 24]"])  # fmt: skip
    return load_user_shader(exp.values)


def test_a_vertex_file_without_a_dialect_marker_takes_its_fragment_shaders(tmp_path):
    """A WebGL 1 vertex shader as three.js holds it declares no ``#version`` and no
    ``precision``: the pair is read as its fragment shader's GLSL ES 1.00, not as GLSL 1.10."""
    shader = _plain_webgl1_pair(tmp_path)
    assert shader.dialect.es and shader.vertex.shader.defines == ("#version 100",)
    assert shader.vertex.shader.original == (tmp_path / "plain.vert").read_text()  # as held


@pytest.mark.slow  # the WebGL 1 pair's executor (~30 s)
def test_a_vertex_file_without_a_marker_runs_as_written(tmp_path, inputs):
    """That pair's GL check runs both files as written on OpenGL ES."""
    from study.export.gl_check import gl_check_user

    shader = _plain_webgl1_pair(tmp_path)
    check = gl_check_user(shader, inputs, shader.defaults(), shader.render(inputs).numpy())
    assert check["ran"] and check["passed"], check
    assert_ran_as_written(check, "es")


def test_the_short_sheet_names_what_each_of_the_users_names_is(tmp_path):
    """The engine values the declaration gives (``value uRippleTiling 0.5``) and the meaning of
    each bound name, in either stage, are on the short sheet."""
    from study.export.shaders import export_user_shader

    shader = _shader("split_matrices_water", SPLIT)
    export_user_shader(shader, shader.defaults(), tmp_path / "shaders", targets=["gles300"])
    sheet = (tmp_path / "shaders" / "gles300" / "BINDINGS.md").read_text()
    rows = {r.split("|")[1].strip(" `"): r.split("|")[5].strip() for r in sheet.splitlines()
            if r.startswith("| `")}  # fmt: skip
    assert rows["uRippleTiling"] == "engine value: set it to 0.5"
    assert rows["uModel"].startswith("bound to `model`: model -> world")
    assert rows["uMirrorMap"].startswith("bound to `reflection_sampler`: ")
    assert rows["inTexCoord"].startswith("bound to `uv`: texture coordinate")
    assert all(rows[n] for n in ("uEye", "uRipple0", "uSunDir", "uView", "uProjection"))


def test_an_initialized_uniform_not_fitted_reaches_every_target_as_a_value(tmp_path, inputs):
    """``uniform float Shininess = 800.0;`` in a GLSL 330 file, not a constant to fit: a value
    the engine sets (the initializer's), so the GLSL ES target (which refuses an initializer)
    is written, the initializer moved to the sheet; the file itself runs as written."""
    from shaders_port.spirv.user_shader import UserShader
    from study.export.gl_check import gl_check_user
    from study.export.shaders import export_user_shader

    path = SHADERS / "initialized_uniforms.frag"
    shader = UserShader.from_file(path).check()
    assert shader.initialized == {"Shininess": (800.0,), "Tint": (0.1, 0.2, 0.3)}
    assert shader.written(shader.defaults()) == path.read_text()  # the file as the engine holds it
    folder = tmp_path / "shaders"
    export_user_shader(shader, shader.defaults(), folder, targets=["gles300", "hlsl"])
    es = (folder / "gles300" / "initialized_uniforms.frag").read_text()
    assert "uniform highp float Shininess;" in es and "800" not in es
    sheet = (folder / "gles300" / "BINDINGS.md").read_text()
    assert "| `Shininess` | uniform | float | by name | engine value: set it to 800.0 |" in sheet
    ours = shader.render(inputs).numpy()
    check = gl_check_user(shader, inputs, shader.defaults(), ours)
    assert check["passed"] and check["text"] == "your file as written", check
