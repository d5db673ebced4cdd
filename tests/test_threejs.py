"""The three.js module every calibration of the study's shaders writes (``threejs/``), run with
the real three.js (the npm package the project pins) in headless Chromium (WebGL 2 on
SwiftShader, the page opened from ``file://``):

* fed the study's own inputs, three's render of the calibrated material matches the Dr.Jit port
  within the GL check's thresholds, at the fitted and at the start constants;
* the glue: the example pool is a three.js scene whose floor and walls carry the study's lit
  top-down colour on its world height, and whose sky is the study's cube map as three holds
  one; the inputs the module builds from that scene (top-down colour and height, sky cube map)
  reproduce the study's, and so does the water they feed (FLIP <= 0.02 on the water pixels);
* a missing texture and a shader WebGL rejects show in the page and in its errors array.

One tiny calibration of the study's shader and one Chromium, shared by the module."""

from __future__ import annotations

import base64
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from helpers import REPO
from helpers.experiments import TINY, replaced
from helpers.sheets import sheet_values
from helpers.viewer import tiny_calibration
from shaders_port import Constants
from shaders_port.gl.compare import compare_port_gl
from study import read_exr
from study._metrics import flip
from study.export.gl_check import GL_MEAN, GL_P999, passes
from study.export.shaders import load_constants_json
from study.export.threejs import THREE_FILES, lacking_inputs, three_version
from study.export.viewer.browser import (
    FILE_ACCESS,
    SOFTWARE_GL,
    BrowserRenderer,
    Chromium,
    open_three_example,
    render_float,
)

OVERRIDES = replaced(TINY, "fit.max_steps=5")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A tiny calibration of the default experiment (24x24), its shader inputs as the GL check
    runs them, and one Chromium that may read files beside a ``file://`` page."""
    root = tmp_path_factory.mktemp("threejs")
    out, inputs = tiny_calibration(root, "study", OVERRIDES)
    with Chromium(flags=SOFTWARE_GL + FILE_ACCESS) as browser:
        yield {"out": out, "root": root, "browser": browser, "inputs": inputs}


def _calibration(folder: Path) -> dict:
    text = (folder / "calibration.js").read_text()
    body = text[text.index("export default ") + len("export default ") :].rstrip().rstrip(";")
    return json.loads(body)


def test_calibrate_writes_the_module_with_the_pinned_three(run):
    folder = run["out"] / "threejs"
    files = sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())
    assert files == sorted([*THREE_FILES, "water.js", "example.html", "example.js",
                            "calibration.js"])  # fmt: skip
    pinned = json.loads((REPO / "package.json").read_text())["dependencies"]["three"]
    cal = _calibration(folder)
    assert cal["threeVersion"] == pinned == three_version()
    # three.js as the package ships it, and nothing fetched from a network
    pkg = REPO / "node_modules" / "three"
    for name, src in THREE_FILES.items():
        assert (folder / name).read_bytes() == (pkg / src).read_bytes(), name
    for name in ("water.js", "example.js", "example.html"):
        assert not re.search(r"https?://", (folder / name).read_text()), name
    # the exported GLSL ES text and textures.json, read by the page from the export's files
    assert cal["files"] == {"vert": "../shaders/gles300/water.vert",
                            "frag": "../shaders/gles300/water_refraction.frag",
                            "textures": "../shaders/textures/textures.json"}  # fmt: skip
    summary = json.loads((run["out"] / "constants.json").read_text())
    assert cal["constants"] == summary["constants"]


def test_three_with_the_study_inputs_matches_the_port(run):
    """The study's camera, clock time 0, three's WebGLRenderer drawing the calibrated
    RawShaderMaterial on the study's own images: against the port at the fitted and at the
    start constants, with the GL check's thresholds. The colour is drawn on the quad of the
    screen's corners (SwiftShader snaps vertices to 1/16 pixel, which moves every varying of the
    water's own quad by up to ~0.02 pixel and a sharp highlight with them), as the viewer
    draws it; the coverage is the water quad's."""
    b, out = run["browser"], run["out"]
    assert open_three_example(b, out / "threejs" / "example.html") == []
    fitted = load_constants_json(out / "constants.json")
    start = Constants.from_dict(read_exr(out / "default.exr")[1]["constants"])
    gl = {}
    for which, constants in (("fitted", fitted), ("default", start)):
        renderer = BrowserRenderer(b, which, api="waterThree", inputs="study", screenPlane=True)
        res = compare_port_gl(run["inputs"], constants, "water_refraction", renderer=renderer)
        assert res["n_water"] > 300 and res["mask_mismatch"] == 0, res["n_water"]
        assert passes(res), {k: res[k] for k in ("mean_abs", "p999", "max_abs", "unexplained")}
        gl[which] = res["gl"]
    assert np.abs(gl["fitted"] - gl["default"]).max() > 0.01  # two different shaders


def _floats(entry: dict, shape) -> np.ndarray:
    return np.frombuffer(base64.b64decode(entry), "<f4").reshape(shape)


def _asymmetric_sky(folder: Path) -> np.ndarray:
    """The copy of the viewer's data in ``folder`` with a sky that tells every face, row and
    column apart (a smooth function of the direction, no symmetry); returns it (6, n, n, 3)."""
    path = folder / "viewer" / "data.js"
    data = json.loads(path.read_text()[len("window.WATER_VIEWER_DATA = ") : -2])
    n = data["textures"]["reflectionTexture"]["size"]
    c = (np.arange(n) + 0.5) / n * 2 - 1
    sc, tc = np.meshgrid(c, c)  # row = t, column = s
    one = np.ones_like(sc)
    # GL's face table: the direction of texel (s, t) of each face
    dirs = [(one, -tc, -sc), (-one, -tc, sc), (sc, one, tc), (sc, -one, -tc), (sc, -tc, one),
            (-sc, -tc, -one)]  # fmt: skip
    d = np.stack([np.stack(f, -1) for f in dirs])
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    sky = np.stack([0.6 + 0.3 * d[..., 0] + 0.1 * d[..., 2] ** 2, 0.5 + 0.2 * d[..., 1],
                    0.4 + 0.25 * d[..., 2] + 0.05 * d[..., 0] * d[..., 1]], -1)  # fmt: skip
    sky = sky.astype(np.float32)
    data["textures"]["reflectionTexture"]["data"] = base64.b64encode(sky.tobytes()).decode()
    path.write_text(f"window.WATER_VIEWER_DATA = {json.dumps(data)};\n")
    return sky


def test_the_inputs_three_builds_from_the_pool_reproduce_the_studys(run):
    """The glue: water.js's WaterInputs, run on the example's three.js scene (the pool as a
    height field carrying the lit top-down colour, unlit; an asymmetric sky as
    scene.background), builds the study's top-down colour and height (its rows run the other
    way: its top-down camera looks down with x to the right) and the study's sky cube map;
    the water they feed matches the water on the study's own inputs."""
    folder = run["root"] / "asymmetric_sky"
    for sub in ("threejs", "viewer", "shaders"):
        shutil.copytree(run["out"] / sub, folder / sub)
    sky = _asymmetric_sky(folder)
    b = run["browser"]
    assert open_three_example(b, folder / "threejs" / "example.html") == []
    built = b.evaluate("waterThree.builtInputs()")
    n, k = built["size"], built["skySize"]
    i = run["inputs"]
    assert n == i.refraction_texture.shape[0] and k == sky.shape[1]
    colour = _floats(built["color"], (n, n, 4))[::-1, :, :3]
    height = _floats(built["height"], (n, n, 4))[::-1, :, 0]
    assert np.abs(colour - i.refraction_texture[..., :3]).max() < 1e-5
    assert np.abs(height - i.world_y).max() < 1e-4
    faces = np.stack([_floats(f, (k, k, 4))[..., :3] for f in built["sky"]])
    assert np.abs(faces - sky).max() < 1e-5
    # the texture matrix maps a world point to the texel it landed in
    m = np.asarray(built["textureMatrix"], np.float64).reshape(4, 4).T
    record = json.loads((folder / "shaders" / "textures" / "textures.json").read_text())
    x0, z0, x1, z1 = record["scene"]["top_down"]["extent"]
    s, t = (m @ [x0 + 0.3 * (x1 - x0), 0.0, z0 + 0.2 * (z1 - z0), 1.0])[:2]
    assert abs(s - 0.3) < 1e-6 and abs(t - 0.8) < 1e-6
    # the water both ways, on the water pixels
    study, mask = render_float(b, "waterThree", inputs="study")
    scene, mask_s = render_float(b, "waterThree", inputs="scene")
    assert (mask == mask_s).all() and mask.sum() > 300
    d = np.abs(study - scene)[mask][:, :3]
    score = flip(study[..., :3], scene[..., :3], mask)
    print(f"three.js water, scene-built against study inputs: FLIP {score:.2e}, "
          f"mean |diff| {d.mean():.2e}, max {d.max():.2e}")  # fmt: skip
    assert score <= 0.02


def test_the_module_is_wired_by_the_sheet_and_textures_alone(run):
    """calibration.js holds none of the values the fit used: water.js reads them from
    ``shaders/textures/textures.json``, and the shaders from ``shaders/gles300/``. The scene
    record rewritten from the short sheet's text alone (its printed precision) draws the port's
    water from the inputs the module builds; the sun moved in that file, the water follows."""
    folder = run["root"] / "from_the_sheet"
    for sub in ("threejs", "viewer", "shaders"):
        shutil.copytree(run["out"] / sub, folder / sub)
    cal = _calibration(folder / "threejs")
    assert not {"light", "waves", "topDown", "normalTile", "textures", "shaders"} & set(cal)
    scene, tile = sheet_values((folder / "shaders" / "gles300" / "BINDINGS.md").read_text())
    path = folder / "shaders" / "textures" / "textures.json"
    record = json.loads(path.read_text())
    record["scene"], record["normal_map"]["tile"] = scene, tile
    fitted = load_constants_json(run["out"] / "constants.json")
    b = run["browser"]

    def drawn(record: dict) -> dict:
        path.write_text(json.dumps(record))
        assert open_three_example(b, folder / "threejs" / "example.html") == []
        r = BrowserRenderer(b, "fitted", api="waterThree", inputs="scene", screenPlane=True)
        return compare_port_gl(run["inputs"], fitted, "water_refraction", renderer=r)

    res = drawn(record)
    assert res["n_water"] > 300 and passes(res), {k: res[k] for k in ("mean_abs", "p999")}
    moved = drawn({**record, "scene": {**scene, "lightpos": [800.0, 500.0, 300.0]}})
    assert not passes(moved) and np.abs(moved["gl"] - res["gl"]).max() > 0.05


def test_a_missing_texture_or_a_rejected_shader_shows_in_the_page(run):
    b = run["browser"]
    folder = run["root"] / "broken"
    for sub in ("threejs", "viewer", "shaders"):
        shutil.copytree(run["out"] / sub, folder / sub)
    (folder / "shaders" / "textures" / "normal_map.exr").unlink()
    errors = open_three_example(b, folder / "threejs" / "example.html", expect_errors=True)
    assert len(errors) == 1 and "normalMap" in errors[0] and "normal_map.exr" in errors[0]
    assert "normal_map.exr" in b.evaluate("document.getElementById('errors').textContent")
    # the textures back, the shader broken: three reports the compile error, the page shows it
    shutil.copy(run["out"] / "shaders" / "textures" / "normal_map.exr",
                folder / "shaders" / "textures")  # fmt: skip
    frag = folder / "shaders" / "gles300" / "water_refraction.frag"
    frag.write_text(frag.read_text().replace("void main()", "void main(", 1))
    errors = open_three_example(b, folder / "threejs" / "example.html", expect_errors=True)
    assert errors and any("compile" in e.lower() or "shader" in e.lower() for e in errors), errors
    assert not b.evaluate("waterThree.ready")


def test_a_shader_reading_inputs_the_module_does_not_build_is_named():
    """The screen-space reflection reads the scene's colour and depth buffers, which water.js
    does not render: they are named (and the calibration writes no threejs/)."""
    frag = (
        "#version 300 es\nprecision mediump float;\nuniform highp sampler2D normalMap;\n"
        "uniform highp sampler2D sceneDepth;\nuniform highp mat4 uTextureMatrix0;\n"
        "uniform highp sampler2D sceneColor;\nvoid main() {}\n"
    )
    vert = "#version 300 es\nuniform mat4 uModelViewProjectionMatrix;\nuniform vec2 wave1;\n"
    assert lacking_inputs(vert, frag) == ["sceneDepth", "sceneColor"]
    assert lacking_inputs(vert, frag.replace("sceneDepth", "normalMap2")) == [
        "normalMap2", "sceneColor"]  # fmt: skip


@pytest.mark.slow  # a calibration of a user's shader (~20 s)
def test_a_users_shader_in_three_matches_the_executor(tmp_path):
    """``experiments/shaders/my_water.frag`` after the study's vertex shader, its sampler
    ``waveNormals`` bound to ``normalMap``: water.js sets it under its own name, and three's
    render matches the executor within the GL check's thresholds, on the study's images and on
    the inputs it builds from the pool."""
    from study._backend import drjit_backend
    from study.export.shaders import user_shader_of

    user = [*OVERRIDES, f'fit.shader="{REPO / "experiments" / "shaders" / "my_water.frag"}"']
    out, i = tiny_calibration(tmp_path, "user", user)
    cal = _calibration(out / "threejs")
    assert cal["uniformNames"] == {"waveNormals": "normalMap"} and cal["startDefines"] is None
    shader = user_shader_of(out / "constants.json")
    values = load_constants_json(out / "constants.json")
    ours = shader.render(i, values, backend=drjit_backend("llvm_ad_rgb")).numpy()
    with Chromium(flags=SOFTWARE_GL + FILE_ACCESS) as b:
        assert open_three_example(b, out / "threejs" / "example.html") == []
        for inputs in ("study", "scene"):
            rgba, mask = render_float(b, "waterThree", inputs=inputs, screenPlane=True)
            both = mask & (ours["mask"] > 0.5)
            d = np.abs(rgba[..., :3] - ours["color"]).max(-1)[both]
            assert both.sum() > 300 and d.mean() <= GL_MEAN, (inputs, d.mean())
            assert np.percentile(d, 99.9) <= GL_P999, (inputs, np.percentile(d, 99.9))


def test_a_shader_with_its_own_vertex_shader_is_refused_by_name(tmp_path):
    """A calibration of an engine pair (its own vertex shader): the module says why it is not
    written, naming the vertex shader and the binding sheet, not a missing file of the study's
    vertex shader (which such an export does not have)."""
    from study.export.threejs import ThreeUnsupported, calibration_data

    src = REPO / "docs" / "results" / "loss-transport" / "webgl_mirror_water" / "constants.json"
    shutil.copy(src, tmp_path / "constants.json")
    with pytest.raises(ThreeUnsupported, match="its own vertex shader webgl_mirror_water.vert"):
        calibration_data(tmp_path, None, None)
