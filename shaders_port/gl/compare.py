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

On a GPU's own OpenGL (NVIDIA's driver; docs/where-it-runs.md, "The GL check on a GPU") the
texture units address and filter at a fixed sub-texel precision (8 fractional bits) where
llvmpipe computes in float32. On such an OpenGL (``gpu_addressing``: its ``GL_RENDERER`` is no
software rasteriser, :func:`is_gpu`) two more reasons, from the port's diagnostics of a render
with ``diagnose=True`` (the raycast ports), explain what is left after the four above:

* ``raymarch_texel_edge``: one of the raymarch's nearest-filtered depth lookups (the start and
  every step) lies within ``GPU_TEXEL_EDGE`` (1/512 texel: half a step of 8 sub-texel bits) of a
  texel edge, where the GPU may read the neighbouring depth texel;
* ``fresnel_texel_edge``: the Fresnel LUT's nearest lookup likewise.

Together these two may explain at most ``GPU_SHARE`` (0.1 %) of the water pixels; beyond that
none of their pixels counts as explained (``gpu_over_cap``).

Anything else over the threshold is ``unexplained``. ``outlier_pixels`` names each outlier
(up to ``MAX_NAMED``) with every reason that applies to it and, where the port gives it, the
highlight's slope there (``highlight_slope``: the colour's change per unit of the Phong cosine
``dot(rLight, vEye)``, ``ports.highlight.highlight_slope``; the gap over it is the cosine change
that would make the gap, which a GPU filtering the normal map at its own precision can cause: it
is recorded, never accepted as a reason).

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
# a GPU's texture unit converts a nearest lookup's texel coordinate to fixed point with 8 sub-texel
# bits: a coordinate within half a step (1/512 texel) of an edge may land in the neighbouring texel
# (on an H200 a lookup 3e-4 texels below an edge read the texel above; rounding the port's
# coordinates to 1/256 texel reproduces those pixels' colours to 3e-4)
GPU_TEXEL_EDGE = 2.0**-9
GPU_SHARE = 1e-3  # the GPU reasons explain at most this share of the water pixels
MAX_NAMED = 50  # outliers listed in ``outlier_pixels``


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
    gpu_addressing: bool = False,
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
    if output is None:  # the raycast ports' diagnostics for the reasons (colour bit-identical)
        kw = {"diagnose": True} if getattr(variant.port(), "GL_CHECK_DIAGNOSE", False) else {}
        out = variant.render(inputs, constants, **kw).numpy()
    else:
        out = output
    own = renderer is None
    if own:
        renderer = variant.gl_renderer(inputs)
    try:
        rgba, gl_mask = renderer.render(constants)
    finally:
        if own:
            renderer.release()
    port_mask = out["mask"] > 0.5
    gpu = gpu_reasons(out) if gpu_addressing else {}
    return compare_outputs(out, rgba, gl_mask, port_reasons(out, port_mask), gpu)


def port_reasons(out: dict, port_mask: np.ndarray) -> dict:
    """The reasons (module doc) the port's output ``out`` (``ShaderOutput.numpy()``) gives
    for an outlier, on the pixels of ``port_mask``: name -> (H, W) bool."""
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
    return reasons


def compare_outputs(out: dict, rgba: np.ndarray, gl_mask: np.ndarray, reasons: dict,
                    gpu: dict) -> dict:  # fmt: skip
    """The figures of :func:`compare_port_gl` for the port's ``out`` (``color`` (H, W, 3),
    ``mask`` (H, W)) against OpenGL's ``rgba`` (H, W, 4) and ``gl_mask`` (H, W) bool, the
    outliers explained by ``reasons`` and then ``gpu`` (name -> (H, W) bool each)."""
    port_mask = out["mask"] > 0.5
    both = port_mask & gl_mask
    diff = np.where(both, np.abs(out["color"] - rgba[..., :3]).max(-1), 0.0).astype(np.float32)
    d = diff[both]
    if d.size == 0:
        raise ValueError("the port and GL share no water pixel; check the camera and water_rect")
    outlier = both & ~(diff <= OUTLIER)  # NaN on either side counts as an outlier
    explained, left = explain_outliers(outlier, reasons, gpu, int(both.sum()))
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
        "outlier_pixels": name_outliers(outlier, diff, {**reasons, **gpu}, out),
        "diff": diff,
        "port": out["color"],
        "gl": rgba[..., :3],
    }


def gpu_reasons(out: dict) -> dict:
    """The GPU explanations (module doc) that the port's diagnostics in ``out`` allow: name ->
    (H, W) bool. Empty for a render without them (``diagnose`` off, the SPIR-V executor)."""
    why = {}
    if "raymarch_texel_edge" in out:
        why["raymarch_texel_edge"] = out["raymarch_texel_edge"] < GPU_TEXEL_EDGE
    if "fresnel_texel_edge" in out:
        why["fresnel_texel_edge"] = out["fresnel_texel_edge"] < GPU_TEXEL_EDGE
    return why


def is_gpu(gl_renderer: str | None) -> bool:
    """True for a ``GL_RENDERER`` that is no software rasteriser (Mesa's llvmpipe, softpipe,
    lavapipe or SwiftShader): a GPU's texture unit, with its fixed sub-texel precision."""
    if not gl_renderer:
        return False
    soft = ("llvmpipe", "softpipe", "lavapipe", "swiftshader")
    return not any(s in gl_renderer.lower() for s in soft)


def explain_outliers(outlier: np.ndarray, reasons: dict, gpu: dict, n_water: int):
    """``(explained, left)``: each reason of ``reasons`` in turn takes the outliers it covers
    (count in ``explained``); then the ``gpu`` reasons take what is left, as long as together
    they take no more than ``GPU_SHARE`` of the ``n_water`` pixels (else none of theirs counts
    and ``explained['gpu_over_cap']`` says how many they would have taken). ``left``: the
    unexplained outliers."""
    explained, left = {}, outlier.copy()
    for name, why in reasons.items():
        explained[name] = int((left & why).sum())
        left &= ~why
    if not gpu:
        return explained, left
    taken = np.zeros_like(left)
    counts = {}
    for name, why in gpu.items():
        counts[name] = int((left & ~taken & why).sum())
        taken |= left & why
    if int(taken.sum()) > GPU_SHARE * n_water:
        explained.update({name: 0 for name in gpu})
        explained["gpu_over_cap"] = int(taken.sum())
        return explained, left
    explained.update(counts)
    return explained, left & ~taken


def name_outliers(outlier: np.ndarray, diff: np.ndarray, reasons: dict, out: dict) -> list:
    """The outliers, largest first (at most ``MAX_NAMED``): ``y``, ``x``, ``diff``, ``why``
    (every reason of ``reasons`` that applies to the pixel; empty: none) and, where ``out``
    has it, ``highlight_slope`` there."""
    ys, xs = np.nonzero(outlier)
    order = np.argsort(-np.nan_to_num(diff[ys, xs], nan=np.inf), kind="stable")[:MAX_NAMED]
    slope = out.get("highlight_slope")
    named = []
    for i in order:
        y, x = int(ys[i]), int(xs[i])
        p = {"y": y, "x": x, "diff": float(diff[y, x]),
             "why": [name for name, w in reasons.items() if w[y, x]]}  # fmt: skip
        if slope is not None:
            p["highlight_slope"] = float(slope[y, x])
        named.append(p)
    return named
