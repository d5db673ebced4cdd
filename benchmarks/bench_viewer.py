"""Load time and frame time of a calibration's WebGL 2 viewer (``viewer/index.html``) in headless
Chromium on the software renderer (SwiftShader, ``--use-angle=swiftshader``), opened from
``file://`` as a user opens it.

Usage: .venv/bin/python benchmarks/bench_viewer.py [VIEWER_FOLDER] [--loads 5] [--frames 30]

VIEWER_FOLDER defaults to ``out/default/viewer`` (``make run`` writes it; ``study viewer OUT
EXPERIMENT`` writes one for an existing result). Prints the size of ``data.js``; per load
(a fresh tab each): the wall time from navigation to the load event, measured here, and the
page's own set-up time (``waterViewer.setup_ms``: decoding the base64 data, uploading the
textures, compiling and linking both shaders, the first frame); then milliseconds per frame of
the fitted shader into the float framebuffer (``waterViewer.timeFrames``: draw, then a one-pixel
read-back that waits for the renderer) at the study's camera and at an orbit, median and min.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from study.export.viewer.browser import Chromium, open_viewer  # noqa: E402


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", nargs="?", default="out/default/viewer")
    ap.add_argument("--loads", type=int, default=5, help="page loads timed")
    ap.add_argument("--frames", type=int, default=30, help="frames timed per camera")
    args = ap.parse_args(argv)
    index = Path(args.folder) / "index.html"
    if not index.is_file():
        sys.exit(f"bench_viewer: no viewer at {index}: run `make run` first, or pass a folder")
    data_mb = (index.parent / "data.js").stat().st_size / 2**20
    with Chromium() as b:
        loads, setups = [], []
        for _ in range(args.loads):
            t0 = time.perf_counter()
            open_viewer(b, index)
            loads.append((time.perf_counter() - t0) * 1e3)
            setups.append(b.evaluate("waterViewer.setup_ms"))
        size = b.evaluate("[0, 1].map((k) => [waterViewer.width, waterViewer.height][k])")
        renderer = b.evaluate(
            "(() => { const gl = document.getElementById('view').getContext('webgl2'); "
            "const e = gl.getExtension('WEBGL_debug_renderer_info'); "
            "return gl.getParameter(e ? e.UNMASKED_RENDERER_WEBGL : gl.RENDERER); })()"
        )
        frames = {}
        for label, orbit in (("study camera", None), ("orbit 60 deg", {"yaw": 60})):
            if orbit:
                b.evaluate(f"Object.assign(waterViewer.state, {json.dumps(orbit)})")
            frames[label] = b.evaluate(f"waterViewer.timeFrames({args.frames})")
    print(f"viewer: {index} ({size[0]}x{size[1]} pixels), data.js {data_mb:.1f} MiB")
    print(f"renderer: {renderer}")
    print(f"{'':<26} {'median ms':>10} {'min ms':>8}")
    print(f"{'load (navigate to load)':<26} {statistics.median(loads):10.1f} {min(loads):8.1f}")
    print(
        f"{'set-up (decode..1st frame)':<26} {statistics.median(setups):10.1f} {min(setups):8.1f}"
    )
    for label, t in frames.items():
        print(f"{'frame, ' + label:<26} {statistics.median(t):10.2f} {min(t):8.2f}")


if __name__ == "__main__":
    main()
