"""OpenGL-faithful texture sampling in Dr.Jit (no mipmaps), used by the shader ports.

Implements the OpenGL 4.5 core specification, section 8.14 (texture minification /
magnification without mipmaps):

* ``NEAREST``: ``i = wrap(floor(s * W))``.
* ``LINEAR``: ``u = s * W - 0.5``, ``i0 = wrap(floor(u))``, ``i1 = wrap(floor(u) + 1)``,
  ``alpha = frac(u)``; the result is ``(1-a)(1-b) T[i0,j0] + a(1-b) T[i1,j0] + (1-a)b T[i0,j1]
  + ab T[i1,j1]``.
* ``CLAMP_TO_EDGE``: ``wrap(i) = clamp(i, 0, W - 1)``; ``REPEAT``: ``wrap(i) = i mod W``.
* Cube maps (section 8.13, table 8.19): the major axis of the direction picks the face,
  ``s = (sc / |ma| + 1) / 2``, ``t = (tc / |ma| + 1) / 2``; bilinear within that face
  with clamp to edge (seamless cube-map filtering off).

Textures are stored as flat Dr.Jit ``Float`` arrays in OpenGL upload order: texel
``(row r, column c)`` of a ``(H, W, C)`` array sits at ``(r * W + c) * C + channel``; row
``r`` has ``t = (r + 0.5) / H``. Texture coordinates are Dr.Jit ``Float`` arrays (one per
lane); results are lists of ``C`` Dr.Jit ``Float`` arrays. Derivatives flow through the
bilinear weights (texel values carry no gradient; nearest lookups have zero derivative).
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import numpy as np

NEAREST, LINEAR = "nearest", "linear"
CLAMP, REPEAT = "clamp", "repeat"


def backend_types(backend: str):
    """The Dr.Jit AD module for ``backend`` ("llvm" -> drjit.llvm.ad, "cuda" -> drjit.cuda.ad)."""
    if backend == "llvm":
        import drjit.llvm.ad as m
    elif backend == "cuda":
        import drjit.cuda.ad as m
    else:
        raise ValueError(f"backend must be 'llvm' or 'cuda', got {backend!r}")
    return m


@dataclass
class Texture2D:
    """A 2D texture: ``data`` flat Float of ``height * width * channels`` texels (float32)."""

    data: object
    width: int
    height: int
    channels: int
    filter: str
    wrap: str

    @classmethod
    def from_numpy(cls, m, array: np.ndarray, filter: str, wrap: str) -> "Texture2D":
        """``array``: (H, W) or (H, W, C) float32 in GL upload order; ``m``: Dr.Jit type module."""
        a = np.asarray(array, dtype=np.float32)
        if a.ndim == 2:
            a = a[..., None]
        if a.ndim != 3:
            raise ValueError(f"texture must be (H, W) or (H, W, C), got shape {a.shape}")
        if filter not in (NEAREST, LINEAR) or wrap not in (CLAMP, REPEAT):
            raise ValueError(f"unknown filter/wrap {filter!r}/{wrap!r}")
        return cls(
            m.Float(np.ascontiguousarray(a).ravel()),
            a.shape[1],
            a.shape[0],
            a.shape[2],
            filter,
            wrap,
        )

    def sample(self, m, s, t, active=True) -> list:
        """``texture2D(tex, vec2(s, t))``: list of ``channels`` Float arrays."""
        if self.filter == NEAREST:
            i = _wrap(m, m.Int32(dr.floor(s * self.width)), self.width, self.wrap)
            j = _wrap(m, m.Int32(dr.floor(t * self.height)), self.height, self.wrap)
            return self._fetch(m, i, j, active)
        u = s * self.width - 0.5
        v = t * self.height - 0.5
        fu, fv = dr.floor(u), dr.floor(v)
        a, b = u - fu, v - fv
        i0, j0 = m.Int32(fu), m.Int32(fv)
        i1 = _wrap(m, i0 + 1, self.width, self.wrap)
        j1 = _wrap(m, j0 + 1, self.height, self.wrap)
        i0 = _wrap(m, i0, self.width, self.wrap)
        j0 = _wrap(m, j0, self.height, self.wrap)
        t00, t10 = self._fetch(m, i0, j0, active), self._fetch(m, i1, j0, active)
        t01, t11 = self._fetch(m, i0, j1, active), self._fetch(m, i1, j1, active)
        w00, w10, w01, w11 = (1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b
        return [
            w00 * t00[c] + w10 * t10[c] + w01 * t01[c] + w11 * t11[c] for c in range(self.channels)
        ]

    def _fetch(self, m, i, j, active) -> list:
        base = m.UInt32((j * self.width + i) * self.channels)
        return [dr.gather(m.Float, self.data, base + c, active) for c in range(self.channels)]


def _wrap(m, i, n: int, mode: str):
    if mode == CLAMP:
        return dr.clip(i, 0, n - 1)
    r = i % n  # C-style remainder: negative for negative i
    return dr.select(r < 0, r + n, r)


@dataclass
class CubeMap:
    """A cube map: 6 faces of ``size x size`` texels in GL order +X, -X, +Y, -Y, +Z, -Z,
    stored as one flat Float (face-major, each face in GL upload order)."""

    data: object
    size: int
    channels: int

    @classmethod
    def from_numpy(cls, m, array: np.ndarray) -> "CubeMap":
        """``array``: (6, F, F, C) float32, each face in GL upload order."""
        a = np.asarray(array, dtype=np.float32)
        if a.ndim != 4 or a.shape[0] != 6 or a.shape[1] != a.shape[2]:
            raise ValueError(f"cube map must be (6, F, F, C), got shape {a.shape}")
        return cls(m.Float(np.ascontiguousarray(a).ravel()), a.shape[1], a.shape[3])

    def sample(self, m, rx, ry, rz, active=True) -> list:
        """``textureCube(tex, vec3(rx, ry, rz))``: bilinear, clamp to edge within the selected
        face (no filtering across faces); list of ``channels`` Float arrays."""
        face, s, t = cube_face_coords(m, rx, ry, rz)
        n, C = self.size, self.channels
        u, v = s * n - 0.5, t * n - 0.5
        fu, fv = dr.floor(u), dr.floor(v)
        a, b = u - fu, v - fv
        i0, j0 = m.Int32(fu), m.Int32(fv)
        i1, j1 = _wrap(m, i0 + 1, n, CLAMP), _wrap(m, j0 + 1, n, CLAMP)
        i0, j0 = _wrap(m, i0, n, CLAMP), _wrap(m, j0, n, CLAMP)
        base = m.Int32(face) * (n * n)

        def fetch(i, j):
            o = m.UInt32((base + j * n + i) * C)
            return [dr.gather(m.Float, self.data, o + c, active) for c in range(C)]

        t00, t10, t01, t11 = fetch(i0, j0), fetch(i1, j0), fetch(i0, j1), fetch(i1, j1)
        w00, w10, w01, w11 = (1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b
        return [w00 * t00[c] + w10 * t10[c] + w01 * t01[c] + w11 * t11[c] for c in range(C)]


def cube_face_coords(m, rx, ry, rz):
    """GL table 8.19: (face index UInt32, s, t) for direction (rx, ry, rz).

    Ties between axes go to x before y before z (the order in which the GL table lists them).
    """
    ax, ay, az = dr.abs(rx), dr.abs(ry), dr.abs(rz)
    use_x = (ax >= ay) & (ax >= az)
    use_y = ~use_x & (ay >= az)
    face = dr.select(
        use_x,
        dr.select(rx >= 0, m.UInt32(0), m.UInt32(1)),
        dr.select(
            use_y,
            dr.select(ry >= 0, m.UInt32(2), m.UInt32(3)),
            dr.select(rz >= 0, m.UInt32(4), m.UInt32(5)),
        ),
    )
    # face: +X (sc=-rz, tc=-ry), -X (sc=+rz, tc=-ry), +Y (sc=+rx, tc=+rz),
    #       -Y (sc=+rx, tc=-rz), +Z (sc=+rx, tc=-ry), -Z (sc=-rx, tc=-ry)
    sc = dr.select(
        use_x, dr.select(rx >= 0, -rz, rz), dr.select(use_y, rx, dr.select(rz >= 0, rx, -rx))
    )
    tc = dr.select(use_y, dr.select(ry >= 0, rz, -rz), -ry)
    ma = dr.select(use_x, ax, dr.select(use_y, ay, az))
    s = 0.5 * (sc / ma + 1.0)
    t = 0.5 * (tc / ma + 1.0)
    return face, s, t


# ---- GLSL built-ins with their specified semantics -------------------------------------


def mix(x, y, a):
    """GLSL ``mix``: ``x * (1 - a) + y * a``."""
    return x * (1.0 - a) + y * a


def clamp(x, lo, hi):
    """GLSL ``clamp``: ``min(max(x, lo), hi)``."""
    return dr.minimum(dr.maximum(x, lo), hi)


def gl_pow(x, y):
    """GLSL ``pow`` for ``x >= 0``: ``exp2(y * log2(x))``, 0 at ``x = 0`` (and a 0 derivative
    there instead of the NaN of ``log2(0) * 0``)."""
    pos = x > 0.0
    xs = dr.select(pos, x, 1.0)
    return dr.select(pos, dr.exp2(y * dr.log2(xs)), 0.0)


def texmat_xy(M, p):
    """``(M * vec4(p, 1)).xy`` for a (4, 4) matrix ``M`` (array or nested tuples of float32
    values) and an Array3f ``p``."""
    s = float(M[0][0]) * p.x + float(M[0][1]) * p.y + float(M[0][2]) * p.z + float(M[0][3])
    t = float(M[1][0]) * p.x + float(M[1][1]) * p.y + float(M[1][2]) * p.z + float(M[1][3])
    return s, t
