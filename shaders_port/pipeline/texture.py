"""OpenGL-faithful texture sampling in Dr.Jit, used by the shader ports and the SPIR-V executor.

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

Mipmaps (section 8.14.3), for a texture whose binding has them (:meth:`Texture2D.with_mipmaps`;
the study's inputs have none, and :meth:`Texture2D.sample` is level 0): levels are box-filtered
halvings (``max(1, n // 2)`` texels, each the mean of the 2x2 -- or 2x1 / 1x2 -- texels it
covers); ``mipmap`` is the filter between levels ('nearest': level ``ceil(lod + 0.5) - 1``,
'linear': ``floor(lod)`` and the next blended by ``frac(lod)``), ``filter`` the filter within
a level and the magnification filter (``lod <= 0``: level 0). The level of detail of implicit
and gradient lookups is Mesa llvmpipe's (:func:`lod_from_gradients`): ``0.5 * log2(max(|d/dx|^2,
|d/dy|^2))`` of the texel-space gradients with llvmpipe's piecewise-linear log2 (the
specification allows an approximation of rho and of the logarithm).

Textures are stored as flat Dr.Jit ``Float`` arrays in OpenGL upload order: texel
``(row r, column c)`` of a ``(H, W, C)`` array sits at ``(r * W + c) * C + channel``; row
``r`` has ``t = (r + 0.5) / H``. Texture coordinates are Dr.Jit ``Float`` arrays (one per
lane); results are lists of ``C`` Dr.Jit ``Float`` arrays. Derivatives flow through the
bilinear weights (texel values carry no gradient; nearest lookups have zero derivative).
"""

from __future__ import annotations

from dataclasses import dataclass
from dataclasses import replace as dataclasses_replace

import drjit as dr
import numpy as np

NEAREST, LINEAR = "nearest", "linear"
CLAMP, REPEAT = "clamp", "repeat"


BACKENDS = ("llvm", "cuda")
_DEFAULT_BACKEND = ["llvm"]  # set once per process by study._backend.init_backend


def set_default_backend(backend: str) -> None:
    """Make ``backend`` ("llvm" or "cuda") what every port, the SPIR-V executor and the fit's
    models use when they are given no backend (``backend=None``). ``study._backend.init_backend``
    calls it with the backend of the Mitsuba variant it sets: the one switch of a run."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be 'llvm' or 'cuda', got {backend!r}")
    _DEFAULT_BACKEND[0] = backend


def resolve_backend(backend: str | None) -> str:
    """``backend``, or the process's default (:func:`set_default_backend`; "llvm" until set)."""
    backend = _DEFAULT_BACKEND[0] if backend is None else backend
    if backend not in BACKENDS:
        raise ValueError(f"backend must be 'llvm' or 'cuda', got {backend!r}")
    return backend


def backend_types(backend: str | None = None):
    """The Dr.Jit AD module for ``backend`` ("llvm" -> drjit.llvm.ad, "cuda" -> drjit.cuda.ad;
    None: :func:`resolve_backend`'s default). A CUDA backend on a machine where Dr.Jit found no
    CUDA device is refused here, with the fix, before an array is made."""
    backend = resolve_backend(backend)
    if backend == "llvm":
        import drjit.llvm.ad as m
    else:
        if not dr.has_backend(dr.JitBackend.CUDA):
            raise RuntimeError(
                "the CUDA backend was asked for, but Dr.Jit found no CUDA device on this "
                "machine (no NVIDIA GPU or driver): run on the CPU with --backend llvm_ad_rgb "
                '(or variant = "llvm_ad_rgb"), or on a machine with an NVIDIA GPU and driver'
            )
        import drjit.cuda.ad as m
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
    levels: tuple = ()  # mip levels 1..q: ((data, width, height), ...); () without mipmaps
    mipmap: str | None = None  # the filter between levels, NEAREST | LINEAR; None: none

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

    def texel_edge(self, m, s, t):
        """Distance (Float, in texels) from ``(s, t)`` to the nearest texel edge of this texture:
        where it is within float rounding of 0, a ``NEAREST`` lookup on another implementation
        (a GPU's texel addressing) can read the neighbouring texel."""
        u, v = s * self.width, t * self.height
        du, dv = u - dr.floor(u), v - dr.floor(v)
        return dr.minimum(dr.minimum(du, 1.0 - du), dr.minimum(dv, 1.0 - dv))

    def _fetch(self, m, i, j, active) -> list:
        base = m.UInt32((j * self.width + i) * self.channels)
        return [dr.gather(m.Float, self.data, base + c, active) for c in range(self.channels)]

    # ---- mipmaps -------------------------------------------------------------------------------
    def with_mipmaps(self, m, mipmap: str = LINEAR, array=None) -> "Texture2D":
        """This texture with its box-filtered mip chain down to 1 x 1 (see the module doc) and
        ``mipmap`` the filter between levels. ``array``: the level-0 texels ((H, W) or (H, W, C)
        float32, those :meth:`from_numpy` uploaded) when the caller has them; else they are
        read back from the device."""
        if mipmap not in (NEAREST, LINEAR):
            raise ValueError(f"unknown mipmap filter {mipmap!r}")
        src = self.data.numpy() if array is None else array
        a = np.asarray(src, np.float32).reshape(self.height, self.width, -1)
        levels = []
        for lv in box_mip_chain(a)[1:]:
            levels.append((m.Float(np.ascontiguousarray(lv).ravel()), lv.shape[1], lv.shape[0]))
        return dataclasses_replace(self, levels=tuple(levels), mipmap=mipmap)

    def level(self, k: int) -> tuple:
        """(data, width, height) of mip level ``k`` (0: the base level)."""
        return (self.data, self.width, self.height) if k == 0 else self.levels[k - 1]

    def filtered(self, m, k: int, s, t, active, offset=(0, 0), filt: str | None = None) -> list:
        """Level ``k`` (a Python int) sampled at ``(s, t)`` with filter ``filt`` (default
        ``filter``) and a texel ``offset`` (GLSL ``textureOffset``): ``channels`` Floats."""
        data, w, h = self.level(k)
        C, wrap = self.channels, self.wrap

        def fetch(i, j):
            base = m.UInt32((j * w + i) * C)
            return [dr.gather(m.Float, data, base + c, active) for c in range(C)]

        if (filt or self.filter) == NEAREST:
            i = _wrap(m, m.Int32(dr.floor(s * w)) + offset[0], w, wrap)
            j = _wrap(m, m.Int32(dr.floor(t * h)) + offset[1], h, wrap)
            return fetch(i, j)
        u, v = s * w - 0.5, t * h - 0.5
        fu, fv = dr.floor(u), dr.floor(v)
        a, b = u - fu, v - fv
        i0, j0 = m.Int32(fu) + offset[0], m.Int32(fv) + offset[1]
        i1, j1 = _wrap(m, i0 + 1, w, wrap), _wrap(m, j0 + 1, h, wrap)
        i0, j0 = _wrap(m, i0, w, wrap), _wrap(m, j0, h, wrap)
        t00, t10, t01, t11 = fetch(i0, j0), fetch(i1, j0), fetch(i0, j1), fetch(i1, j1)
        w00, w10, w01, w11 = (1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b
        return [w00 * t00[c] + w10 * t10[c] + w01 * t01[c] + w11 * t11[c] for c in range(C)]

    def sample_lod(self, m, s, t, lod, active=True, offset=(0, 0)) -> list:
        """GL's lookup at level of detail ``lod`` (a Float per lane or a Python float, bias
        already added): level selection and filtering of section 8.14 (module doc)."""
        q = len(self.levels)
        if self.mipmap is None or q == 0:
            return self.filtered(m, 0, s, t, active, offset)
        lod = m.Float(lod)
        mag = lod <= 0.0
        if self.mipmap == NEAREST:
            d = dr.clip(dr.ceil(lod + 0.5) - 1.0, 0.0, float(q))
            out = self.filtered(m, 0, s, t, active, offset)
            for k in range(1, q + 1):
                hit = (d == float(k)) & ~mag
                tk = self.filtered(m, k, s, t, active & hit, offset)
                out = [dr.select(hit, x, y) for x, y in zip(tk, out)]
            return out
        lam = dr.clip(lod, 0.0, float(q))
        d1 = dr.floor(lam)
        frac = lam - d1
        out = [dr.zeros(m.Float, dr.width(lam)) for _ in range(self.channels)]
        for k in range(0, q + 1):
            w = dr.select(d1 == float(k), 1.0 - frac, 0.0) + dr.select(
                d1 + 1.0 == float(k), frac, 0.0
            )
            w = dr.select(mag, 1.0 if k == 0 else 0.0, w)
            used = active & (w > 0.0)
            tk = self.filtered(m, k, s, t, used, offset)
            out = [o + dr.select(used, w * x, 0.0) for o, x in zip(out, tk)]
        return out

    def texel(self, m, i, j, k, active=True) -> list:
        """GLSL ``texelFetch``: texel ``(i, j)`` (Int32 per lane) of level ``k`` (a Python int);
        0 outside the level (what llvmpipe returns; GL leaves it undefined)."""
        data, w, h = self.level(k)
        inside = (i >= 0) & (i < w) & (j >= 0) & (j < h)
        base = m.UInt32((dr.clip(j, 0, h - 1) * w + dr.clip(i, 0, w - 1)) * self.channels)
        return [
            dr.select(inside, dr.gather(m.Float, data, base + c, active & inside), 0.0)
            for c in range(self.channels)
        ]


def box_mip_chain(a: np.ndarray) -> list:
    """The box-filtered mip chain of ``a`` ((H, W, C) float32): [a, level 1, ..., 1 x 1], each
    level ``max(1, n // 2)`` texels a side, the mean of the texels each covers (an odd size's
    last row or column is left out, as a 2x2 box of the even part)."""
    out = [np.asarray(a, np.float32)]
    while out[-1].shape[0] > 1 or out[-1].shape[1] > 1:
        x = out[-1].astype(np.float64)
        h, w = x.shape[:2]
        if h > 1:
            x = 0.5 * (x[0 : h // 2 * 2 : 2] + x[1 : h // 2 * 2 : 2])
        if w > 1:
            x = 0.5 * (x[:, 0 : w // 2 * 2 : 2] + x[:, 1 : w // 2 * 2 : 2])
        out.append(x.astype(np.float32))
    return out


def fast_log2(m, x):
    """llvmpipe's ``lp_build_fast_log2``: ``exponent + mantissa - 1`` (mantissa in [1, 2)),
    piecewise linear between powers of two, exact at them; ``x`` > 0 Float (normal numbers;
    derivatives flow through the mantissa)."""
    x = m.Float(x)
    bits = dr.reinterpret_array(m.Int32, dr.detach(x))
    e = m.Float((bits >> 23) & 0xFF) - 127.0
    return e + x * dr.exp2(-e) - 1.0  # x / 2^e is exact: the derivative is x's, scaled


def lod_from_gradients(m, tex, dsdx, dtdx, dsdy, dtdy):
    """llvmpipe's level of detail from texture-coordinate gradients (Floats): ``0.5 *
    fast_log2(max(|dx|^2, |dy|^2))`` with the gradients in level-0 texels."""
    w, h = float(tex.width), float(tex.height)
    ax, ay = dsdx * w, dtdx * h
    bx, by = dsdy * w, dtdy * h
    rho2 = dr.maximum(ax * ax + ay * ay, bx * bx + by * by)
    return 0.5 * fast_log2(m, dr.maximum(rho2, 1e-30))


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


def smoothstep(e0, e1, x):
    """GLSL ``smoothstep``: ``t * t * (3 - 2 t)``, ``t = clamp((x - e0) / (e1 - e0), 0, 1)``."""
    t = clamp((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def radians(deg):
    """GLSL ``radians``: degrees to radians."""
    return deg * (3.14159265358979 / 180.0)


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
