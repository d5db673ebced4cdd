"""A side-by-side figure kept as data: the panels it shows, so that the figure can be drawn again
from committed files (``scripts/build_docs.py``) rather than only by the run that rendered them.

For a figure ``<stem>.png`` two files sit beside it:

* ``<stem>.exr`` (``study._io.write_exr``): the first panel (the reference) as its RGB layer,
  every other panel as an (H, W, 3) layer ``panel_<k>`` (k = 1, 2, ...), and the water pixels
  scored as an (H, W) layer ``mask`` (1 on water, 0 elsewhere); float32 linear RGB, row 0 at the
  top, at the experiment's resolution;
* ``<stem>.json``: the figure's title and, in the figure's order, each panel's title, its layer
  and its FLIP and RMSE on the water pixels against the reference (absent for the reference).

:func:`panels_figure` draws ``<stem>.png`` from them with
:func:`study.report.calibration.comparison_figure`, the function the run itself draws it with.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .._io import read_exr, write_exr, write_json
from .calibration import comparison_figure


def write_panels(
    png: Path, images: dict, errors: dict, mask: np.ndarray, title: str = ""
) -> tuple[Path, Path]:
    """Write ``png``'s panels as data (see the module doc): ``images``: title -> (H, W, 3) linear
    RGB, the reference first; ``errors``: title -> {"flip", "rmse"} (floats); ``mask``: (H, W)
    bool. Returns (the EXR path, the JSON path)."""
    png = Path(png)
    names = list(images)
    layers = {f"panel_{k}": images[n] for k, n in enumerate(names[1:], start=1)}
    layers["mask"] = np.asarray(mask, dtype=np.float32)
    exr = write_exr(png.with_suffix(".exr"), images[names[0]], extra=layers)
    panels = []
    for k, n in enumerate(names):
        p = {"title": n, "layer": "RGB" if k == 0 else f"panel_{k}"}
        if n in errors:
            p.update(flip=float(errors[n]["flip"]), rmse=float(errors[n]["rmse"]))
        panels.append(p)
    meta = png.with_suffix(".json")
    write_json(meta, {"title": title, "figure": png.name, "panels": panels})
    return exr, meta


def read_panels(png: Path) -> tuple[dict, dict, np.ndarray, str]:
    """(images, errors, mask, title) of ``png`` from its ``.exr`` and ``.json`` (the arguments of
    :func:`write_panels`)."""
    png = Path(png)
    meta = json.loads(png.with_suffix(".json").read_text())
    rgb, _, extra = read_exr(png.with_suffix(".exr"))
    images, errors = {}, {}
    for p in meta["panels"]:
        images[p["title"]] = rgb if p["layer"] == "RGB" else extra[p["layer"]]
        if "flip" in p:
            errors[p["title"]] = {"flip": p["flip"], "rmse": p["rmse"]}
    return images, errors, extra["mask"] > 0.5, meta["title"]


def panels_figure(png: Path) -> Path:
    """Draw ``png`` from its panels' data (:func:`read_panels`)."""
    images, errors, mask, title = read_panels(png)
    return comparison_figure(Path(png), images, errors, mask, title=title)
