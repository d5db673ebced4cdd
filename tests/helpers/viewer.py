"""A viewer page of a user's shader without a calibration (no reference, no port images): its
GLSL ES 3.00 export and what the GL check binds for it, for tests of ``viewer/`` in Chromium;
and a tiny calibration with the inputs its exports are checked on (the viewer's and the
three.js page's tests)."""

from __future__ import annotations

from collections import OrderedDict
from pathlib import Path

import numpy as np

from shaders_port.spirv import user_vertex
from study.calibration.frames import prepare
from study.cli import main
from study.export.textures import with_exported_textures
from study.scene.baseline_inputs import inputs_for_shader
from study.scene.shader_inputs import load_or_build_shader_inputs
from study.export.shaders import export_user_shader
from study.export.viewer import viewer_data, write_viewer
from study.export.viewer.user import user_parts

from .experiments import DEFAULT, sets


def tiny_calibration(root: Path, name: str, overrides: list[str], experiment=DEFAULT):
    """A calibration of ``experiment`` with ``overrides`` (a tiny one: the tests' TINY) into
    ``root/name`` (cache ``root/cache``) and its shader inputs as the GL check runs them (with
    the exported textures)."""
    import pytest

    out = root / name
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("STUDY_CACHE", str(root / "cache"))
        assert main(["calibrate", str(experiment), "--out", str(out)] + sets(overrides)) == 0
        exp, variant, _ = prepare(experiment, out, overrides)
        i = load_or_build_shader_inputs(exp, variant, log=lambda *a: None)
        i = inputs_for_shader(exp, i, exp.fit.shader, variant, log=lambda *a: None)
    return out, with_exported_textures(i, out / "shaders")


# the page's fields (page.html) the tests do not read
_PAGE = {"options": '<option value="live_fitted">live</option>'
         '<option value="live_default">start</option>',
         "flip_default": "-", "flip_fitted": "-", "rmse_default": "-", "rmse_fitted": "-",
         "time_max": "20", "pitch_deg": "30", "orbit_drag": "", "velocities": "",
         "provenance": "tests/helpers/viewer.py"}  # fmt: skip


def shader_viewer(folder: Path, shader, inputs, values: dict | None = None,
                  velocities=((0.01, 0.02),) * 4) -> tuple[Path, dict]:  # fmt: skip
    """``folder/viewer/index.html`` drawing ``shader`` (``UserShader``) on ``inputs`` with
    ``values`` (default: its start values; the page's 'default' constants are the start
    values), exported into ``folder/shaders``; returns it and the ``bound`` data."""
    values = shader.defaults() if values is None else values
    export_user_shader(shader, values, folder / "shaders", targets=("gles300",))
    parts = user_parts(shader, folder / "shaders", inputs, values, shader.defaults())
    camera = {"position": [float(v) for v in inputs.viewpos], "target": [0.0, 0.0, 0.0],
              "fov_y": 45.0, "near": 0.05, "far": 100.0, "orbit": False,
              "pitch_deg": 30.0}  # fmt: skip
    images = {"scored": np.ones((inputs.height, inputs.width), np.float32)}
    data = viewer_data(inputs, parts["vert"], parts["frag"], parts["frag_default"], images,
                       camera, {"velocities": [list(v) for v in velocities]})  # fmt: skip
    data["textures"], data["bound"] = {}, parts["bound"]
    page = {**_PAGE, "title": shader.label, "inputs": parts["names"], "camera_note": "fixed"}
    return write_viewer(folder / "viewer", data, page), parts["bound"]


def swiftshader_snapping(monkeypatch) -> None:
    """From now on in the test, the executor rasterises a user's vertex shader's triangles
    (``spirv.user_vertex``) from window positions rounded to 1/16 pixel, as SwiftShader (WebGL
    2 in headless Chromium) snaps vertices (4 sub-pixel bits; llvmpipe keeps 8): the same
    coverage and barycentric weights, every vertex output as before. Frames rendered before
    are kept apart (the frame cache is a fresh one)."""
    raster = user_vertex.rasterize_triangles

    def snapped(clip, triangles, width, height):
        c = np.array(clip, np.float64)
        size = np.array([width, height], np.float64)
        window = np.round((c[:, :2] / c[:, 3:4] * 0.5 + 0.5) * size * 16.0) / 16.0
        c[:, :2] = (window / size * 2.0 - 1.0) * c[:, 3:4]
        return raster(c, triangles, width, height)

    monkeypatch.setattr(user_vertex, "rasterize_triangles", snapped)
    monkeypatch.setattr(user_vertex, "_FRAMES", OrderedDict())


def smooth_sky(size: int = 16) -> np.ndarray:
    """(6, F, F, 3) float32 cube map (GL face order, GL upload order) of a sky continuous across
    its faces: colour ``0.5 + 0.4 d`` of the texel's direction ``d``. WebGL 2 always filters a
    cube map across its faces (seamless), the executor and the GL check within a face: on a sky
    continuous at the seams they differ by the bilinear error of a smooth function only."""
    c = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    s, t = np.meshgrid(c, c)  # s along a row, t down the rows
    one = np.ones_like(s)
    faces = [(one, -t, -s), (-one, -t, s), (s, one, t), (s, -one, -t), (s, -t, one), (-s, -t, -one)]
    d = np.stack([np.stack(f, -1) for f in faces])
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return (0.5 + 0.4 * d).astype(np.float32)
