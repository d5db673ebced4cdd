"""A user's own GLSL shader calibrated from its file: two shaders written for these tests
(``tests/shaders/``: Schlick-Fresnel water with two normal layers and exponential fog; a
parallax-occlusion water with its own search loop), declared by ``// @study`` pragmas, executed
through SPIR-V, differentiated (checked by central differences), fitted to synthetic targets
(parameter recovery), written back into the file and checked on llvmpipe."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from helpers.experiments import TINY as CLI_TINY
from helpers.gl import user_gl_render_or_skip
from helpers.images import save_comparison
from helpers.port_checks import FD_NOISE, FD_RTOL
from helpers.synthetic import synthetic_inputs
from shaders_port.spirv.translated import STUDY_INPUTS
from shaders_port.spirv.user_shader import UserShader
from study.fit.calibrate import calibrate_model
from study.fit.model import get_value
from study.fit.spirv_model import SpirvModel

SHADERS = Path(__file__).parent / "shaders"
TRUTH = {
    "schlick_fog": {"FOG_DENSITY": 0.8, "FOG_COLOR": (0.1, 0.3, 0.2), "BUMP": 1.4},
    "parallax_water": {"ABSORPTION": (0.5, 0.2, 0.05), "BUMP": 0.7},
}


@pytest.fixture(scope="module")
def inputs():
    return synthetic_inputs(width=48, height=36)


def _shader(name: str) -> UserShader:
    return UserShader.from_file(SHADERS / f"{name}.frag")


def _calibrate(shader: UserShader, inputs, target: np.ndarray, constants: list[str]):
    """The study's one calibration (``calibrate_model``) of ``shader``'s ``constants`` against
    ``target`` on its coverage: (Calibration, RMSE at the start, RMSE fitted)."""
    model = SpirvModel(shader, inputs, target)
    start = model.start_constants()
    cal = calibrate_model(model, start, constants, "levenberg_marquardt", 30)
    r0, r1 = model.residual(start), model.residual(cal.fitted)
    return cal, float(np.sqrt(np.mean(r0**2))), float(np.sqrt(np.mean(r1**2)))


@pytest.mark.parametrize("name", sorted(TRUTH))
def test_calibrates_written_back_and_gl_checked(name, inputs, tmp_path):
    shader = _shader(name)
    truth = shader.with_scalars(shader.defaults(), {})
    truth.update(TRUTH[name])
    target = shader.render(inputs, truth).numpy()["color"]
    names = [s for s in shader.scalar_names() if s.split("[")[0] in TRUTH[name]]
    cal, rmse_start, rmse = _calibrate(shader, inputs, target, sorted(TRUTH[name]))
    assert sorted(cal.parameters) == sorted(names)
    assert rmse_start > 1e-3 and rmse < 1e-5, (rmse_start, rmse, cal.fit_summary["message"])
    want = shader.with_scalars(truth, {})
    for s in names:
        base, _, idx = s.partition("[")
        t = want[base][int(idx[:-1])] if idx else want[base]
        got = get_value(cal.fitted, s)
        assert abs(got - t) <= 1e-3 * abs(t), (s, got, t)
    # written back: the constants replaced, every other byte the same; the file compiles and
    # runs on llvmpipe like the executor
    text = shader.written(cal.fitted)
    src = shader.source
    for c in sorted(shader.constants.values(), key=lambda c: -c.span[0]):
        src = src[: c.span[0]] + "@" + src[c.span[1] :]
        text_parts = text
    assert text_parts.count("\n") == shader.source.count("\n")
    out_file = tmp_path / f"{name}.frag"
    out_file.write_text(text)
    again = UserShader.from_file(out_file)
    for s in names:
        v = get_value(cal.fitted, s)
        base, _, idx = s.partition("[")
        got = again.defaults()[base]
        got = got[int(idx[:-1])] if idx else got
        assert got == np.float32(v), s
    strip = [ln for ln in text.split("\n") if not any(f" {n} =" in ln for n in shader.constants)]
    orig = [
        ln for ln in shader.source.split("\n") if not any(f" {n} =" in ln for n in shader.constants)
    ]
    assert strip == orig
    rgba, mask = user_gl_render_or_skip(again, inputs)
    ours = again.render(inputs).numpy()
    both = mask & (ours["mask"] > 0)
    d = np.abs(rgba[..., :3] - ours["color"]).max(-1)[both]
    if not (d.mean() <= 1e-3 and np.percentile(d, 99.9) <= 1e-2):
        save_comparison(f"user_gl_{name}", ours["color"], rgba[..., :3])
    assert both.sum() > 500 and d.mean() <= 1e-3 and np.percentile(d, 99.9) <= 1e-2


@pytest.mark.parametrize("name", sorted(TRUTH))
def test_jacobian_matches_central_differences(name, inputs):
    shader = _shader(name)
    names = shader.scalar_names()
    base = shader.render(inputs).numpy()
    out, J = shader.render_with_jacobian(inputs, None, names)
    assert np.array_equal(out.numpy()["color"], base["color"])
    for j, s in enumerate(names):
        if s == "STEP_LENGTH":  # moves the search's crossing step: checked where it does not
            continue
        v = shader.with_scalars(shader.defaults(), {})
        b, _, idx = s.partition("[")
        x = v[b][int(idx[:-1])] if idx else v[b]
        h = 1e-3 * max(abs(x), 1.0)
        p = shader.render(inputs, shader.with_scalars(v, {s: x + h})).numpy()
        m = shader.render(inputs, shader.with_scalars(v, {s: x - h})).numpy()
        same = (p["iterations"] == m["iterations"]) & (base["iterations"] == p["iterations"])
        fd = (p["color"] - m["color"]) / (2 * h)
        fp, fm = (p["color"] - base["color"]) / h, (base["color"] - m["color"]) / h
        noise = FD_NOISE / h
        # pixels without a jump in the stencil (a floor texel edge under the crossing)
        smooth = (
            same & (base["mask"] > 0) & (np.abs(fp - fm) <= 0.2 * np.abs(fd) + 2 * noise).all(-1)
        )
        assert smooth.sum() >= 0.8 * (base["mask"] > 0).sum(), s
        assert np.abs(fd[smooth]).max() > 10 * noise, s
        bad = smooth & ~(np.abs(J[..., j] - fd) <= 2 * noise + FD_RTOL * np.abs(fd)).all(-1)
        assert not bad.any(), (s, int(bad.sum()))


def test_confounded_constant_is_frozen_and_the_rest_recovered(inputs):
    """Two constants that only act as a product (``exp(-FOG_DENSITY * FOG_SCALE * t)``): the
    identifiability analysis holds one at its start value, the other takes up the product."""
    src = (SHADERS / "schlick_fog.frag").read_text()
    src = src.replace("const float F0", "const float FOG_SCALE = 1.0;\nconst float F0")
    src = src.replace("exp(-FOG_DENSITY * t)", "exp(-FOG_DENSITY * FOG_SCALE * t)")
    src = src.replace(
        "// @study constant BUMP", "// @study constant FOG_SCALE 0.25 4.0\n// @study constant BUMP"
    )
    shader = UserShader(src, "confounded.frag")
    target = shader.render(inputs, {"FOG_DENSITY": 0.8}).numpy()["color"]
    cal, _, rmse = _calibrate(shader, inputs, target, ["FOG_DENSITY", "FOG_SCALE", "BUMP"])
    p = cal.parameters
    frozen = [n for n in ("FOG_DENSITY", "FOG_SCALE") if p[n]["status"] == "frozen"]
    assert len(frozen) == 1 and "null space" in p[frozen[0]]["reason"], p
    assert get_value(cal.fitted, frozen[0]) == p[frozen[0]]["default"]
    product = get_value(cal.fitted, "FOG_DENSITY") * get_value(cal.fitted, "FOG_SCALE")
    assert abs(product - 0.8) <= 1e-3 * 0.8 and rmse < 1e-5, (product, rmse)
    assert p["BUMP"]["status"] == "fitted" and p["BUMP"]["rel_std_error"] is not None


def test_declaration_errors_name_the_problem(tmp_path):
    src = (SHADERS / "schlick_fog.frag").read_text()
    with pytest.raises(ValueError, match="FOG_DENSITY = 0.35 lies outside"):
        UserShader(src, "a.frag", {"constants": {"FOG_DENSITY": [1.0, 2.0]}})
    with pytest.raises(ValueError, match="NOPE to fit has no one-line declaration"):
        UserShader(src, "a.frag", {"constants": {"NOPE": [0.0, 1.0]}})
    with pytest.raises(ValueError, match="names no study input"):
        UserShader(src, "a.frag", {"bindings": {"waveNormals": "normal_mapp"}})
    with pytest.raises(ValueError, match="unknown pragma"):
        UserShader(src.replace("@study bind", "@study bnd"), "a.frag")
    with pytest.raises(ValueError, match="no file"):
        UserShader.from_file(tmp_path / "missing.frag")
    assert "normalMap" in STUDY_INPUTS


def test_unbound_sampler_is_refused_at_render(inputs):
    src = (
        (SHADERS / "schlick_fog.frag")
        .read_text()
        .replace("// @study bind waveNormals normalMap\n", "")
    )
    with pytest.raises(ValueError, match="'waveNormals'.*bind it"):
        UserShader(src, "a.frag").render(inputs)


# ---- fit.shader = a user's file: experiment validation and `study calibrate` --------------

TINY = CLI_TINY + ["reference.lighting_size=32", "reference.wall_spp=8", "fit.max_steps=5"]
MY_WATER = Path(__file__).parent.parent / "experiments" / "my_water.toml"


def test_experiment_refuses_a_bad_user_declaration(tmp_path):
    from study import load_experiment
    from study.config.errors import ExperimentError

    with pytest.raises(ExperimentError, match="fit.declare.*constant NAME LOW HIGH"):
        load_experiment(MY_WATER, ['fit.declare=["constant F0 0.0"]'])
    with pytest.raises(ExperimentError) as err:
        load_experiment(MY_WATER, [f'fit.shader="{tmp_path / "none.frag"}"'])
    assert str(err.value) == f"fit.shader: no file {str(tmp_path / 'none.frag')!r}"
    with pytest.raises(ExperimentError, match="names no study input"):
        load_experiment(MY_WATER, ['fit.declare=["bind waveNormals normal_map"]'])
    exp = load_experiment(MY_WATER)
    assert Path(exp["fit.shader"]).is_file() and exp["fit.parameters"] is None
    # fit.parameters names the study's constants (a shipped experiment's list): a user's
    # shader fits those of its declaration
    assert load_experiment(MY_WATER, ['fit.parameters=["bumptex_mult"]'])["fit.parameters"] is None


@pytest.fixture(scope="module")
def user_run(tmp_path_factory):
    """``study calibrate experiments/my_water.toml`` on a copy of its shader, with
    ``fit.write_back = "file"``: (output folder, the copy, its text before)."""
    import shutil

    from study.cli import main

    root = tmp_path_factory.mktemp("user")
    mine = root / "my_water.frag"
    shutil.copy(MY_WATER.parent / "shaders" / "my_water.frag", mine)
    before = mine.read_text()
    sets = [a for kv in TINY for a in ("--set", kv)]
    sets += ["--set", f'fit.shader="{mine}"', "--set", 'fit.write_back="file"']
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("STUDY_CACHE", str(root / "cache"))
        assert main(["calibrate", str(MY_WATER), "--out", str(root / "c")] + sets) == 0
    return root / "c", mine, before


def test_study_calibrate_fits_and_gl_checks(user_run):
    import json

    out, mine, _ = user_run
    res = json.loads((out / "constants.json").read_text())
    # the layout of every calibration: start and fitted errors, statuses, diagnostics
    for metric in ("rmse", "flip"):
        assert res["error"][metric]["fitted"] < res["error"][metric]["default"], res["error"]
    assert {p["status"] for p in res["parameters"].values()} <= {"fitted", "bound", "frozen"}
    assert res["shader"] == "my_water.frag" and res["shader_file"] == str(mine)
    d = res["diagnostics"]
    assert d["fetches"]["mean"] == 5.0 and d["iterations"]["mean"] == 0.0
    if res["gl_check"]["ran"]:
        assert res["gl_check"]["passed"], res["gl_check"]
    # the engine targets, translated from the written file and checked as the study's shaders'
    from study.export.targets import resolve_targets

    targets = res["engine_targets"]
    assert set(targets) == set(resolve_targets(None)) and targets, targets
    for target, t in targets.items():
        assert t["files"] and all((out / "shaders" / f).is_file() for f in t["files"]), target
    # the HLSL back through glslang and SPIRV-Cross, run on llvmpipe like the GLSL
    hlsl = targets["hlsl"]["llvmpipe"]
    if hlsl["ran"]:
        assert hlsl["passed"] and hlsl["pixels"] > 100, hlsl
    report = (out / "report.md").read_text()
    assert "FLIP" in report and "`shaders/core/my_water.frag`" in report
    assert (out / "comparison.png").is_file()
    written = (out / "shaders" / "core" / "my_water.frag").read_text()
    fitted = UserShader(written, "my_water.frag", {"constants": {"F0": [0.0, 0.2]}}).defaults()
    for name, v in res["constants"].items():
        want = tuple(np.float32(v)) if isinstance(v, list) else np.float32(v)
        got = tuple(np.float32(fitted[name])) if isinstance(v, list) else np.float32(fitted[name])
        assert got == want, name


def test_write_back_into_the_users_own_file(user_run):
    """``fit.write_back = "file"``: the user's file itself gets the fitted constants, every
    other byte the same."""
    import json

    out, mine, before = user_run
    res = json.loads((out / "constants.json").read_text())
    after = mine.read_text()
    assert after == (out / "shaders" / "core" / "my_water.frag").read_text()
    assert after != before and len(after.split("\n")) == len(before.split("\n"))
    changed = [a for a, b in zip(after.split("\n"), before.split("\n")) if a != b]
    assert changed and all(any(f" {n} = " in ln for n in res["constants"]) for ln in changed)


def _user_tradeoff(user_run):
    """(``study tradeoff`` arguments on a copy of the fitted user's shader, that copy, the
    sweep's folder, its cache): one study shader at one schedule beside the user's."""
    import shutil

    out, fitted, _ = user_run
    root = out.parent
    edit = root / "edit"
    edit.mkdir(exist_ok=True)
    mine = edit / "my_water.frag"  # a copy of its own: a test may edit it
    shutil.copy(fitted, mine)
    plan = [
        'tradeoff.variants=["water_refraction"]',
        "tradeoff.steps_grazing=[10.0]",
        "tradeoff.steps_steep=[3.0]",
        "tradeoff.loop_cap=[40]",
        "tradeoff.scales=[1.0]",
        "tradeoff.gl_repeats=3",
        "tradeoff.lod=false",
    ]
    sets = [a for kv in TINY + plan + [f'fit.shader="{mine}"'] for a in ("--set", kv)]
    args = ["tradeoff", str(MY_WATER), "--out", str(root / "t"), "--workers", "1"]
    return args + ["--search", "exhaustive"] + sets, mine, root / "t", root / "cache"


def test_study_tradeoff_charts_the_users_shader(user_run):
    """``study tradeoff`` on a user's shader: it is measured in full beside the study's points,
    placed on the front by the same rule, drawn, calibrated and exported with its fitted
    constants as study calibrate does."""
    import json

    from study.cli import main
    from study.sweep import read_table

    args, _, t, cache = _user_tradeoff(user_run)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("STUDY_CACHE", str(cache))
        assert main(args) == 0
    (user,) = read_table(t / "user.parquet")
    assert user["status"] == "ok", user.get("error")
    assert user["fetches_mean"] == 5.0 and 0 < user["flip"] < 1 and user["gl_ms_512"] > 0
    summary = json.loads((t / "summary.json").read_text())
    scene = summary["scenes"]["my_water"]
    (place,) = scene["user"]
    assert place["label"] == "user:my_water.frag" and place["flip"] == user["flip"]
    ours = [r for r in read_table(t / "tradeoff.parquet") if r["job.kind"] != "converged"]
    beaten = [
        r for r in ours if r["fetches_mean"] <= user["fetches_mean"] and r["flip"] < user["flip"]
    ]
    assert place["on_front"] == (not beaten)
    assert place["on_front"] == (place["label"] in {r["label"] for r in scene["front"]})
    report = (t / "report.md").read_text()
    assert "**Your shader**, `my_water.frag`" in report
    assert "your shader: user:my_water.frag" in summary["panels"]["my_water"]
    # calibrated as study calibrate calibrates it: recommended/ or yours/, its file inside
    mine_out = t / summary["user_exports"]["my_water"]["file"]
    assert mine_out.parent.parent.parent.name in ("recommended", "yours"), mine_out
    written = UserShader.from_file(mine_out).defaults()
    for s in ("FOG_DENSITY", "BUMP"):
        assert np.float32(written[s]) == np.float32(user[f"fitted.{s}"]), s
    if summary["user_exports"]["my_water"]["gl_check"]["ran"]:
        assert summary["user_exports"]["my_water"]["gl_check"]["passed"]


@pytest.mark.slow
def test_an_edited_users_shader_is_measured_again(user_run):
    """An edited shader (its fog twice as dense at the start) is fitted and measured again, not
    read back from the table (by default: its job key covers the text,
    ``test_tradeoff.py::test_a_user_shaders_job_hash_covers_includes_defines_and_the_vertex_shader``)."""
    import json

    from study.cli import main
    from study.sweep import read_table

    args, mine, t, cache = _user_tradeoff(user_run)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("STUDY_CACHE", str(cache))
        assert main(args) == 0
        (user,) = read_table(t / "user.parquet")
        mine.write_text(mine.read_text().replace("exp(-FOG_DENSITY", "exp(-2.0 * FOG_DENSITY"))
        assert main(args) == 0
    again = [r for r in read_table(t / "user.parquet") if r["key"] != user["key"]]
    assert len(again) == 1 and again[0]["status"] == "ok", again
    assert again[0]["fitted.FOG_DENSITY"] != user["fitted.FOG_DENSITY"]
    summary = json.loads((t / "summary.json").read_text())
    assert summary["scenes"]["my_water"]["user"][0]["flip"] == again[0]["flip"]


def test_fit_declare_gives_every_pragma_without_editing_the_file(tmp_path):
    """An engine's file calibrates untouched: the `// @study` lines of a shipped pair moved into
    fit.declare (``up``, ``bind``, ``constant``, ``normal``, ``value`` for either stage,
    ``normal_map`` relative to the experiment file) declare the same shader."""
    from study import load_experiment
    from study.config.errors import ExperimentError
    from study.config.user_shader import load_user_shader
    from study.studies.tradeoff_user import shader_sha256

    shaders = Path(__file__).parent.parent / "experiments" / "shaders"
    for stem in ("zup_water", "webgl_mirror_water"):
        frag = (shaders / f"{stem}.frag").read_text()
        lines = [ln for ln in frag.splitlines() if ln.startswith("// @study ")]
        bare = "\n".join(ln for ln in frag.splitlines() if not ln.startswith("// @study "))
        (tmp_path / f"{stem}.frag").write_text(bare + "\n")
        (tmp_path / f"{stem}.vert").write_text((shaders / f"{stem}.vert").read_text())
        # the normal map relative to the experiment file (tmp_path/exp/e.toml)
        declare = [
            "normal_map ../files/water_normals.png" if ln.startswith("// @study normal_map") else
            ln[len("// @study ") :] for ln in lines
        ]  # fmt: skip
        (tmp_path / "files").mkdir(exist_ok=True)
        (tmp_path / "files" / "water_normals.png").write_bytes(
            (MY_WATER.parent / "files" / "water_normals.png").read_bytes()
        )
        (tmp_path / "exp").mkdir(exist_ok=True)
        (tmp_path / "exp" / "e.toml").write_text(
            (MY_WATER.parent / f"{stem}.toml")
            .read_text()
            .replace(f'"shaders/{stem}.frag"', f'"{tmp_path / f"{stem}.frag"}"')
            .replace("[fit]", f"[fit]\ndeclare = {json.dumps(declare)}")
        )
        ours = load_user_shader(load_experiment(tmp_path / "exp" / "e.toml").values)
        theirs = load_user_shader(load_experiment(MY_WATER.parent / f"{stem}.toml").values)
        assert ours.engine["up"] == theirs.engine["up"]
        assert ours.engine_record() == theirs.engine_record()
        assert ours.bindings == theirs.bindings and ours.normal == theirs.normal
        assert {n: c.default for n, c in ours.constants.items()} == {
            n: c.default for n, c in theirs.constants.items()
        }
        assert ours.engine_values() == theirs.engine_values()
        assert shader_sha256(ours) != shader_sha256(theirs)  # their texts differ
    # a value reaches the stage that reads it; a value nobody reads is refused
    one = SHADERS / "one_file_water.glsl"
    keys = [f'fit.shader="{one}"', f'fit.vertex="{one}"', 'fit.defines=["COMPILEPS", "PS=main"]',
            'fit.vertex_defines=["COMPILEVS", "VS=main"]', "fit.vertex_grid=[8, 6]"]  # fmt: skip
    exp = load_experiment(MY_WATER, [*keys, 'fit.declare=["value cTiling 0.75"]'])
    shader = load_user_shader(exp.values)
    assert shader.vertex.shader.values["cTiling"] == (0.75,)
    with pytest.raises(ExperimentError, match="value cNoSuch: neither this shader nor its vertex"):
        load_experiment(MY_WATER, [*keys, 'fit.declare=["value cNoSuch 1"]'])
    with pytest.raises(ExperimentError, match="fit.declare: 'up x'"):
        load_experiment(MY_WATER, [*keys, 'fit.declare=["up x"]'])
