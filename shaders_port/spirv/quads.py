"""Pixel quads of the SPIR-V executor: screen-space derivatives as GL computes them.

GL runs a fragment shader on 2x2 pixel quads aligned at even window coordinates (window origin
at the bottom left) and takes a derivative as the difference with the quad neighbour. Measured
on Mesa llvmpipe (``tests/test_spirv_instructions.py``): ``dFdx``, ``dFdy`` and their ``Fine``
and ``Coarse`` forms are all the *fine* derivative, ``dFdx(v) = v(x1, y) - v(x0, y)`` in the
pixel's own row and ``dFdy(v) = v(x, y1) - v(x, y0)`` in its own column (the specification
allows a coarse derivative to be computed as the fine one); ``fwidth(v) = |dFdx(v)| +
|dFdy(v)|``. The level of detail of an implicit texture lookup is computed once per quad from
the quad's origin pixel ``(x0, y0)`` (:attr:`Quads.origin`, :attr:`Quads.right`,
:attr:`Quads.up`): llvmpipe's choice, measured likewise.

Helper invocations. A pixel of a quad that the primitive does not cover still runs the
shader, as a helper: its inputs are the primitive's interpolants extrapolated to its centre
(for the water quad, the plane point seen through that pixel, :func:`study_quad_bindings`;
for a user's vertex shader's triangles, the interpolants of the triangle whose fragments the
quad runs, evaluated on its plane equations, ``pipeline.interpolate.quad_helpers``).
The executor runs such lanes after the shaded ones (lanes ``shaded ..`` of a run) and keeps
only the shaded lanes' outputs and costs (:meth:`Quads.shaded_part`).

Non-uniform control flow. GL leaves a derivative undefined where the quad's pixels do not all
run it. The executor runs both sides of a selection on every lane (only stores are masked),
so a derivative inside an ``if`` is the difference of the values the neighbours compute in
that branch, as llvmpipe's SIMD lanes do; inside a loop whose trip count differs between
pixels the executor refuses it, naming the line (:class:`~spirv.loops.UnsupportedInstruction`).
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import numpy as np

from ..pipeline.interpolate import plane_points
from .ops import is_py

QUADS_KEY = "@quads"  # the bindings entry holding a frame's Quads (no GLSL name can be it)
DERIVATIVES = {
    "OpDPdx": "x",
    "OpDPdxFine": "x",
    "OpDPdxCoarse": "x",
    "OpDPdy": "y",
    "OpDPdyFine": "y",
    "OpDPdyCoarse": "y",
    "OpFwidth": "w",
    "OpFwidthFine": "w",
    "OpFwidthCoarse": "w",
}
_PER_LANE = ("varyingVecWorldPosition", "varyingVecEye", "varyingVecLight", "gl_FragCoord") + tuple(
    f"vTexCoord{k}" for k in range(4)
)


@dataclass
class Quads:
    """The quads of a run's lanes: ``shaded`` (int) lanes the shader runs for, then helper
    lanes; for every lane (UInt32 lane indices): ``x_lo``/``x_hi`` the left/right pixel of its
    row in its quad, ``y_lo``/``y_hi`` the lower/upper pixel of its column (window y),
    ``origin``/``right``/``up`` the quad's pixels ``(x0, y0)``, ``(x0 + 1, y0)``,
    ``(x0, y0 + 1)``; ``lanes``: the number of lanes."""

    shaded: int
    lanes: int
    x_lo: object
    x_hi: object
    y_lo: object
    y_hi: object
    origin: object
    right: object
    up: object

    def shaded_part(self, m, v):
        """The shaded lanes of a value (a scalar, a per-lane Dr.Jit value or a list)."""
        if isinstance(v, list):
            return [self.shaded_part(m, x) for x in v]
        if is_py(v) or not isinstance(v, dr.ArrayBase) or dr.width(v) != self.lanes:
            return v
        if self.shaded == self.lanes:
            return v
        return dr.gather(type(v), v, dr.arange(m.UInt32, self.shaded))


def helper_pixels(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pixels (window x, y int64) of the quads of the pixels ``(x, y)`` that are not among
    them: the helper invocations of a frame."""
    x0, y0 = x - (x & 1), y - (y & 1)
    have = set(zip(x.tolist(), y.tolist()))
    out = set()
    for a, b in set(zip(x0.tolist(), y0.tolist())):
        for p in ((a, b), (a + 1, b), (a, b + 1), (a + 1, b + 1)):
            if p not in have:
                out.add(p)
    hx = np.array(sorted(out), dtype=np.int64).reshape(-1, 2)
    return hx[:, 0], hx[:, 1]


def quads_of_pixels(m, x: np.ndarray, y: np.ndarray, shaded: int, group=None) -> Quads:
    """:class:`Quads` of lanes at window pixels ``(x, y)`` (int, every quad complete: the
    shaded pixels then their helpers). ``group`` (int, one per lane) tells the quad
    invocations apart where one quad runs more than once (one invocation per triangle that
    covers pixels of it, ``pipeline.interpolate.quad_helpers``); by default one per quad."""
    x, y = np.asarray(x, np.int64), np.asarray(y, np.int64)
    if group is None:
        _, group = np.unique(np.stack([x >> 1, y >> 1], 1), axis=0, return_inverse=True)
    group = np.asarray(group, np.int64).ravel()
    key = group * 4 + (x & 1) + 2 * (y & 1)
    order = np.argsort(key, kind="stable")
    sorted_keys = key[order]
    if np.any(sorted_keys[1:] == sorted_keys[:-1]):
        raise ValueError("a pixel of a quad invocation is given twice")

    def lane(dx, dy):
        k = group * 4 + dx + 2 * dy
        pos = np.clip(np.searchsorted(sorted_keys, k), 0, len(k) - 1)
        if not np.array_equal(sorted_keys[pos], k):
            raise ValueError("a quad of the frame's lanes is incomplete (a helper is missing)")
        return m.UInt32(order[pos].astype(np.uint32))

    sx, sy = x & 1, y & 1
    return Quads(
        shaded=int(shaded),
        lanes=len(x),
        x_lo=lane(0, sy),
        x_hi=lane(1, sy),
        y_lo=lane(sx, 0),
        y_hi=lane(sx, 1),
        origin=lane(0, 0),
        right=lane(1, 0),
        up=lane(0, 1),
    )


def _diff(m, quads: Quads, v, lo, hi):
    if is_py(v) or dr.width(v) != quads.lanes:
        return 0.0  # the same on every lane: no screen-space change
    v = m.Float(v)
    return dr.gather(m.Float, v, hi) - dr.gather(m.Float, v, lo)


def derivative(m, quads: Quads, v, axis: str):
    """``dFdx`` (axis 'x'), ``dFdy`` ('y') or ``fwidth`` ('w') of a scalar value, as
    llvmpipe computes them (module doc)."""
    if axis == "x":
        return _diff(m, quads, v, quads.x_lo, quads.x_hi)
    if axis == "y":
        return _diff(m, quads, v, quads.y_lo, quads.y_hi)
    dx, dy = derivative(m, quads, v, "x"), derivative(m, quads, v, "y")
    return abs(dx) + abs(dy) if is_py(dx) else dr.abs(dx) + dr.abs(dy)


def quad_gradients(m, quads: Quads, v):
    """(d/dx, d/dy) of a scalar value from the quad's origin pixel (the same for the quad's
    four pixels): what llvmpipe's implicit level of detail uses."""
    return _diff(m, quads, v, quads.origin, quads.right), _diff(m, quads, v, quads.origin, quads.up)


def uses_quads(module, bindings: dict) -> bool:
    """Whether a run of ``module`` needs its lanes' quads: it takes a derivative, or samples
    a mipmapped texture with an implicit level of detail."""
    ops = {i.opname for f in module.functions.values() for b in f.blocks.values() for i in b.body}
    if ops & set(DERIVATIVES):
        return True
    implicit = any("ImplicitLod" in op or op == "OpImageQueryLod" for op in ops)
    return implicit and any(getattr(v, "levels", ()) for v in bindings.values())


def study_quad_bindings(m, P, inputs, b: dict, up: str = "y") -> dict:
    """The study's bindings ``b`` (``spirv.translated.study_bindings`` of the prepared frame
    ``P``, in the world frame ``up``: 'z' gives the world-space varyings as ``(x, -z, y)``,
    as there) with the frame's helper lanes after its covered pixels, and the frame's
    :class:`Quads` under :data:`QUADS_KEY`."""
    r = P.raster
    col, row = r.index % r.width, r.index // r.width
    x, y = col, r.height - 1 - row
    hx, hy = helper_pixels(x, y)
    hcol, hrow = hx, r.height - 1 - hy
    world, _ = plane_points(inputs.view_proj, r.width, r.height, hcol, hrow)
    clip = np.c_[world, np.ones(len(hx))] @ inputs.view_proj.astype(np.float64).T
    base = world[:, [0, 2]] / inputs.normal_tile
    helper = {
        "varyingVecWorldPosition": world.T,
        "varyingVecEye": (inputs.viewpos.astype(np.float64) - world).T,
        "varyingVecLight": (inputs.lightpos.astype(np.float64) - world).T,
        "gl_FragCoord": np.stack(
            [hx + 0.5, hy + 0.5, 0.5 * clip[:, 2] / clip[:, 3] + 0.5, 1.0 / clip[:, 3]]
        ),
    }
    if up == "z":  # the world-space varyings in the Z-up frame the shaded lanes have
        for name in ("varyingVecWorldPosition", "varyingVecEye", "varyingVecLight"):
            x_, y_, z_ = helper[name]
            helper[name] = np.stack([x_, -z_, y_])
    for k in range(4):
        tc = base + inputs.waves[k].astype(np.float64)
        helper[f"vTexCoord{k}"] = np.stack(
            [tc[:, 0], tc[:, 1], np.zeros(len(hx)), np.ones(len(hx))]
        )
    out = dict(b)
    for name in _PER_LANE:
        if name not in b:
            continue
        comps = []
        for c, v in enumerate(b[name]):
            h = helper[name][c].astype(np.float32)
            if is_py(v):
                comps.append(
                    v
                    if np.all(h == np.float32(v))
                    else m.Float(np.r_[np.full(len(r.index), v, np.float32), h])
                )
            else:
                comps.append(dr.concat([m.Float(v), m.Float(h)]))  # on the device
        out[name] = comps
    out[QUADS_KEY] = quads_of_pixels(m, np.r_[x, hx], np.r_[y, hy], len(x))
    return out
