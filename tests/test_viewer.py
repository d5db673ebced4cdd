"""The WebGL 2 viewer every calibration writes (``viewer/``), run in headless Chromium (Debian's
``chromium-headless-shell``, WebGL 2 on SwiftShader): opened from ``file://`` with no flag but
the software-rendering ones, it runs the exported GLSL ES 3.00 shaders on the calibration's
inputs, and its float framebuffer matches the Dr.Jit port (the executor, for a user's shader)
within the GL check's thresholds; the waves move with the clock; the camera orbits where the
technique allows it; a shader WebGL rejects or a texture the data lacks is reported as text.
One tiny calibration of the study's shader and one of a user's shader, shared by the module."""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from helpers import REPO
from helpers.experiments import DEFAULT, TINY, replaced, sets
from helpers.synthetic import synthetic_baseline_inputs
from helpers.viewer import shader_viewer, smooth_sky, swiftshader_snapping, tiny_calibration
from shaders_port import Constants
from shaders_port.gl.compare import compare_port_gl
from shaders_port.spirv.user_shader import UserShader
from study import load_experiment, read_exr
from study._backend import drjit_backend
from study.cli import main
from study.config.user_shader import load_user_shader
from study.export.gl_check import GL_MEAN, GL_P999, passes
from study.export.shaders import export_shaders, load_constants_json, user_shader_of
from study.export.viewer import (
    read_names,
    spec_defines,
    tied_names,
    views_note,
    with_spec_defines,
)
from study.export.viewer.browser import BrowserRenderer, Chromium, open_viewer, render_float

OVERRIDES = replaced(TINY, "fit.max_steps=5")
USER = [*OVERRIDES, f'fit.shader="{REPO / "experiments" / "shaders" / "my_water.frag"}"']


@pytest.fixture(scope="module")
def browser():
    with Chromium() as b:
        yield b


@pytest.fixture(scope="module")
def runs(tmp_path_factory, browser):
    """A calibration of the study's shader (24x24) and one Chromium."""
    root = tmp_path_factory.mktemp("viewer")
    out, inputs = tiny_calibration(root, "study", OVERRIDES)
    return {"out": {"study": out}, "inputs": {"study": inputs}, "browser": browser, "root": root}


@pytest.fixture(scope="module")
def user_run(tmp_path_factory, browser):
    """A calibration of a user's shader (24x24, ``experiments/shaders/my_water.frag``)."""
    root = tmp_path_factory.mktemp("viewer_user")
    out, inputs = tiny_calibration(root, "user", USER)
    return {"out": {"user": out}, "inputs": {"user": inputs}, "browser": browser, "root": root}


def test_calibrate_writes_a_self_contained_viewer(runs):
    _self_contained(runs, "study")


def _self_contained(runs, name: str) -> None:
    """The viewer folder of calibration ``name``: three files, nothing fetched, the exported
    shader as it is, the FLIP of each image."""
    folder = runs["out"][name] / "viewer"
    assert sorted(p.name for p in folder.iterdir()) == [
        "bound.js", "data.js", "index.html", "viewer.js"]  # fmt: skip
    page = (folder / "index.html").read_text()
    summary = json.loads((runs["out"][name] / "constants.json").read_text())
    for k in ("default", "fitted"):  # the FLIP of each beside the images
        assert f"{summary['error']['flip'][k]:.4f}" in page
    # nothing fetched: two local scripts, no URL, no module, no framework
    assert re.findall(r'<script src="([^"]+)"', page) == ["data.js", "bound.js", "viewer.js"]
    for f in ("index.html", "viewer.js", "bound.js"):
        assert not re.search(r"https?://|import\s|fetch\(", (folder / f).read_text()), f
    data = (folder / "data.js").read_text()
    assert data.startswith("window.WATER_VIEWER_DATA = {")
    exported = (runs["out"][name] / "shaders" / "gles300").glob("*.frag")
    assert json.dumps(next(exported).read_text())[1:-1] in data  # the exported file as is


def test_the_fitted_shader_in_chromium_matches_the_port(runs):
    """The study's camera, clock time 0, the exported file's own constants: the browser's float
    framebuffer against the port at the fitted constants, with the GL check's thresholds."""
    b, out = runs["browser"], runs["out"]["study"]
    assert open_viewer(b, out / "viewer" / "index.html") == []
    fitted = load_constants_json(out / "constants.json")
    res = compare_port_gl(runs["inputs"]["study"], fitted, "water_refraction",
                          renderer=BrowserRenderer(b, "fitted"))  # fmt: skip
    assert res["n_water"] > 300 and res["mask_mismatch"] == 0, res["n_water"]
    assert passes(res), {k: res[k] for k in ("mean_abs", "p999", "max_abs", "unexplained")}
    # the original constants (the export's specialization constants set by #define lines)
    start = Constants.from_dict(read_exr(out / "default.exr")[1]["constants"])
    res0 = compare_port_gl(runs["inputs"]["study"], start, "water_refraction",
                           renderer=BrowserRenderer(b, "default"))  # fmt: skip
    assert passes(res0), {k: res0[k] for k in ("mean_abs", "p999", "max_abs", "unexplained")}
    assert np.abs(res["gl"] - res0["gl"]).max() > 0.01  # two different shaders


def test_the_water_moves_with_the_clock_and_the_camera_orbits(runs):
    b, out = runs["browser"], runs["out"]["study"]
    open_viewer(b, out / "viewer" / "index.html")
    a, mask = render_float(b, time=0.0)
    c, mask_c = render_float(b, time=0.5)
    assert np.all(np.isfinite(a)) and np.all(np.isfinite(c)) and (mask == mask_c).all()
    assert np.abs(a - c)[mask].mean() > 0.01  # the normal-map layers moved
    # the refraction shader reads top-down and world-space inputs only: it orbits
    data = _data(out)
    assert data["camera"]["orbit"] is True
    o, mask_o = render_float(b, yaw=60.0, pitch=40.0)
    assert mask_o.sum() > 100 and np.all(np.isfinite(o[mask_o])) and (mask_o != mask).any()
    page = (out / "viewer" / "index.html").read_text()
    # the page names what this shader reads, not the screen-space buffers it does not read
    assert "orbits the pool" in page and "screen-space buffers" not in page
    assert "refractionTexture" in page


@pytest.mark.slow  # a second calibration (~15 s)
def test_a_users_shader_in_chromium_matches_the_executor(user_run):
    runs = user_run
    _self_contained(runs, "user")
    b, out = runs["browser"], runs["out"]["user"]
    assert open_viewer(b, out / "viewer" / "index.html") == []
    user = user_shader_of(out / "constants.json")
    values = load_constants_json(out / "constants.json")
    ours = user.render(runs["inputs"]["user"], values, backend=drjit_backend("llvm_ad_rgb"))
    ours = ours.numpy()
    rgba, mask = render_float(b)
    both = mask & (ours["mask"] > 0.5)
    d = np.abs(rgba[..., :3] - ours["color"]).max(-1)[both]
    assert both.sum() > 300 and d.mean() <= GL_MEAN and np.percentile(d, 99.9) <= GL_P999
    # a user's shader stays at the study's camera, and says why
    assert _data(out)["camera"]["orbit"] is False
    assert (
        "fixed at the study's camera: a user's shader"
        in (out / "viewer" / "index.html").read_text()
    )
    # its original constants: the file exported again at its start values
    start = {k: tuple(v) if isinstance(v, list) else v
             for k, v in read_exr(out / "default.exr")[1]["constants"].items()}  # fmt: skip
    ours0 = user.render(runs["inputs"]["user"], start, backend=drjit_backend("llvm_ad_rgb"))
    rgba0, _ = render_float(b, constants="default")
    d0 = np.abs(rgba0[..., :3] - ours0.numpy()["color"]).max(-1)[both]
    assert d0.mean() <= GL_MEAN and np.percentile(d0, 99.9) <= GL_P999


def _data(out: Path) -> dict:
    text = (out / "viewer" / "data.js").read_text()
    return json.loads(text[len("window.WATER_VIEWER_DATA = ") : -2])


def _broken(runs, name: str, change) -> Path:
    """A copy of the study calibration's viewer with ``change(data)`` applied to its data."""
    folder = runs["root"] / name
    shutil.copytree(runs["out"]["study"] / "viewer", folder)
    data = _data(runs["out"]["study"])
    change(data)
    (folder / "data.js").write_text(f"window.WATER_VIEWER_DATA = {json.dumps(data)};\n")
    return folder / "index.html"


def test_webgl_errors_are_reported_in_the_page(runs):
    """A shader WebGL cannot compile, a texture the data lacks: the page says so in its text
    (and in ``waterViewer.errors``, which the tests and ``open_viewer`` read), no black canvas."""
    b = runs["browser"]

    def bad_shader(d):
        d["shaders"]["frag"] = d["shaders"]["frag"].replace("void main()", "void main() { oops; }")

    def no_normals(d):
        del d["textures"]["normalMap"]

    for change, words in ((bad_shader, ("could not compile", "fitted shader", "oops")),
                          (no_normals, ("normalMap", "data does not hold"))):  # fmt: skip
        errors = open_viewer(b, _broken(runs, change.__name__, change), expect_errors=True)
        assert len(errors) == 1 and all(w in errors[0] for w in words), errors
        shown = b.evaluate(
            "(() => { const e = document.getElementById('errors'); "
            "return e.hidden ? '' : e.innerText; })()"
        )
        assert "The viewer failed" in shown and words[0] in shown
        assert b.evaluate("waterViewer.ready") is False


def test_study_viewer_writes_it_again_and_refuses_another_experiment(runs, capsys):
    out = runs["out"]["study"]
    before = (out / "viewer" / "data.js").read_bytes()
    (out / "viewer" / "data.js").unlink()
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("STUDY_CACHE", str(runs["root"] / "cache"))
        assert main(["viewer", str(out), str(DEFAULT)] + sets(OVERRIDES)) == 0
        assert (out / "viewer" / "data.js").read_bytes() == before
        other = replaced(OVERRIDES, "water.ior=1.4")
        assert main(["viewer", str(out), str(DEFAULT)] + sets(other)) == 2
    err = capsys.readouterr().err
    assert "is not the experiment" in err and "same --set options" in err


@pytest.mark.slow  # a calibration per shader (~15 s each; the local cube map's capture more)
@pytest.mark.parametrize("shader", ["water_reflection", "water_baseline", "water_refraction_box"])
def test_the_reflection_and_baseline_shaders_in_chromium(shader, tmp_path, browser):
    """The raycast reflection (top-down inputs from below: orbits), the local cube map (world
    space: orbits) and the baseline (screen-space buffers of the study's camera: stays there)
    against the port, as the refraction shader."""
    ov = replaced(TINY, "fit.max_steps=2", f'fit.shader="{shader}"')
    out, inputs = tiny_calibration(tmp_path, shader, ov)
    assert open_viewer(browser, out / "viewer" / "index.html") == []
    fitted = load_constants_json(out / "constants.json")
    res = compare_port_gl(inputs, fitted, shader, renderer=BrowserRenderer(browser))
    assert passes(res), {k: res[k] for k in ("mean_abs", "p999", "max_abs", "unexplained")}
    assert _data(out)["camera"]["orbit"] is (shader != "water_baseline")


def test_what_ties_a_shader_to_the_camera_and_the_start_constants(tmp_path):
    """From the exported GLSL ES text: the screen-space inputs a shader reads, and the
    ``#define`` lines that set its specialization constants (GLSL ES takes no int for a float)."""
    export_shaders(Constants(), tmp_path, ["water_refraction", "water_baseline"], ("gles300",))
    refr = (tmp_path / "gles300" / "water_refraction.frag").read_text()
    base = (tmp_path / "gles300" / "water_baseline.frag").read_text()
    assert tied_names(refr) == []
    assert {"sceneColor", "sceneDepth"} <= set(tied_names(base))
    assert tied_names(
        "uniform sampler2D buf; void main() { texture(buf, p); }", {"buf": "sceneColor"}
    ) == ["sceneColor"]
    start = {"ATTENUATION_DISTANCE": 7, "LOOP_CAP": 12, "waterColor": [0.1, 0.2, 0.3, 1.0]}
    lines = spec_defines(refr, start).splitlines()
    values = dict(line.split()[1:] for line in lines)
    ids = dict(re.findall(r"#define (SPIRV_CROSS_CONSTANT_ID_\d+) [^\n]*\n#endif\n"
                          r"const \w+ (\w+) =", refr))  # fmt: skip
    by_name = {ids[k]: v for k, v in values.items()}
    colour = {f"waterColor_{c}": v for c, v in zip("rgba", ("0.1", "0.2", "0.3", "1.0"))}
    assert by_name == {"ATTENUATION_DISTANCE": "7.0", "LOOP_CAP": "12", **colour}
    assert with_spec_defines(refr, start).startswith("#version 300 es\n" + lines[0])


def test_the_page_names_only_the_inputs_its_shader_reads(tmp_path):
    """The page's list of textures and its words on the camera name what the exported shader
    reads and nothing it does not (the refraction reads no reflection texture)."""
    names = ["refraction", "reflection", "baseline"]
    export_shaders(Constants(), tmp_path, [f"water_{n}" for n in names], ("gles300",))
    frag = {n: (tmp_path / "gles300" / f"water_{n}.frag").read_text() for n in names}
    textures = sorted(["refractionTexture", "worldYComponent", "worldYComponentReflection",
                       "reflectionBottom", "reflectionTexture", "normalMap"])  # fmt: skip
    refr = read_names(frag["refraction"], textures)
    assert "refractionTexture" in refr and "worldYComponentReflection" not in refr
    assert "reflectionBottom" in read_names(frag["reflection"], textures)
    note = views_note(frag["refraction"])
    assert note.startswith("It reads the ground seen from above (refractionTexture")
    assert "reflectionBottom" not in note and "sceneColor" not in note
    assert "reflectionBottom" in views_note(frag["reflection"])
    assert views_note("void main() {}") == ""
    page = (REPO / "study" / "export" / "viewer" / "page.html").read_text()
    assert "the left view" not in page and "the image chosen under <i>left</i>" in page


# ---- a user's shader pair, and the engine inputs, drawn as the GL check binds them ----------
ENGINE_EXPERIMENTS = REPO / "experiments"


@pytest.fixture(scope="module")
def engine_inputs():
    """48x36 synthetic frame with the screen-space buffers, its sky continuous across the cube
    map's faces (``helpers.viewer.smooth_sky``)."""
    return dataclasses.replace(synthetic_baseline_inputs(48, 36), cubemap=smooth_sky())


def _pair(name: str):
    exp = load_experiment(ENGINE_EXPERIMENTS / f"{name}.toml", ["fit.vertex_grid=[16,16]"])
    return load_user_shader(exp.values)


def _against(rgba, mask, ours) -> dict:
    """The browser's frame against an executor's ``ShaderOutput.numpy()``: pixels covered by
    one only, and the per-pixel max-over-channel |difference| where both cover."""
    mine = ours["mask"] > 0.5
    d = np.abs(rgba[..., :3] - ours["color"]).max(-1)[mask & mine]
    return {"xor": int((mask ^ mine).sum()), "n": int(d.size), "mean": float(d.mean()),
            "p999": float(np.percentile(d, 99.9)), "max": float(d.max())}  # fmt: skip


@pytest.mark.parametrize("name", ["fog_cube_water", "zup_water"])
def test_a_pair_in_chromium_matches_the_executor(name, browser, engine_inputs, tmp_path,
                                                 monkeypatch):  # fmt: skip
    """A pair (the user's vertex shader on the water grid: Urho3D-style with a DuDv map, the
    sky cube, the depth buffer, an #include and a #define; a Z-up one), its uniforms and
    textures as the GL check binds them. SwiftShader snaps vertices to 1/16 pixel: against the
    executor given the same snapped vertices the GL check's thresholds hold; against the exact
    executor the varyings shift by up to 1/32 pixel, a difference the thresholds below bound
    at about twice its measure (docs/engine.md gives the figures)."""
    shader = _pair(name)
    page, bound = shader_viewer(tmp_path, shader, engine_inputs)
    g = bound["geometry"]
    assert g["mode"] == "triangles" and g["depth_test"] and g["screen"] is None
    assert open_viewer(browser, page) == []
    rgba, mask = render_float(browser)
    exact = _against(rgba, mask, shader.render(engine_inputs).numpy())
    swiftshader_snapping(monkeypatch)
    snapped = _against(rgba, mask, shader.render(engine_inputs).numpy())
    assert snapped["n"] > 400 and snapped["xor"] <= 1
    assert snapped["mean"] <= GL_MEAN and snapped["p999"] <= GL_P999, snapped
    assert exact["xor"] <= 2 and exact["mean"] <= 5e-3 and exact["p999"] <= 3e-2, exact
    later, _ = render_float(browser, time=2.0)
    assert np.abs(later - rgba)[mask].mean() > 1e-3  # the clock moves the layers' offsets


def test_engine_textures_in_chromium_match_the_executor(browser, engine_inputs, tmp_path):
    """A fragment shader reading a DuDv map, the user's own normal-map image (trilinear) and the
    sky cube on the study's quad (drawn as the screen's corners: no snapping): every texture as
    the GL check uploads it; the mip level SwiftShader picks differs from llvmpipe's (which
    the executor reproduces), a difference the thresholds bound at about twice its measure."""
    shader = UserShader.from_file(REPO / "tests" / "shaders" / "engine_textures.frag")
    page, bound = shader_viewer(tmp_path, shader, engine_inputs)
    tex = {t["input"]: t for t in bound["textures"]}
    assert sorted(tex) == ["dudv_map", "sky_cube", "user_normal_map"]
    assert tex["user_normal_map"]["min_filter"] == "linear_mipmap_linear"
    assert len(tex["user_normal_map"]["levels"]) == 9 and tex["sky_cube"]["target"] == "cube"
    assert bound["geometry"]["screen"] is not None and bound["clock"]["time"] == "time"
    assert open_viewer(browser, page) == []
    rgba, mask = render_float(browser)
    res = _against(rgba, mask, shader.render(engine_inputs).numpy())
    assert res["n"] > 400 and res["xor"] <= 1
    assert res["mean"] <= 3e-3 and res["p999"] <= 2e-2, res
    later, _ = render_float(browser, time=2.0)
    assert np.abs(later - rgba)[mask].mean() > 1e-3  # time scrolls the DuDv map


@pytest.mark.slow  # a calibration of a pair (~40 s)
def test_calibrate_writes_the_viewer_of_a_pair(tmp_path, browser, monkeypatch):
    """``study calibrate`` of an engine-style pair (experiments/fog_cube_water.toml, shrunk)
    writes its viewer and ships the textures it reads: the page draws the pair at the study's
    camera, against the executor (SwiftShader's snapping given to it) within the GL check's
    thresholds."""
    ov = replaced(TINY, "fit.max_steps=2", "fit.vertex_grid=[16,16]")
    out, inputs = tiny_calibration(tmp_path, "pair", ov, ENGINE_EXPERIMENTS / "fog_cube_water.toml")
    _self_contained({"out": {"pair": out}}, "pair")
    files = {p.name for p in (out / "shaders" / "textures").iterdir()}
    assert {"dudv_map.exr", "sky_cube_px.exr", "sky_cube_nz.exr"} <= files
    assert "`sEnvCubeMap` = `sky_cube_px.exr`" in (out / "shaders/gles300/BINDINGS.md").read_text()
    page = (out / "viewer" / "index.html").read_text()
    assert "its own vertex shader fog_cube_water.vert draws the water grid" in page
    assert open_viewer(browser, out / "viewer" / "index.html") == []
    user = user_shader_of(out / "constants.json")
    values = load_constants_json(out / "constants.json")
    rgba, mask = render_float(browser)
    swiftshader_snapping(monkeypatch)
    res = _against(rgba, mask, user.render(inputs, values).numpy())
    assert res["n"] > 100 and res["xor"] <= 1
    assert res["mean"] <= GL_MEAN and res["p999"] <= GL_P999, res
