"""The exported core shader run on llvmpipe (Mesa, headless EGL) against the Dr.Jit port."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np


def gl_check(shader: str, inputs, constants, shaders_dir: Path) -> dict:
    """Run the exported core file of variant ``shader``, ``core/<shader>.frag``, exactly as
    written (its own constants block and ``#define`` lines, nothing added) on llvmpipe and
    compare it with the port of the variant with ``constants`` on the water pixels. Returns the
    figures of ``compare_port_gl`` and ``passed``."""
    from shaders_port._compare import compare_port_gl
    from shaders_port._gl import GLRenderer
    from shaders_port._variants import get_variant

    variant = get_variant(shader)
    source = (shaders_dir / "core" / f"{variant.name}.frag").read_text()
    with GLRenderer(variant.shader, variant.prepare_inputs(inputs), source=source) as r:
        res = compare_port_gl(inputs, constants, shader, renderer=_OwnBlock(r))
    out = {
        k: res[k]
        for k in (
            "mean_abs",
            "p999",
            "max_abs",
            "n_water",
            "n_outliers",
            "n_nonfinite",
            "unexplained",
        )
    }
    out["passed"] = bool(
        np.isfinite(res["mean_abs"])
        and res["mean_abs"] <= 1e-3
        and res["p999"] <= 1e-2
        and res["unexplained"] == 0
        and res["n_nonfinite"] == 0
    )
    if not out["passed"]:
        print(
            f"calibrate: WARNING: the exported shader on llvmpipe does not match the port: {out}",
            file=sys.stderr,
        )
    return out


class _OwnBlock:
    """A GLRenderer view whose render() ignores the constants (uses the exported block)."""

    def __init__(self, r):
        self.r = r

    def render(self, constants):
        return self.r.render(None)
