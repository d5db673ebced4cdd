"""Differential check: the Dr.Jit port against the GLSL run on a real OpenGL (llvmpipe).

:func:`compare_port_gl` renders one shader both ways on the same :class:`ShaderInputs` and
constants and measures the colour difference on water pixels (pixels both the port and GL
cover). Pixels beyond ``OUTLIER`` (1e-2 linear RGB, max over channels) must be explained by
the port's diagnostics, i.e. lie next to a decision of the shader that float rounding can
flip:

* ``tiny_denominator``: ``diagnostics['denominator'] < 1e-3`` (the crossing interpolation
  divides by a near-zero number, so rounding of the inputs is amplified);
* ``reflection_decision``: (water_reflection and the screen-space reflection) the reflection
  ray's hit / no-hit or its hit step differs between neighbouring pixels (an edge of the
  geometry above the water);
* ``crossing_step_edge``: the refraction crossing step, or the path of a refinement's
  decisions, differs from a 4-neighbour's (a step-schedule discontinuity passes through the
  pixel);
* ``nearest_texel_edge``: a refinement's depth lookup (nearest-filtered) lies within
  ``TEXEL_EDGE`` texels of a texel edge, where the GPU's texel addressing may read the
  neighbouring texel.

Anything else over the threshold is ``unexplained``.

On llvmpipe (Mesa, float32 textures) float textures are filtered with float weights (no 8-bit
sub-texel quantisation), so what remains between the port and GL is float32 rounding of the
rasteriser's interpolation and of the texture-coordinate arithmetic.
"""

from __future__ import annotations

import numpy as np

from ..inputs import Constants, ShaderInputs
from ..variants import get_variant

OUTLIER = 1e-2
# how near (texels) a nearest-filtered lookup may come to a texel edge before the two sides may
# read different texels (float32 texel coordinates of a few hundred texels round at ~1e-5)
TEXEL_EDGE = 1e-3


def _neighbour_differs(a: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(H, W) bool: some valid 4-neighbour of a valid pixel has a different value of ``a``."""
    out = np.zeros(a.shape, bool)
    for axis in (0, 1):
        for shift in (1, -1):
            b = np.roll(a, shift, axis)
            vb = np.roll(valid, shift, axis)
            edge = np.zeros(a.shape, bool)
            if axis == 0:
                edge[0 if shift == 1 else -1, :] = True
            else:
                edge[:, 0 if shift == 1 else -1] = True
            out |= valid & vb & ~edge & (a != b)
    return out


def compare_port_gl(
    inputs: ShaderInputs,
    constants: Constants | None,
    shader: str,
    *,
    renderer=None,
    output: dict | None = None,
) -> dict:
    """Render ``shader`` with the port (LLVM) and with the core GLSL on OpenGL and compare.

    Args:
        inputs, constants: the frame (constants None = defaults).
        shader: a shader variant name (``shaders_port.variants.VARIANTS``).
        renderer: an open ``GLRenderer`` for these inputs to reuse (else one is made).
        output: the ``ShaderOutput.numpy()`` dict to compare in place of the port's (e.g. the
            SPIR-V executor's, ``shaders_port.spirv.translated``); None renders the port.

    Returns a dict: ``mean_abs`` and ``p999`` (99.9th percentile) and ``max_abs`` of the
    per-pixel max-over-channel |port - GL| on common water pixels (linear RGB);
    ``n_water``; ``mask_mismatch`` (pixels covered by exactly one side); ``n_outliers``
    (pixels over 1e-2); ``explained`` dict reason -> count; ``unexplained`` count;
    ``diff`` (H, W) float32 map (0 off the common water pixels); ``port`` / ``gl`` colours.
    """
    variant = get_variant(shader)
    constants = constants if constants is not None else Constants()
    out = variant.render(inputs, constants).numpy() if output is None else output
    own = renderer is None
    if own:
        renderer = variant.gl_renderer(inputs)
    try:
        rgba, gl_mask = renderer.render(constants)
    finally:
        if own:
            renderer.release()
    port_mask = out["mask"] > 0.5
    both = port_mask & gl_mask
    diff = np.where(both, np.abs(out["color"] - rgba[..., :3]).max(-1), 0.0).astype(np.float32)
    d = diff[both]
    if d.size == 0:
        raise ValueError("the port and GL share no water pixel; check the camera and water_rect")
    outlier = both & ~(diff <= OUTLIER)  # NaN on either side counts as an outlier
    reasons = {"crossing_step_edge": _neighbour_differs(out["iterations"], port_mask)}
    if "refine_path" in out:  # the refinement's decisions, as the linear search's steps
        reasons["crossing_step_edge"] |= _neighbour_differs(out["refine_path"], port_mask)
        reasons["nearest_texel_edge"] = out["refine_texel_edge"] < TEXEL_EDGE
    if "denominator" in out:  # the raycast shaders' crossing interpolation
        reasons["tiny_denominator"] = out["denominator"] < 1e-3
    if "refl_hit" in out:
        reasons["reflection_decision"] = _neighbour_differs(
            out["refl_hit"], port_mask
        ) | _neighbour_differs(out["refl_iterations"], port_mask)
    explained, left = {}, outlier.copy()
    for name, why in reasons.items():
        explained[name] = int((left & why).sum())
        left &= ~why
    return {
        "mean_abs": float(d.mean()),
        "p999": float(np.percentile(d, 99.9)),
        "max_abs": float(d.max()),
        "n_water": int(both.sum()),
        "mask_mismatch": int((port_mask ^ gl_mask).sum()),
        "n_outliers": int(outlier.sum()),
        "n_nonfinite": int((both & ~np.isfinite(diff)).sum()),
        "explained": explained,
        "unexplained": int(left.sum()),
        "diff": diff,
        "port": out["color"],
        "gl": rgba[..., :3],
    }
