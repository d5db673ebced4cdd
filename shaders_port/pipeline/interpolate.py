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

:func:`weights_at` evaluates a sub-triangle's plane equations at any pixel centre (inside it
or not); :func:`quad_helpers` builds with it the helper pixels of each triangle's 2x2 quads,
as GL runs a derivative's quads. :func:`plane_points` is the study's own quad's
interpolation: the points of ``y = 0`` seen through pixel centres (``pipeline.raster``).

Perspective-correct weights are ``(l_i / w_i) / sum_j (l_j / w_j)`` of the window-space
(linear) weights ``l_i``; ``flat`` outputs take the provoking vertex, GL's default last vertex
of the triangle (``triangles[t, 2]``). Pixels no triangle covers are not water pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "Grid",
    "Coverage",
    "Planes",
    "water_grid",
    "rasterize_triangles",
    "weights_at",
    "quad_helpers",
    "interpolate",
    "plane_points",
    "weight_tangents",
    "interpolate_tangent",
]

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
        sub: (N,) int64 the clipped sub-triangle of :attr:`planes` each pixel sees.
        planes: the mesh's :class:`Planes` (for :func:`quad_helpers`).
    """

    mask: np.ndarray
    index: np.ndarray
    triangle: np.ndarray
    smooth: np.ndarray
    linear: np.ndarray
    depth: np.ndarray
    inv_w: np.ndarray
    front: np.ndarray
    sub: np.ndarray | None = None
    planes: "Planes | None" = None


def plane_points(view_proj: np.ndarray, width: int, height: int, col, row):
    """The points of the water plane ``y = 0`` seen through the centres of image pixels
    ``(col, row)`` (float64 arrays of one shape, row 0 at the top; either may lie outside the
    image), as the study's quad interpolates them: ``(points (..., 3) float64, t (...))``,
    ``t`` the point's place on the segment from the near plane (0) to the far plane (1), NaN
    or infinite for a ray parallel to the plane. ``view_proj`` (4, 4) must be invertible."""
    vp = np.asarray(view_proj, np.float64)
    try:
        inv = np.linalg.inv(vp)
    except np.linalg.LinAlgError as e:
        raise ValueError(
            "ShaderInputs.view_proj is singular; build it with perspective_view_proj"
        ) from e
    ndc_x = 2.0 * (np.asarray(col, np.float64) + 0.5) / width - 1.0
    ndc_y = 2.0 * (height - np.asarray(row, np.float64) - 0.5) / height - 1.0

    def unproject(z):
        q = np.stack([ndc_x, ndc_y, np.full_like(ndc_x, z), np.ones_like(ndc_x)], -1) @ inv.T
        return q[..., :3] / q[..., 3:4]

    p_near, p_far = unproject(-1.0), unproject(1.0)
    d = p_far - p_near
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -p_near[..., 1] / d[..., 1]
    p = p_near + t[..., None] * d
    p[..., 1] = 0.0
    return p, t


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


@dataclass
class Planes:
    """The window-space plane equations of the (clipped) sub-triangles of a mesh: ``fx``,
    ``fy`` (S, 3) float64 unsnapped window positions, ``zw`` (S, 3) window depths, ``w`` (S, 3)
    clip ``w``, ``smooth`` / ``linear`` (S, 3, 3) each vertex's weights over its original
    triangle's vertices (clip-space and window-space), ``parent`` (S,) the original triangle,
    ``area`` (S,) twice the signed window area of the snapped positions."""

    fx: np.ndarray
    fy: np.ndarray
    zw: np.ndarray
    w: np.ndarray
    smooth: np.ndarray
    linear: np.ndarray
    parent: np.ndarray
    area: np.ndarray


def weights_at(planes: Planes, s: np.ndarray, px: np.ndarray, py: np.ndarray) -> dict:
    """The interpolants of sub-triangles ``s`` (M,) at the centres of window pixels ``(px,
    py)`` (M,) int, inside the triangle or not (a helper pixel's are extrapolated on the same
    planes): ``smooth`` / ``linear`` (M, 3) float64 weights over the original triangle's
    vertices, ``depth`` (M,) window depth, ``inv_w`` (M,) ``1 / w_clip``. The weights come
    from the unsnapped positions, as llvmpipe's attribute setup takes them."""
    FX, FY = planes.fx[s], planes.fy[s]
    cx, cy = px + 0.5, py + 0.5
    E = np.stack([_edge(FX[:, (i + 1) % 3], FY[:, (i + 1) % 3], FX[:, (i + 2) % 3],
                        FY[:, (i + 2) % 3], cx, cy) for i in range(3)], 1)  # fmt: skip
    lw = E / E.sum(1, keepdims=True)  # window-space weights of the sub-triangle
    q = lw / planes.w[s]
    inv_w = q.sum(1)
    persp = q / inv_w[:, None]
    return {
        "smooth": np.einsum("ni,nij->nj", persp, planes.smooth[s]),
        "linear": np.einsum("ni,nij->nj", lw, planes.linear[s]),
        "depth": (lw * planes.zw[s]).sum(1),
        "inv_w": inv_w,
    }


def _planes(clip: np.ndarray, triangles: np.ndarray, width: int, height: int):
    """(:class:`Planes`, snapped window x (S, 3), snapped window y (S, 3), order within the
    parent (S,)) of the mesh after near/far clipping."""
    verts, smooth, lin, parent, order = _clipped(clip, np.asarray(triangles, np.int64))
    w = verts[..., 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        fx = (verts[..., 0] / w + 1.0) * 0.5 * width
        fy = (verts[..., 1] / w + 1.0) * 0.5 * height
        zw = (verts[..., 2] / w + 1.0) * 0.5
    xw, yw = np.round(fx * SUBPIXEL) / SUBPIXEL, np.round(fy * SUBPIXEL) / SUBPIXEL
    area = _edge(xw[:, 0], yw[:, 0], xw[:, 1], yw[:, 1], xw[:, 2], yw[:, 2])
    return Planes(fx, fy, zw, w, smooth, lin, parent, area), xw, yw, order


def rasterize_triangles(clip: np.ndarray, triangles: np.ndarray, width: int, height: int):
    """:class:`Coverage` of the triangles ``triangles`` (T, 3) over vertices at clip-space
    positions ``clip`` (V, 4) on a ``width x height`` image (see the module doc)."""
    planes, xw, yw, order = _planes(np.asarray(clip, np.float64), triangles, width, height)
    area, w, parent = planes.area, planes.w, planes.parent
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
    wts = weights_at(planes, s, px, py)
    depth = wts["depth"]
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
        smooth=wts["smooth"][keep],
        linear=wts["linear"][keep],
        depth=depth[keep],
        inv_w=wts["inv_w"][keep],
        front=area[ks] > 0,
        sub=ks,
        planes=planes,
    )


def quad_helpers(cov: Coverage, width: int, height: int):
    """The helper invocations of the covered pixels' 2x2 quads, as GL runs them: each
    triangle's fragments of a quad run together, and the quad's other pixels (not covered, or
    covered by another triangle) run with that triangle's interpolants extrapolated to their
    centres (:func:`weights_at` on its plane equations). Returns ``(x, y, group, helpers)``:
    window pixel x, y (int64, y up; helpers may lie outside the image) and the quad invocation
    (int64) of every lane, the covered pixels first (in ``cov.index`` order), and a
    :class:`Coverage` of the helper lanes (``mask`` None, ``index`` -1)."""
    x = cov.index % width
    y = height - 1 - cov.index // width
    qx, qy = x >> 1, y >> 1
    key = np.stack([qx, qy, cov.triangle], 1)
    _, first, group = np.unique(key, axis=0, return_index=True, return_inverse=True)
    group = group.ravel()
    have = set(zip(group.tolist(), (x & 1).tolist(), (y & 1).tolist()))
    hg, hx, hy = [], [], []
    for g, f in enumerate(first.tolist()):
        for dx, dy in ((0, 0), (1, 0), (0, 1), (1, 1)):
            if (g, dx, dy) not in have:
                hg.append(g)
                hx.append(2 * qx[f] + dx)
                hy.append(2 * qy[f] + dy)
    hg, hx, hy = (np.asarray(a, np.int64) for a in (hg, hx, hy))
    hs = cov.sub[first[hg]]  # the sub-triangle of a covered pixel of its invocation
    wts = weights_at(cov.planes, hs, hx, hy)
    helpers = Coverage(
        mask=None,
        index=np.full(len(hg), -1, np.int64),
        triangle=cov.triangle[first[hg]],
        smooth=wts["smooth"],
        linear=wts["linear"],
        depth=wts["depth"],
        inv_w=wts["inv_w"],
        front=cov.front[first[hg]],
    )
    return np.r_[x, hx], np.r_[y, hy], np.r_[group, hg], helpers


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


def weight_tangents(clip, dclip, triangles, tri, px, py, width: int, height: int) -> dict:
    """Forward-mode derivatives of the interpolants of lanes at the fixed centres of window
    pixels ``(px, py)`` (N,) int (y up), each on the original triangle ``tri`` (N,) of
    ``triangles``, when the clip-space positions ``clip`` (V, 4) move by ``dclip`` (V, 4): the
    coverage held fixed, each pixel keeps its triangle. Returns float64 ``smooth`` / ``linear``
    (N, 3) weights and their derivatives ``dsmooth`` / ``dlinear``, ``ddepth`` and ``dinv_w``
    (N,). The weights are those :func:`weights_at` gives, in closed form: the point of the
    triangle's plane seen through the pixel is ``P = sum_i b_i C_i`` with ``(P.x, P.y) = (X, Y)
    P.w`` (``X``, ``Y`` the centre's NDC), so ``b`` is ``M^-1 (X, Y, 1)`` normalised, ``M`` the
    columns ``(x, y, w)`` of the vertices ``C_i`` (clipping keeps that plane); ``linear`` is
    ``b_i w_i / P.w``, the depth ``(P.z / P.w + 1) / 2``, ``gl_FragCoord.w`` ``1 / P.w``."""
    V = np.asarray(triangles, np.int64)[tri]
    C, dC = np.asarray(clip, np.float64)[V], np.asarray(dclip, np.float64)[V]  # (N, 3, 4)
    X = 2.0 * (np.asarray(px, np.float64) + 0.5) / width - 1.0
    Y = 2.0 * (np.asarray(py, np.float64) + 0.5) / height - 1.0
    M = np.stack([C[..., 0], C[..., 1], C[..., 3]], 1)  # rows x, y, w; a column per vertex
    dM = np.stack([dC[..., 0], dC[..., 1], dC[..., 3]], 1)
    rhs = np.stack([X, Y, np.ones_like(X)], 1)
    n = len(X)
    a, da = np.zeros((n, 3)), np.zeros((n, 3))
    det = np.linalg.det(M) if n else np.zeros(0)
    ok = np.isfinite(det) & (np.abs(det) > 1e-300)
    if ok.any():
        a[ok] = np.linalg.solve(M[ok], rhs[ok, :, None])[..., 0]
        da[ok] = -np.linalg.solve(M[ok], np.einsum("nij,nj->ni", dM[ok], a[ok])[..., None])[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        S, dS = a.sum(1, keepdims=True), da.sum(1, keepdims=True)
        b = a / S
        db = (da - b * dS) / S
        P = np.einsum("ni,nik->nk", b, C)
        dP = np.einsum("ni,nik->nk", db, C) + np.einsum("ni,nik->nk", b, dC)
        w, dw = C[..., 3], dC[..., 3]
        Pw, dPw = P[:, 3:], dP[:, 3:]
        lin = b * w / Pw
        dlin = (db * w + b * dw) / Pw - lin * dPw / Pw
        ddepth = 0.5 * (dP[:, 2] * Pw[:, 0] - P[:, 2] * dPw[:, 0]) / Pw[:, 0] ** 2
        dinv_w = -dPw[:, 0] / Pw[:, 0] ** 2
    bad = ~ok
    for arr in (db, dlin):
        arr[bad] = 0.0
    ddepth[bad], dinv_w[bad] = 0.0, 0.0
    return {"smooth": b, "linear": lin, "dsmooth": db, "dlinear": dlin, "ddepth": ddepth,
            "dinv_w": dinv_w}  # fmt: skip


def interpolate_tangent(values, dvalues, weights, dweights, vertices, mode: str):
    """The derivative of one vertex output interpolated (:func:`interpolate`) at lanes whose
    triangle's vertices are ``vertices`` (N, 3): ``values`` and its derivative ``dvalues``
    (V, ...), the lanes' weights of ``mode`` and their derivatives (N, 3) (``smooth`` or
    ``linear`` of :func:`weight_tangents`; a ``flat`` output takes the provoking vertex's
    derivative). Returns (N, ...) float64."""
    vals, dvals = np.asarray(values, np.float64), np.asarray(dvalues, np.float64)
    tri = np.asarray(vertices, np.int64)
    if mode == "flat":
        return dvals[tri[:, 2]]
    extra = (None,) * (vals.ndim - 1)
    out = 0.0
    for i in range(3):
        w = (slice(None), i, *extra)
        out = out + dweights[w] * vals[tri[:, i]] + weights[w] * dvals[tri[:, i]]
    return out
