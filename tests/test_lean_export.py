"""A LEAN shader (``normals = "lean"``) exported with what it reads: ``study calibrate`` ships
``slope_moments.exr`` (exactly the moments the fit and the GL check used) with its record in
``textures.json`` and a line in the binding sheet; its WGSL on lavapipe (the mip chain
uploaded) and its GLSL ES 3.00 in the viewer's page in Chromium (the levels uploaded as given)
match the port at the fitted constants."""

from __future__ import annotations

import json

import numpy as np
import pytest

from helpers.experiments import DEFAULT, TINY, replaced
from helpers.viewer import tiny_calibration
from shaders_port.gl.compare import compare_port_gl
from shaders_port.pipeline.moments import slope_moments
from study import read_exr
from study.export.gl_check import passes
from study.export.shaders import load_constants_json

SHADER = "water_refraction_disc_lean"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A tiny calibration of the LEAN disc shader and its inputs as the GL check runs them."""
    root = tmp_path_factory.mktemp("lean_export")
    overrides = replaced(TINY, "fit.max_steps=3", f'fit.shader="{SHADER}"')
    out, inputs = tiny_calibration(root, "lean", overrides, DEFAULT)
    return out, inputs, load_constants_json(out / "constants.json")


def _figures(res: dict) -> dict:
    return {k: res[k] for k in ("mean_abs", "p999", "max_abs", "unexplained", "n_water")}


def test_the_moments_ship_with_their_record(run):
    out, inputs, _ = run
    folder = out / "shaders" / "textures"
    record = json.loads((folder / "textures.json").read_text())
    rec = record["slope_moments"]
    assert rec["mipmaps"] is True and rec["wrap"] == "repeat"
    assert rec["bound_as"] == ["slopeMoments"]
    texels, _, _ = read_exr(folder / rec["file"])
    np.testing.assert_array_equal(texels, slope_moments(inputs.normal_map))
    sheets = "\n".join(p.read_text() for p in (out / "shaders").rglob("*.md"))
    assert "`slopeMoments` = `slope_moments.exr`" in sheets
    assert json.loads((out / "constants.json").read_text())["gl_check"]["passed"] is True


def test_the_wgsl_on_lavapipe_matches_the_port(run):
    from study.export.wgsl_run import WgslRenderer

    out, inputs, fitted = run
    try:
        r = WgslRenderer(out / "shaders", SHADER, inputs)
    except RuntimeError as exc:
        if "mesa-vulkan-drivers" in str(exc):
            pytest.skip(str(exc))
        raise
    with r:
        res = compare_port_gl(inputs, fitted, SHADER, renderer=r)
    assert res["n_water"] > 100 and passes(res), _figures(res)


def test_the_viewer_in_chromium_matches_the_port(run):
    from study.export.viewer.browser import BrowserRenderer, Chromium, open_viewer

    out, inputs, fitted = run
    with Chromium() as browser:
        assert open_viewer(browser, out / "viewer" / "index.html") == []
        res = compare_port_gl(inputs, fitted, SHADER, renderer=BrowserRenderer(browser))
    assert res["n_water"] > 100 and passes(res), _figures(res)
