"""The WGSL (WebGPU) engine target: the export's SPIR-V through Vulkan GLSL and naga
(``shaders_port.spirv.wgsl``, npm ``naga-wasm`` run by Node.js), the fitted constants as
``override`` declarations, and the WGSL pair run with wgpu on Mesa's lavapipe
(``study.export.wgsl_run``) against the Dr.Jit port with the GL check's thresholds, at the
file's own constants and at others set through the overrides at pipeline creation."""

from __future__ import annotations

import dataclasses
import json
import re
import shutil

import numpy as np
import pytest

from helpers.experiments import DEFAULT, TINY, replaced, sets
from helpers.synthetic import EXPORT_CONSTANTS as FITTED
from helpers.synthetic import synthetic_baseline_inputs, synthetic_inputs
from helpers.viewer import smooth_sky
from shaders_port.gl.compare import compare_port_gl
from shaders_port.spirv import wgsl as W
from shaders_port.spirv.tools import SPEC_IDS, missing_tools
from study.export.gl_check import passes
from study.export.shaders import export_shaders
from study.export.targets import resolve_targets, target_file

MISSING = missing_tools() + W.missing_tools()
pytestmark = pytest.mark.skipif(bool(MISSING), reason=f"the WGSL target needs {MISSING}")

# what the overrides set instead: a visibly different water
OTHER = FITTED.replace(
    attenuation_distance=2.1, specular_strength=0.6, water_color=(0.3, 0.12, 0.05, 1.0)
)
SHADERS = ("water_refraction", "water_baseline")


@pytest.fixture(scope="module")
def export(tmp_path_factory):
    """The refraction shader and the baseline (it reads gl_FragCoord) exported with FITTED to
    WGSL (and SPIR-V, whose reflection holds the GL bindings)."""
    out = tmp_path_factory.mktemp("wgsl") / "shaders"
    export_shaders(FITTED, out, list(SHADERS), targets=["spirv", "wgsl"])
    return out


def _renderer(export, shader, inputs, **kw):
    """A ``WgslRenderer``, or a skip naming what is missing when lavapipe is not there."""
    from study.export.wgsl_run import WgslRenderer

    try:
        return WgslRenderer(export, shader, inputs, **kw)
    except RuntimeError as exc:
        if "mesa-vulkan-drivers" in str(exc):
            pytest.skip(str(exc))
        raise


def _figures(res: dict) -> dict:
    return {k: res[k] for k in ("mean_abs", "p999", "max_abs", "unexplained", "n_water")}


@pytest.fixture(scope="module")
def inputs():
    """Synthetic inputs with a sky continuous across the cube map's faces: WebGPU filters a cube
    map across its faces, the port (as desktop GL here) each face on its own."""
    return dataclasses.replace(synthetic_inputs(width=96, height=72), cubemap=smooth_sky())


def _overrides(text: str) -> dict:
    return {
        name: (int(i), float(v))
        for i, name, v in re.findall(r"^@id\((\d+)\) override (\w+): \w+ = ([^;]+);$", text, re.M)
    }


def test_the_export_writes_wgsl_holding_the_fitted_constants(export):
    manifest = json.loads((export / "targets.json").read_text())
    assert "naga" in manifest["targets"]["wgsl"]["check"]
    vert = (export / target_file("wgsl", "water", "vert")).read_text()
    frag = (export / "wgsl" / "water_refraction.frag.wgsl").read_text()
    assert "@vertex" in vert and "@fragment" in frag
    assert frag.startswith("diagnostic(off, derivative_uniformity);")
    got = _overrides(frag)
    glsl = FITTED.to_glsl_dict()
    for name in ("ATTENUATION_DISTANCE", "LOOP_CAP", "BumptexMult", "SPECULAR_EXPONENT"):
        assert got[name] == (SPEC_IDS[name], np.float32(glsl[name])), name
    for k, c in enumerate("rgba"):
        assert got[f"waterColor_{c}"][1] == np.float32(FITTED.water_color[k])
    assert "override LOOP_CAP: i32 = 37;" in frag  # a plain literal, as in the other targets


def test_the_reflection_lists_the_bindings_and_the_std140_offsets(export):
    refl = json.loads((export / "wgsl" / "water_refraction.frag.reflect.json").read_text())
    by_kind = {}
    for b in refl["bindings"]:
        assert b["group"] == 0
        by_kind.setdefault(b["kind"], {})[b["glsl"]] = b["binding"]
    # the textures keep their GL bindings, each sampler 16 above, the block at 32
    spirv = json.loads((export / "spirv" / "water_refraction.frag.reflect.json").read_text())
    assert by_kind["texture"] == {t["name"]: t["binding"] for t in spirv["textures"]}
    assert by_kind["sampler"] == {n: b + W.SAMPLER_OFFSET for n, b in by_kind["texture"].items()}
    assert by_kind["uniform"] == {"FragUniforms": 32}
    (block,) = refl["uniform_blocks"]
    members = {m["glsl"]: m for m in block["members"]}
    # std140: mat4 64 bytes, vec3 aligned to 16, mat3 as three 16-byte columns
    assert members["uTextureMatrix0"]["offset"] == 0
    assert members["lightcolor"]["offset"] == 64 and members["lightcolor"]["size"] == 12
    assert members["uNormalMatrix"]["size"] == 48
    assert members["uNormalMatrix"]["matrix_stride"] == 16
    assert block["size"] % 16 == 0 and block["size"] >= max(
        m["offset"] + m["size"] for m in block["members"]
    )
    vert = json.loads((export / "wgsl" / "water.vert.reflect.json").read_text())
    assert [b["binding"] for b in vert["bindings"]] == [33]
    locations = {i["name"]: i["location"] for i in vert["inputs"]}
    assert locations == {"aVertex": 0, "aMultiTexCoord0": 1}
    baseline = json.loads((export / "wgsl" / "water_baseline.frag.reflect.json").read_text())
    names = {m["glsl"] for m in baseline["uniform_blocks"][0]["members"]}
    assert W.FRAMEBUFFER_HEIGHT in names  # it reads gl_FragCoord
    sheet = (export / "wgsl" / "BINDINGS.md").read_text()
    assert "## Conventions of wgsl" in sheet and "float32-filterable" in sheet
    assert "| `_normalMap_sampler` | sampler | sampler | @group(0) @binding(" in sheet
    assert "| 10 | `BumptexMult` | 0.9797 |" in sheet


def test_the_wgsl_on_lavapipe_matches_the_port_at_the_fitted_constants(export, inputs):
    """The file's own override defaults (no constant set on the pipeline)."""
    with _renderer(export, "water_refraction", inputs) as r:
        res = compare_port_gl(inputs, FITTED, "water_refraction", renderer=r)
    assert res["n_water"] > 1500 and res["mask_mismatch"] <= 2, res["n_water"]
    # measured: mean 1.0e-5, 99.9th percentile 3.7e-4, max 1.3e-3 (the cube map's seams: WebGPU
    # filters across them, the port within a face; the sky is smooth there, not identical)
    assert passes(res) and res["mean_abs"] < 1e-4, _figures(res)


def test_constants_set_through_the_overrides(export, inputs):
    """Other constants given to the pipeline (``constants={"<id>": value}``): the WGSL follows
    them as the port does, and the image is another."""
    with _renderer(export, "water_refraction", inputs, overrides=True) as r:
        res = compare_port_gl(inputs, OTHER, "water_refraction", renderer=r)
        assert passes(res) and res["mean_abs"] < 1e-4, _figures(res)
        fitted, _ = r.render(FITTED)
    assert np.abs(res["gl"] - fitted[..., :3]).max() > 0.05


def test_the_baseline_reads_gl_fragcoord_as_gl_does(export):
    """The baseline samples its screen-space buffers at gl_FragCoord / screenSize: GL's window
    y, from the bottom, through ``glFramebufferHeight``."""
    frame = synthetic_baseline_inputs(width=96, height=72)
    with _renderer(export, "water_baseline", frame) as r:
        res = compare_port_gl(frame, FITTED, "water_baseline", renderer=r)
    assert res["n_water"] > 1500 and passes(res), _figures(res)


def test_a_failing_tool_gives_its_log(tmp_path, monkeypatch):
    with pytest.raises(RuntimeError, match=r"spirv-cross failed on wgsl/x\.frag\.wgsl"):
        W.translate(b"not SPIR-V", "frag", "wgsl/x.frag.wgsl")
    header = np.array([0x07230203, 0x10000, 0, 1, 0], "<u4").tobytes()
    with pytest.raises(RuntimeError, match=r"(?s)naga failed on wgsl/y\.frag\.wgsl:\n.*naga 30"):
        W.naga([(header + b"\x01\x02", "wgsl/y.frag.wgsl")])
    with pytest.raises(RuntimeError, match=r"(?s)naga failed on wgsl/z\.wgsl.*validating"):
        W.check([("fn main( {", "wgsl/z.wgsl")])
    # an export whose translation fails writes nothing
    monkeypatch.setattr(W, "NAGA_SCRIPT", tmp_path / "missing.mjs")
    with pytest.raises(RuntimeError, match="naga failed on wgsl/water.vert.wgsl"):
        export_shaders(FITTED, tmp_path / "shaders", ["water_refraction"], targets=["wgsl"])
    assert not (tmp_path / "shaders").exists()


def test_the_target_needs_node_and_naga(monkeypatch):
    assert "wgsl" in resolve_targets(None)
    real = shutil.which
    monkeypatch.setattr(shutil, "which", lambda n: None if n == "node" else real(n))
    assert "wgsl" not in resolve_targets(None) and "hlsl" in resolve_targets(None)
    with pytest.raises(RuntimeError, match=r"need node .*bash scripts/setup\.sh"):
        resolve_targets(["hlsl", "wgsl"])


def test_no_lavapipe_is_said(monkeypatch):
    wgpu = pytest.importorskip("wgpu")
    from study.export import wgsl_run

    wgsl_run._lavapipe_adapter.cache_clear()
    monkeypatch.setattr(wgpu.gpu, "enumerate_adapters_sync", lambda: [])
    try:
        with pytest.raises(RuntimeError, match="apt-get install mesa-vulkan-drivers"):
            wgsl_run.lavapipe_device()
    finally:
        wgsl_run._lavapipe_adapter.cache_clear()


# Chromium's WebGPU (Dawn, its WGSL compiler Tint) on SwiftShader's Vulkan, no GPU
WEBGPU_FLAGS = ("--enable-unsafe-webgpu", "--enable-features=Vulkan", "--use-vulkan=swiftshader",
                "--use-webgpu-adapter=swiftshader")  # fmt: skip
_TINT = """(async () => {
  if (!navigator.gpu) return null;
  const adapter = await navigator.gpu.requestAdapter();
  if (!adapter) return null;
  const device = await adapter.requestDevice({requiredFeatures: ["float32-filterable"]});
  const out = {};
  for (const [name, code] of Object.entries(%s)) {
    const info = await device.createShaderModule({code}).getCompilationInfo();
    out[name] = info.messages.map((m) => `${m.type}: ${m.message}`);
  }
  return out;
})()"""


def test_chromium_webgpu_compiles_the_wgsl(export, tmp_path):
    """Chrome's WGSL compiler (Tint, stricter than naga: its uniformity analysis refuses
    ``textureSample`` in the raymarch's loop without the file's ``diagnostic`` directive)
    accepts every exported file without a message."""
    from study.export.viewer.browser import BrowserError, Chromium, find_browser

    if find_browser() is None:
        pytest.skip("no Chromium (apt-get install chromium-headless-shell)")
    codes = {p.name: p.read_text() for p in sorted((export / "wgsl").glob("*.wgsl"))}
    (tmp_path / "blank.html").write_text("<!doctype html><title>webgpu</title>")
    try:
        with Chromium(flags=WEBGPU_FLAGS, timeout=120) as b:
            b.open((tmp_path / "blank.html").as_uri())  # a secure context: navigator.gpu
            got = b.evaluate(_TINT % json.dumps(codes))
    except BrowserError as exc:
        pytest.skip(f"Chromium did not start: {exc}")
    if got is None:
        pytest.skip("this Chromium has no WebGPU adapter")
    assert got == {name: [] for name in codes}, got


@pytest.mark.slow
def test_a_tiny_calibration_writes_wgsl_that_runs_like_the_port(tmp_path, monkeypatch):
    """``study calibrate`` writes ``shaders/wgsl/``; on the calibration's own inputs the WGSL
    at its fitted constants matches the port."""
    from study.calibration.frames import prepare
    from study.cli import main
    from study.export.shaders import load_constants_json
    from study.export.textures import with_exported_textures
    from study.scene.baseline_inputs import inputs_for_shader
    from study.scene.shader_inputs import load_or_build_shader_inputs

    overrides = replaced(TINY, "fit.max_steps=5")
    out = tmp_path / "study"
    monkeypatch.setenv("STUDY_CACHE", str(tmp_path / "cache"))
    assert main(["calibrate", str(DEFAULT), "--out", str(out)] + sets(overrides)) == 0
    assert (out / "shaders" / "wgsl" / "water_refraction.frag.wgsl").is_file()
    exp, variant, _ = prepare(DEFAULT, out, overrides)
    frame = load_or_build_shader_inputs(exp, variant, log=lambda *a: None)
    frame = inputs_for_shader(exp, frame, exp.fit.shader, variant, log=lambda *a: None)
    frame = with_exported_textures(frame, out / "shaders")
    fitted = load_constants_json(out / "constants.json")
    with _renderer(out / "shaders", "water_refraction", frame) as r:
        res = compare_port_gl(frame, fitted, "water_refraction", renderer=r)
    # measured on lavapipe: mean 9.3e-7, 99.9th percentile 4.1e-5, max 4.4e-5 on 432 pixels
    assert res["n_water"] > 300 and passes(res) and res["max_abs"] < 1e-3, _figures(res)


def test_an_output_array_becomes_one_output_per_element(tmp_path):
    """Urho3D's GL3 path writes its colour to ``fragData[0]``; WGSL's entry points take no
    array: the translation declares ``fragData_0`` at location 0 (naga validates it)."""
    from helpers import REPO
    from shaders_port.spirv.user_shader import UserShader
    from shaders_port.spirv.user_vertex import UserVertex
    from study.export.shaders import export_user_shader

    path = REPO / "tests" / "shaders" / "one_file_water.glsl"
    vertex = UserVertex.from_file(path, (24, 24), ("COMPILEVS", "VS=main"), (), shared=True)
    shader = UserShader.from_file(path, None, ("COMPILEPS", "PS=main"), (), vertex=vertex)
    export_user_shader(shader, shader.defaults(), tmp_path / "shaders", targets=["wgsl"])
    frag = (tmp_path / "shaders" / "wgsl" / "one_file_water.frag.wgsl").read_text()
    assert "fragData_0" in frag and "@location(0)" in frag and "fragData[" not in frag
    vert = json.loads(
        (tmp_path / "shaders" / "wgsl" / "one_file_water.vert.reflect.json").read_text()
    )
    outs = sorted(o["location"] for o in vert["outputs"])
    assert outs == list(range(len(outs))) and len(outs) == 3  # vClip, vUv, vEye: no overlap
