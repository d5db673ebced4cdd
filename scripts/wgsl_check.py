"""The WGSL export of a calibration run with wgpu on Mesa's lavapipe against the Dr.Jit port,
measured for docs/webgpu.md: ``docs/results/wgsl/check.json`` and ``wgsl_vs_port.png`` (the WGSL
render at the fitted constants | the port's | their difference, x100).

    .venv/bin/python scripts/wgsl_check.py [OUT] [EXPERIMENT]     # default: out/default

``OUT`` is a calibration's folder (``make run`` writes ``out/default``), ``EXPERIMENT`` the
experiment it was calibrated on. Its constants are exported again (``study export``, targets
``spirv`` and ``wgsl``) into a temporary folder and drawn on the study's camera at clock time
0: at the file's own constants (the fitted ones, the ``override`` defaults), and at the start
constants set through the overrides at pipeline creation. Figures as the GL check's
(``compare_port_gl``): mean and 99.9th percentile of the per-pixel max-over-channel
|difference| on the water pixels, outliers the port's diagnostics do not explain.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "scripts"))

from export_run_check import calibration, record_head, verdict  # noqa: E402
from shaders_port.gl.compare import compare_port_gl  # noqa: E402
from study._io import write_json, write_png  # noqa: E402
from study.export.shaders import export_shaders  # noqa: E402
from study.export.wgsl_run import WgslRenderer, _lavapipe_adapter  # noqa: E402

RESULTS = REPO / "docs" / "results" / "wgsl"


def _adapter_name() -> str:
    info = _lavapipe_adapter().info
    return f"{info['device']} ({info['backend_type']}), {info.get('description', '')}".strip(", ")


def _render_png(res: dict, path: Path) -> None:
    """``res``'s WGSL render | the port's | |difference| x 100 (grey), side by side, sRGB."""
    diff = np.repeat(np.minimum(res["diff"] * 100.0, 1.0)[..., None], 3, axis=-1)
    gap = np.ones((res["gl"].shape[0], 4, 3))
    path.parent.mkdir(parents=True, exist_ok=True)
    write_png(path, np.concatenate([res["gl"], gap, res["port"], gap, diff], axis=1))


def main(out="out/default", experiment="experiments/default.toml") -> dict:
    out = Path(out)
    inputs, summary, constants = calibration(out, experiment)
    shader, fitted, start = summary["shader"], constants["fitted"], constants["default"]
    record = record_head("wgsl_check.py", out, experiment, summary, inputs)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "shaders"
        t0 = time.perf_counter()
        export_shaders(fitted, folder, [shader], targets=["spirv", "wgsl"])
        record["export_s"] = round(time.perf_counter() - t0, 2)
        record["adapter"] = _adapter_name()
        for name, constants, overrides in (("file_constants", fitted, False),
                                           ("start_by_overrides", start, True)):  # fmt: skip
            with WgslRenderer(folder, shader, inputs, overrides=overrides) as r:
                res = compare_port_gl(inputs, constants, shader, renderer=r)
            record[name] = verdict(res)
            if name == "file_constants":
                _render_png(res, RESULTS / "wgsl_vs_port.png")
    RESULTS.mkdir(parents=True, exist_ok=True)
    write_json(RESULTS / "check.json", record)
    print(json.dumps(record, indent=1))
    return record


if __name__ == "__main__":
    main(*sys.argv[1:])
