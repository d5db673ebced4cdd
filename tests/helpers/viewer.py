"""A viewer page of a user's shader without a calibration (no reference, no port images): its
GLSL ES 3.00 export and what the GL check binds for it, for tests of ``viewer/`` in Chromium."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from study.export.shaders import export_user_shader
from study.export.viewer import viewer_data, write_viewer
from study.export.viewer.user import user_parts

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
              "fov_y": 45.0, "near": 0.05, "far": 100.0, "orbit": False, "pitch_deg": 30.0}  # fmt: skip
    images = {"scored": np.ones((inputs.height, inputs.width), np.float32)}
    data = viewer_data(inputs, parts["vert"], parts["frag"], parts["frag_default"], images,
                       camera, {"velocities": [list(v) for v in velocities]})  # fmt: skip
    data["textures"], data["bound"] = {}, parts["bound"]
    page = {**_PAGE, "title": shader.label, "inputs": parts["names"], "camera_note": "fixed"}
    return write_viewer(folder / "viewer", data, page), parts["bound"]
