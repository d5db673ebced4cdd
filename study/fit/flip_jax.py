"""LDR-FLIP written in JAX, so that the fit can differentiate the error the study reports.

:func:`flip_map` follows ``flip-evaluator``'s LDR path (``evaluate(ref, test, "LDR",
inputsRGB=False)``, Andersson et al. 2020, "FLIP: A Difference Evaluator for Alternating
Images") step by step:

1. linear RGB in [0, 1] -> XYZ (D65) -> YCxCz;
2. colour pipeline: each YCxCz channel filtered by its contrast sensitivity function (sums of
   Gaussians, separable, edge-replicated borders), back to linear RGB and clamped to [0, 1],
   CIELab, Hunt-adjusted (a, b scaled by 0.01 L), HyAB distance ``|dL| + ||d(a, b)||``, raised
   to ``qc = 0.7`` and remapped to [0, 1] (``pc = 0.4`` of the green-blue distance ``cmax``
   mapped to ``pt = 0.95``);
3. feature pipeline: the achromatic channel ``(Y + 16) / 116`` filtered by the first and second
   derivatives of a Gaussian (``sigma = 0.5 * 0.082 * ppd`` pixels; positive and negative
   weights normalised to +1 and -1), the larger of the edge and point magnitude differences,
   ``(diff / sqrt(2)) ** qf`` with ``qf = 0.5``;
4. ``FLIP = colour ** (1 - feature)`` per pixel.

It is computed in float64 (``flip-evaluator`` uses float32) and agrees with it to the
tolerance ``tests/test_flip_loss.py`` states. :func:`flip_map` is the value; derivatives
(``jax.jvp``, ``jax.linearize``) are those of the same function with its kinks smoothed where
the exact derivative is infinite or undefined: ``|dL|``, the (a, b) and feature magnitudes and
the powers at zero use ``sqrt(x^2 + SMOOTH^2)`` and a floor of ``SMOOTH`` (``SMOOTH`` is far
below the float32 resolution of ``flip-evaluator``'s own map, so the value is unchanged to
that resolution).

Images are (H, W, 3) linear RGB; maps are (H, W) in [0, 1]. ``ppd``: pixels per degree of
visual angle (``flip-evaluator``'s default, 67.0206 ppd: a 0.7 m wide 4K display seen from
0.7 m).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .jax_residual import enable_x64

#: flip-evaluator's default observer: 0.7 m wide 3840-pixel display at 0.7 m
PPD = 0.7 * 3840 / 0.7 * np.pi / 180
QC, QF, PC, PT, FEATURE_W = 0.7, 0.5, 0.4, 0.95, 0.082
#: where |x|, sqrt and the powers are smoothed for the derivatives (see the module docstring)
SMOOTH = 1e-9
#: keeps the square roots of :func:`flip_residual` differentiable at zero
TINY = 1e-24

_RGB2XYZ = np.array(
    [
        [10135552 / 24577794, 8788810 / 24577794, 4435075 / 24577794],
        [2613072 / 12288897, 8788810 / 12288897, 887015 / 12288897],
        [1425312 / 73733382, 8788810 / 73733382, 70074185 / 73733382],
    ]
)
_XYZ2RGB = np.array(
    [
        [3.241003275, -1.537398934, -0.498615861],
        [-0.969224334, 1.875930071, 0.041554224],
        [0.055639423, -0.204011202, 1.057148933],
    ]
)
_WHITE = np.array([0.950428545, 1.0, 1.088900371])
#: the contrast sensitivity functions' (a1, b1, a2, b2) for Y, Cx and Cz
_CSF = {
    "y": (1.0, 0.0047, 0.0, 1e-5),
    "cx": (1.0, 0.0053, 0.0, 1e-5),
    "cz": (34.1, 0.04, 13.5, 0.025),
}


@lru_cache(maxsize=8)
def _filters(ppd: float) -> dict:
    """The separable 1-D kernels at ``ppd``: the CSFs (Y, Cx: one Gaussian; Cz: two) and the
    feature filters (Gaussian, first and second derivative)."""
    r = int(np.ceil(3 * np.sqrt(0.04 / (2 * np.pi**2)) * ppd))
    x2 = (np.arange(-r, r + 1) / ppd) ** 2

    def g(a, b):
        return a * np.sqrt(np.pi / b) * np.exp(-(np.pi**2) * x2 / b)

    out = {name: [g(a1, b1) / g(a1, b1).sum()] for name, (a1, b1, _, _) in _CSF.items()
           if name != "cz"}  # fmt: skip
    a1, b1, a2, b2 = _CSF["cz"]
    # a sum of two 2-D Gaussians as a sum of two separable products (each 1-D factor the
    # square root of its 2-D weight), normalised so that the 2-D kernel sums to one
    s1 = np.sqrt(a1 * np.sqrt(np.pi / b1)) * np.exp(-(np.pi**2) * x2 / b1)
    s2 = np.sqrt(a2 * np.sqrt(np.pi / b2)) * np.exp(-(np.pi**2) * x2 / b2)
    norm = np.sqrt(s1.sum() ** 2 + s2.sum() ** 2)
    out["cz"] = [s1 / norm, s2 / norm]

    sd = 0.5 * FEATURE_W * ppd
    rf = int(np.ceil(3 * sd))
    xf = np.arange(-rf, rf + 1, dtype=np.float64)
    gauss = np.exp(-(xf**2) / (2 * sd * sd))
    dg = -xf * gauss
    ddg = (xf**2 / (sd * sd) - 1) * gauss

    def signed(k):
        return np.where(k > 0, k / k[k > 0].sum(), k / -k[k < 0].sum())

    out["feature"] = (gauss / gauss.sum(), signed(dg), signed(ddg))
    return out


def _conv1d(img, k, axis: int):
    """``img`` (H, W) convolved with the symmetric or antisymmetric 1-D kernel ``k`` along
    ``axis`` (0: y, 1: x), the border replicated (flip-evaluator's clamp-to-edge)."""
    import jax.numpy as jnp
    from jax import lax

    r = (len(k) - 1) // 2
    pad = [(0, 0), (0, 0)]
    pad[axis] = (r, r)
    p = jnp.pad(img, pad, mode="edge")[None, None]
    # correlation with the kernel reversed is convolution
    kern = jnp.asarray(np.asarray(k, np.float64)[::-1])
    kern = kern[None, None, None, :] if axis == 1 else kern[None, None, :, None]
    return lax.conv_general_dilated(p, kern.astype(p.dtype), (1, 1), "VALID")[0, 0]


def _sep(img, kx, ky):
    return _conv1d(_conv1d(img, kx, 1), ky, 0)


def _smooth_abs(x):
    import jax.numpy as jnp

    return jnp.sqrt(x * x + SMOOTH * SMOOTH)


def _norm2(x, y):
    import jax.numpy as jnp

    return jnp.sqrt(x * x + y * y + SMOOTH * SMOOTH)


def _ycxcz(rgb):
    import jax.numpy as jnp

    xyz = (rgb @ jnp.asarray(_RGB2XYZ.T)) / jnp.asarray(_WHITE)
    return jnp.stack(
        [
            116 * xyz[..., 1] - 16,
            500 * (xyz[..., 0] - xyz[..., 1]),
            200 * (xyz[..., 1] - xyz[..., 2]),
        ],
        axis=-1,
    )


def _lab_hunt(ycxcz):
    """Filtered YCxCz -> linear RGB clamped to [0, 1] -> Hunt-adjusted CIELab (H, W, 3)."""
    import jax.numpy as jnp

    fy = (ycxcz[..., 0] + 16) / 116
    xyz = jnp.stack([fy + ycxcz[..., 1] / 500, fy, fy - ycxcz[..., 2] / 200], -1) * _WHITE
    rgb = jnp.clip(xyz @ jnp.asarray(_XYZ2RGB.T), 0.0, 1.0)
    t = (rgb @ jnp.asarray(_RGB2XYZ.T)) / jnp.asarray(_WHITE)
    d = 6 / 29
    cube = jnp.cbrt(jnp.maximum(t, d**3))
    f = jnp.where(t > d**3, cube, t / (3 * d * d) + 4 / 29)
    L = 116 * f[..., 1] - 16
    a = 500 * (f[..., 0] - f[..., 1])
    b = 200 * (f[..., 1] - f[..., 2])
    return jnp.stack([L, 0.01 * L * a, 0.01 * L * b], -1)


@lru_cache(maxsize=1)
def _cmax() -> float:
    """The Hunt-adjusted HyAB distance of pure green to pure blue, to the power ``qc``."""
    import jax
    import jax.numpy as jnp

    with jax.ensure_compile_time_eval():
        return _cmax_of(jnp)


def _cmax_of(jnp) -> float:
    green = _lab_hunt(_ycxcz(jnp.array([[[0.0, 1.0, 0.0]]])))[0, 0]
    blue = _lab_hunt(_ycxcz(jnp.array([[[0.0, 0.0, 1.0]]])))[0, 0]
    d = green - blue
    return float((abs(d[0]) + jnp.sqrt(d[1] ** 2 + d[2] ** 2)) ** QC)


def _filtered(ycxcz, f):
    import jax.numpy as jnp

    cz = sum(_sep(ycxcz[..., 2], k, k) for k in f["cz"])
    return jnp.stack(
        [
            _sep(ycxcz[..., 0], f["y"][0], f["y"][0]),
            _sep(ycxcz[..., 1], f["cx"][0], f["cx"][0]),
            cz,
        ],
        axis=-1,
    )


def _features(gray, f):
    """(edge magnitude, point magnitude) (H, W) of the achromatic channel ``gray``."""
    g, dg, ddg = f["feature"]
    edge = _norm2(_sep(gray, dg, g), _sep(gray, g, dg))
    point = _norm2(_sep(gray, ddg, g), _sep(gray, g, ddg))
    return edge, point


def flip_map(reference, test, ppd: float = PPD, knee: float = 0.0):
    """(H, W) LDR-FLIP map of ``test`` against ``reference`` ((H, W, 3) linear RGB, clipped to
    [0, 1] here), a JAX array; differentiable in both images (compiled once per shape).
    ``knee`` > 0 (HyAB units, where one unit is about a just noticeable difference) replaces
    ``HyAB ** qc`` by ``(HyAB^2 + knee^2) ** (qc / 2) - knee ** qc``: quadratic below the knee,
    FLIP's above it, so that a fit's loss has no cusp where an error crosses zero (the map is
    then not FLIP's: the fit's loss, not the metric). Computed in float64 (switches JAX to
    64-bit floats for the process, as a fit's residual does: ``jax_residual.enable_x64``)."""
    enable_x64()
    return _jitted("map")(reference, test, float(ppd), float(knee))


def flip_residual(reference, test, ppd: float = PPD, knee: float = 0.0):
    """(H, W, 3) residual whose squared norm per pixel is :func:`flip_map`'s value:
    ``sqrt(FLIP) * d / |d|`` with ``d`` the pixel's difference in the Hunt-adjusted CIELab of
    the colour pipeline. With ``knee`` > 0 it is linear in ``d`` near zero, so Gauss-Newton
    sees a smooth least-squares problem whose loss is half the sum of the (kneed) map. In
    float64, as :func:`flip_map`."""
    enable_x64()
    return _jitted("residual")(reference, test, float(ppd), float(knee))


@lru_cache(maxsize=2)
def _jitted(what: str):
    import jax
    import jax.numpy as jnp

    def residual(reference, test, ppd, knee):
        value, d = _flip_parts(reference, test, ppd, knee)
        norm = jnp.sqrt(jnp.sum(d * d, axis=-1, keepdims=True) + TINY)
        return jnp.sqrt(value + TINY)[..., None] * d / norm

    def value(reference, test, ppd, knee):
        return _flip_parts(reference, test, ppd, knee)[0]

    return jax.jit(residual if what == "residual" else value, static_argnums=(2, 3))


def _flip_parts(reference, test, ppd: float, knee: float):
    """(the FLIP map (H, W), the Hunt-adjusted CIELab difference (H, W, 3))."""
    import jax.numpy as jnp

    f = _filters(ppd)
    ref = _ycxcz(jnp.clip(jnp.asarray(reference, jnp.float64), 0.0, 1.0))
    tst = _ycxcz(jnp.clip(jnp.asarray(test, jnp.float64), 0.0, 1.0))

    d = _lab_hunt(_filtered(ref, f)) - _lab_hunt(_filtered(tst, f))
    hyab = _smooth_abs(d[..., 0]) + _norm2(d[..., 1], d[..., 2])
    if knee > 0:
        power = jnp.power(hyab * hyab + knee * knee, QC / 2) - knee**QC
    else:
        power = jnp.power(jnp.maximum(hyab, SMOOTH), QC)
    cmax = _cmax()
    bend = PC * cmax
    colour = jnp.where(
        power < bend, power * (PT / bend), PT + (power - bend) / (cmax - bend) * (1 - PT)
    )

    er, pr = _features((ref[..., 0] + 16) / 116, f)
    et, pt = _features((tst[..., 0] + 16) / 116, f)
    diff = jnp.maximum(_smooth_abs(er - et), _smooth_abs(pr - pt))
    feature = jnp.power(jnp.maximum(diff / np.sqrt(2), SMOOTH), QF)
    return jnp.power(jnp.maximum(colour, SMOOTH), 1 - feature), d
