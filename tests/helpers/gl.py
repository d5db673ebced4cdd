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


def user_gl_render_or_skip(shader, inputs, values=None, **how):
    """``UserShader.gl_render`` (RGBA (H, W, 4) float32, covered mask (H, W) bool; ``how``:
    ``as_written``, ``highp`` of ``shaders_port.spirv.gl_run.plan``), skipping the test where
    no headless OpenGL context can be made; any other failure raises."""
    pytest.importorskip("moderngl")
    try:
        return shader.gl_render(inputs, values, **how)
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


def assert_ran_as_written(check: dict, kind: str) -> None:
    """A user's shader's GL check (``gl_check_user``) ran the file as written on a context of
    ``kind`` (``shaders_port.gl.contexts.KINDS``) where this machine makes one, else its
    core-profile translation saying why; the record names the context."""
    from shaders_port.gl.contexts import KINDS
    from shaders_port.spirv.gl_run import context_support

    assert kind in KINDS
    words = {"es": "OpenGL ES 3.", "compatibility": "compatibility profile", "core": "core profile"}
    if context_support(kind)[0]:
        assert check["text"].startswith("your file as written"), check
        assert words[kind] in check["context"] and "why_translation" not in check, check
    else:
        assert check["text"] == "its core-profile translation (GLSL 330 core)", check
        assert "core profile" in check["context"] and check["why_translation"], check
