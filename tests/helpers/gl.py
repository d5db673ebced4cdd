"""The Dr.Jit port against the GLSL on OpenGL (Mesa llvmpipe, EGL): the comparison, skipped
where no headless OpenGL context can be made, and the thresholds every GL check uses.

On water pixels (covered by both): mean |diff| <= 1e-3 and 99.9th percentile <= 1e-2 in
linear RGB (max over channels); every pixel beyond 1e-2 must be explained by the port's
diagnostics (see shaders_port.gl.compare) and their number stays below 0.1 % of the water."""

from __future__ import annotations

import pytest

from helpers.images import save_comparison


def compare_or_skip(inputs, constants, shader, **kw) -> dict:
    """``compare_port_gl``, skipping the test where no headless OpenGL context can be made."""
    pytest.importorskip("shaders_port.gl.renderer")
    from shaders_port.gl.compare import compare_port_gl

    try:
        return compare_port_gl(inputs, constants, shader, **kw)
    except RuntimeError as exc:
        if "EGL" in str(exc) or "context" in str(exc).lower():
            pytest.skip(f"no headless OpenGL here: {exc}")
        raise


def user_gl_render_or_skip(shader, inputs, values=None):
    """``UserShader.gl_render`` (RGBA (H, W, 4) float32, covered mask (H, W) bool), skipping
    the test where no headless OpenGL context can be made; any other failure raises."""
    pytest.importorskip("moderngl")
    try:
        return shader.gl_render(inputs, values)
    except RuntimeError as exc:
        if "EGL" in str(exc) or "context" in str(exc).lower():
            pytest.skip(f"no headless OpenGL here: {exc}")
        raise


def check_gl_match(res: dict, tag: str) -> None:
    """Assert the thresholds on a ``compare_port_gl`` result; images to tests/_failures/ first
    when one fails."""
    ok = (
        res["mean_abs"] <= 1e-3
        and res["p999"] <= 1e-2
        and res["unexplained"] == 0
        and res["n_outliers"] <= 1e-3 * res["n_water"]
    )
    if not ok:
        save_comparison(tag, res["port"], res["gl"])
    assert res["n_water"] > 500
    assert res["mask_mismatch"] <= 0.01 * res["n_water"], res["mask_mismatch"]
    assert res["mean_abs"] <= 1e-3, res["mean_abs"]
    assert res["p999"] <= 1e-2, res["p999"]
    assert res["unexplained"] == 0, f"{res['unexplained']} pixels over 1e-2 not explained"
    assert res["n_outliers"] <= 1e-3 * res["n_water"], (res["n_outliers"], res["explained"])
