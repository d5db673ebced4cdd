"""Triangles rasterised as OpenGL does, for a user's own vertex shader: which triangle of a
tessellated water grid each pixel sees, and the barycentric weights that interpolate the
vertex shader's outputs there.

:func:`water_grid` tessellates the water quad (``ShaderInputs.water_rect`` on ``y = 0``) into
``nx x nz`` cells of two triangles each. :func:`rasterize_triangles` takes the clip-space
positions the vertex shader wrote (``gl_Position``, one per vertex) and, in float64:

* clips each triangle against the near and far planes (``-w <= z <= w``), as GL does; a
  vertex made by clipping carries its clip-space weights over the original triangle's vertices
  (for perspective-correct and flat outputs) and its window-space weights (for
  ``noperspective`` ones), so every output is interpolated over the triangle the shader made;
* maps to window coordinates (viewport = the image, depth range [0, 1]); coverage is decided on
  positions snapped to 1/256 pixel (llvmpipe's 8 bits of sub-pixel precision), the weights
  from the unsnapped ones (as llvmpipe sets up its attribute planes);
* covers a pixel whose centre ``(c + 0.5, H - r - 0.5)`` lies inside the triangle (either
  winding: no face culling), a centre on an edge going down or along the top of a
  counter-clockwise triangle included (one of the two triangles sharing the edge gets it);
* keeps per pixel the nearest fragment (depth test ``GL_LESS``, depth cleared to 1; of equal
  depths the triangle drawn first).

Perspective-correct weights are ``(l_i / w_i) / sum_j (l_j / w_j)`` of the window-space
(linear) weights ``l_i``; ``flat`` outputs take the provoking vertex, GL's default last vertex
of the triangle (``triangles[t, 2]``). Pixels no triangle covers are not water pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Grid", "Coverage", "water_grid", "rasterize_triangles", "interpolate"]

SUBPIXEL = 256.0  # window positions snapped to 1/SUBPIXEL pixel


@dataclass
class Grid:
    """A tessellated water quad: ``position`` (V, 3) float32 world units (y = 0), ``uv`` (V, 2)
    float32 ``(x, z) / normal_tile``, ``triangles`` (T, 3) int32 vertex indices in drawing
    order (the last of each its provoking vertex)."""

    position: np.ndarray
    uv: np.ndarray
    triangles: np.ndarray


def water_grid(rect, normal_tile: float, cells: tuple[int, int]) -> Grid:
    """``cells = (nx, nz)`` cells over ``rect = (x0, z0, x1, z1)``; vertex ``(i, k)`` (``i``
    along x) has index ``k * (nx + 1) + i``; cell ``(i, k)`` is the triangles ``(a, c, b)`` and
    ``(b, c, d)`` of its corners ``a = (i, k)``, ``b = (i + 1, k)``, ``c = (i, k + 1)``,
    ``d = (i + 1, k + 1)``."""
    nx, nz = (int(n) for n in cells)
    if nx < 1 or nz < 1:
        raise ValueError(f"the water grid needs at least 1 x 1 cells, got {nx} x {nz}")
    x0, z0, x1, z1 = (float(v) for v in rect)
    xs = x0 + (x1 - x0) * np.arange(nx + 1) / nx
    zs = z0 + (z1 - z0) * np.arange(nz + 1) / nz
    X, Z = np.meshgrid(xs, zs)
    pos = np.stack([X.ravel(), np.zeros(X.size), Z.ravel()], 1)
    i, k = np.meshgrid(np.arange(nx), np.arange(nz))
    a = (k * (nx + 1) + i).ravel()
    b, c = a + 1, a + nx + 1
    d = c + 1
    tris = np.stack([np.stack([a, c, b], 1), np.stack([b, c, d], 1)], 1).reshape(-1, 3)
    return Grid(
        position=pos.astype(np.float32),
        uv=(pos[:, [0, 2]] / float(normal_tile)).astype(np.float32),
        triangles=tris.astype(np.int32),
    )


@dataclass
class Coverage:
    """The pixels a triangle mesh covers, in raster order (row 0 at the top).

    Attributes:
        mask: (H, W) bool.
        index: (N,) int64 flat pixel indices ``r * W + c`` of the covered pixels.
        triangle: (N,) int64 the original triangle each pixel sees.
        smooth: (N, 3) float64 perspective-correct weights of its three vertices.
        linear: (N, 3) float64 window-space weights (``noperspective``).
        depth: (N,) float64 window depth in [0, 1] (``gl_FragCoord.z``).
        inv_w: (N,) float64 ``1 / w_clip`` (``gl_FragCoord.w``).
        front: (N,) bool counter-clockwise in window coordinates (``gl_FrontFacing``).
    """

    mask: np.ndarray
    index: np.ndarray
    triangle: np.ndarray
    smooth: np.ndarray
    linear: np.ndarray
    depth: np.ndarray
    inv_w: np.ndarray
    front: np.ndarray


def _clip_polygon(verts, smooth, plane):
    """Sutherland-Hodgman of one polygon (list of clip-space 4-vectors, with their weights over
    the original triangle) against ``plane(v) >= 0``."""
    out_v, out_s = [], []
    n = len(verts)
    for j in range(n):
        a, b = verts[j], verts[(j + 1) % n]
        sa, sb = smooth[j], smooth[(j + 1) % n]
        da, db = plane(a), plane(b)
        if da >= 0:
            out_v.append(a)
            out_s.append(sa)
        if (da >= 0) != (db >= 0):
            t = da / (da - db)
            out_v.append(a + t * (b - a))
            out_s.append(sa + t * (sb - sa))
    return out_v, out_s


def _clipped(clip: np.ndarray, triangles: np.ndarray):
    """Sub-triangles after near/far clipping: (verts (S, 3, 4), smooth weights (S, 3, 3),
    linear weights (S, 3, 3), parent (S,), order within the parent (S,))."""
    V = clip[triangles]  # (T, 3, 4)
    near = V[..., 2] + V[..., 3]
    far = V[..., 3] - V[..., 2]
    inside = (near >= 0).all(1) & (far >= 0).all(1)
    gone = (near < 0).all(1) | (far < 0).all(1)
    eye = np.broadcast_to(np.eye(3), (int(inside.sum()), 3, 3))
    verts, smooth = [V[inside]], [eye]
    parent, order = [np.flatnonzero(inside)], [np.zeros(int(inside.sum()), np.int64)]
    for t in np.flatnonzero(~inside & ~gone):
        poly, w = list(V[t]), list(np.eye(3))
        for plane in (lambda v: v[2] + v[3], lambda v: v[3] - v[2]):
            poly, w = _clip_polygon(poly, w, plane)
        for j in range(1, len(poly) - 1):
            verts.append(np.array([[poly[0], poly[j], poly[j + 1]]]))
            smooth.append(np.array([[w[0], w[j], w[j + 1]]]))
            parent.append(np.array([t]))
            order.append(np.array([j]))
    verts, smooth = np.concatenate(verts), np.concatenate(smooth)
    # window-space weights of each (clipped) vertex over the original triangle's projections
    wo = V[np.concatenate(parent)][..., 3]  # (S, 3) original w
    lin = smooth * wo[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        lin = lin / lin.sum(-1, keepdims=True)
    return verts, smooth, lin, np.concatenate(parent), np.concatenate(order)


def _pairs(lo_x, hi_x, lo_y, hi_y):
    """(sub-triangle, pixel column, window row) of every pixel in each bounding box."""
    nx = np.maximum(hi_x - lo_x + 1, 0)
    ny = np.maximum(hi_y - lo_y + 1, 0)
    count = nx * ny
    s = np.repeat(np.arange(len(count)), count)
    start = np.cumsum(count) - count
    k = np.arange(int(count.sum())) - start[s]
    return s, lo_x[s] + k % nx[s], lo_y[s] + k // np.maximum(nx[s], 1)


def _edge(ax, ay, bx, by, px, py):
    return (bx - ax) * (py - ay) - (by - ay) * (px - ax)


def rasterize_triangles(clip: np.ndarray, triangles: np.ndarray, width: int, height: int):
    """:class:`Coverage` of the triangles ``triangles`` (T, 3) over vertices at clip-space
    positions ``clip`` (V, 4) on a ``width x height`` image (see the module doc)."""
    clip = np.asarray(clip, np.float64)
    verts, smooth, lin, parent, order = _clipped(clip, np.asarray(triangles, np.int64))
    w = verts[..., 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        fx = (verts[..., 0] / w + 1.0) * 0.5 * width
        fy = (verts[..., 1] / w + 1.0) * 0.5 * height
        zw = (verts[..., 2] / w + 1.0) * 0.5
    xw, yw = np.round(fx * SUBPIXEL) / SUBPIXEL, np.round(fy * SUBPIXEL) / SUBPIXEL
    area = _edge(xw[:, 0], yw[:, 0], xw[:, 1], yw[:, 1], xw[:, 2], yw[:, 2])
    ok = np.isfinite(area) & (area != 0) & (w > 0).all(1)
    big = float(max(width, height) + 2)
    lo_x = np.ceil(np.clip(xw.min(1), -2, big) - 0.5).astype(np.int64).clip(0, width - 1)
    hi_x = np.floor(np.clip(xw.max(1), -2, big) - 0.5).astype(np.int64).clip(-1, width - 1)
    lo_y = np.ceil(np.clip(yw.min(1), -2, big) - 0.5).astype(np.int64).clip(0, height - 1)
    hi_y = np.floor(np.clip(yw.max(1), -2, big) - 0.5).astype(np.int64).clip(-1, height - 1)
    hi_x[~ok] = -1
    s, px, py = _pairs(lo_x, hi_x, lo_y, hi_y)
    cx, cy = px + 0.5, py + 0.5
    sign = np.sign(area)[s]
    X, Y = xw[s], yw[s]
    inside = np.ones(len(s), bool)
    for i in range(3):
        a, b = (i + 1) % 3, (i + 2) % 3
        e = sign * _edge(X[:, a], Y[:, a], X[:, b], Y[:, b], cx, cy)
        dx, dy = sign * (X[:, b] - X[:, a]), sign * (Y[:, b] - Y[:, a])
        top_left = (dy < 0) | ((dy == 0) & (dx < 0))
        inside &= (e > 0) | ((e == 0) & top_left)
    s, px, py = s[inside], px[inside], py[inside]
    # the weights from the unsnapped positions, as llvmpipe's attribute setup takes them
    FX, FY = fx[s], fy[s]
    cx, cy = px + 0.5, py + 0.5
    E = np.stack([_edge(FX[:, (i + 1) % 3], FY[:, (i + 1) % 3], FX[:, (i + 2) % 3],
                        FY[:, (i + 2) % 3], cx, cy) for i in range(3)], 1)  # fmt: skip
    lw = E / E.sum(1, keepdims=True)  # window-space weights of the sub-triangle
    depth = (lw * zw[s]).sum(1)
    q = lw / w[s]
    inv_w = q.sum(1)
    persp = q / inv_w[:, None]
    pixel = (height - 1 - py) * width + px
    # depth test GL_LESS: the nearest fragment, of equal depths the one drawn first
    pick = np.lexsort((order[s], parent[s], depth, pixel))
    first = np.r_[True, pixel[pick][1:] != pixel[pick][:-1]]
    keep = pick[first]
    keep = keep[(depth[keep] >= 0.0) & (depth[keep] < 1.0)]
    keep = keep[np.argsort(pixel[keep], kind="stable")]
    ks = s[keep]
    mask = np.zeros(width * height, bool)
    mask[pixel[keep]] = True
    return Coverage(
        mask=mask.reshape(height, width),
        index=pixel[keep],
        triangle=parent[ks],
        smooth=np.einsum("ni,nij->nj", persp[keep], smooth[ks]),
        linear=np.einsum("ni,nij->nj", lw[keep], lin[ks]),
        depth=depth[keep],
        inv_w=inv_w[keep],
        front=area[ks] > 0,
    )


def interpolate(values: np.ndarray, cov: Coverage, triangles: np.ndarray, mode: str):
    """One vertex output ``values`` (V, ...) at the covered pixels, (N, ...) float64: ``mode``
    'smooth' (perspective-correct), 'noperspective' (window-space linear) or 'flat' (the
    provoking vertex, the triangle's last)."""
    vals = np.asarray(values, np.float64)
    tri = np.asarray(triangles, np.int64)[cov.triangle]  # (N, 3)
    if mode == "flat":
        return vals[tri[:, 2]]
    wts = cov.smooth if mode == "smooth" else cov.linear
    extra = (None,) * (vals.ndim - 1)
    return sum(wts[(slice(None), i, *extra)] * vals[tri[:, i]] for i in range(3))
