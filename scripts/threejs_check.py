"""The three.js module of a calibration run in headless Chromium, measured for docs/threejs.md:
``docs/results/threejs/check.json`` and ``example.png`` (the example page's canvas).

    .venv/bin/python scripts/threejs_check.py [OUT] [EXPERIMENT]     # default: out/default

``OUT`` is a calibration's folder (``make run`` writes ``out/default``), ``EXPERIMENT`` the
experiment it was calibrated on. Measured, on the study's camera at clock time 0:

* ``study_inputs``: three's render of the calibrated material on the study's own images against
  the Dr.Jit port (``compare_port_gl``: mean and 99.9th percentile of the per-pixel max-over-
  channel |difference|, outliers the port's diagnostics do not explain), at the fitted and at
  the start constants, drawn on the screen's quad (``screen_plane``, as the viewer draws) and
  on the water's own quad (``water_quad``: SwiftShader snaps its vertices to 1/16 pixel);
* ``scene_inputs``: the water fed by the inputs water.js builds from the example's three.js
  scene against the water fed by the study's images: FLIP and mean / max |difference| on the
  water pixels.
"""

from __future__ import annotations

import base64
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "scripts"))

from export_run_check import calibration, record_head, verdict  # noqa: E402
from shaders_port.gl.compare import compare_port_gl  # noqa: E402
from study._io import write_json  # noqa: E402
from study._metrics import flip  # noqa: E402
from study.export.threejs import three_version  # noqa: E402
from study.export.viewer.browser import (  # noqa: E402
    FILE_ACCESS,
    SOFTWARE_GL,
    BrowserRenderer,
    Chromium,
    open_three_example,
    render_float,
)

RESULTS = REPO / "docs" / "results" / "threejs"


def _screenshot(browser: Chromium, path: Path) -> None:
    """The page's canvas as drawn (sRGB), at its own pixel size."""
    browser.evaluate(
        "(() => { const c = document.getElementById('view'); c.style.width = c.width + 'px'; "
        "return true; })()"
    )
    rect = browser.evaluate(
        "(() => { const r = document.getElementById('view').getBoundingClientRect(); "
        "return {x: r.x, y: r.y, width: r.width, height: r.height}; })()"
    )
    shot = browser.send(
        "Page.captureScreenshot",
        {"format": "png", "clip": {**rect, "scale": 1}},
        session=browser.session,
    )
    path.write_bytes(base64.b64decode(shot["data"]))


def main(out="out/default", experiment="experiments/default.toml") -> dict:
    out = Path(out)
    inputs, summary, constants = calibration(out, experiment)
    record = {
        **record_head("threejs_check.py", out, experiment, summary, inputs),
        "three": three_version(),
        "browser": "headless Chromium, WebGL 2 on SwiftShader",
        "study_inputs": {},
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    with Chromium(flags=SOFTWARE_GL + FILE_ACCESS) as b:
        open_three_example(b, out / "threejs" / "example.html")
        for geometry, plane in (("screen_plane", True), ("water_quad", False)):
            for which, c in constants.items():
                r = BrowserRenderer(b, which, api="waterThree", inputs="study", screenPlane=plane)
                res = compare_port_gl(inputs, c, summary["shader"], renderer=r)
                record["study_inputs"][f"{geometry}_{which}"] = verdict(res)
        study, mask = render_float(b, "waterThree", inputs="study")
        scene, _ = render_float(b, "waterThree", inputs="scene")
        d = np.abs(study - scene)[mask][:, :3]
        record["scene_inputs"] = {
            "flip": float(flip(study[..., :3], scene[..., :3], mask)),
            "mean_abs": float(d.mean()),
            "max_abs": float(d.max()),
            "n_water": int(mask.sum()),
        }
        _screenshot(b, RESULTS / "example.png")
    write_json(RESULTS / "check.json", record)
    print(json.dumps(record, indent=1))
    return record


if __name__ == "__main__":
    main(*sys.argv[1:])
