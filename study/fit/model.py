"""The shader port set up against one experiment's reference: what the fit and the preview call.

A :class:`ShaderModel` holds the shader inputs at the fit resolution, the reference
box-downsampled to it, and the scored water mask: pixels covered by the shader's water quad
*and* whose centre sees the water surface in the reference scene (not a wall in front of
it), eroded by one pixel. ``render`` returns the port's image; ``residual`` the masked, flattened
difference port - reference in linear RGB (unweighted: every water pixel and channel
counts the same); ``residual_and_jacobian`` adds the forward-mode Jacobian of the
residual with respect to named constants.
"""

from __future__ import annotations

import threading
import warnings
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from shaders_port import CONSTANT_SPECS, Constants, ShaderInputs
from shaders_port.pipeline.texture import backend_types, resolve_backend
from shaders_port.spirv.translated import Translated
from shaders_port.variants import get_variant

from .._metrics import downsample, downsample_stderr, erode
from ..config.experiment import Experiment
from ..scene.reference import water_mask
from ..scene.user_scene import sun_summary
from .normal_equations import LaneReduction

# ---- scalar names of constants: 'bumptex_mult', 'water_color[2]' (colours expand to RGB;
# alpha is not fitted since the shader's output alpha is not compared) ----


def expand_parameters(names: list[str]) -> list[str]:
    """['water_color', 'bumptex_mult'] -> ['water_color[0]', 'water_color[1]', 'water_color[2]',
    'bumptex_mult']."""
    out = []
    for n in names:
        if n not in CONSTANT_SPECS:
            raise ValueError(f"unknown constant {n!r}; known: {sorted(CONSTANT_SPECS)}")
        if CONSTANT_SPECS[n][1].endswith("vec4"):
            out += [f"{n}[{i}]" for i in range(3)]
        elif CONSTANT_SPECS[n][1].endswith("int"):
            raise ValueError(
                f"{n} is an integer loop cap: it belongs to the speed/accuracy study, not the fit"
            )
        else:
            out.append(n)
    return out


def split_name(name: str) -> tuple[str, int | None]:
    """'water_color[2]' -> ('water_color', 2); 'bumptex_mult' -> ('bumptex_mult', None)."""
    if name.endswith("]") and "[" in name:
        base, idx = name[:-1].split("[", 1)
        return base, int(idx)
    return name, None


def _component(c, base: str):
    return c[base] if isinstance(c, Mapping) else getattr(c, base)


def get_value(c: Constants | Mapping, name: str) -> float:
    """The scalar ``name`` of ``c``: a hand port's ``Constants`` or a SPIR-V shader's values
    ``{GLSL name: float | tuple}``."""
    base, idx = split_name(name)
    v = _component(c, base)
    return float(v[idx] if idx is not None else v)


def with_values(c: Constants | Mapping, values: dict) -> Constants | dict:
    """``c`` (``Constants``, or a dict ``{GLSL name: float | tuple}``) with scalar names set to
    ``values`` (floats, or Dr.Jit scalars for AD); a new object of the same kind."""
    changes: dict = {}
    for name, v in values.items():
        base, idx = split_name(name)
        if idx is None:
            changes[base] = v
        else:
            comps = list(changes.get(base, _component(c, base)))
            comps[idx] = v
            changes[base] = tuple(comps)
    return {**c, **changes} if isinstance(c, Mapping) else c.replace(**changes)


def constants_json(c: Constants | Mapping) -> dict:
    """``c`` as a JSON object: ``Constants.to_dict()``, or ``{GLSL name: float | list}``."""
    if isinstance(c, Mapping):
        return {k: [float(x) for x in v] if isinstance(v, (tuple, list)) else float(v)
                for k, v in c.items()}  # fmt: skip
    return c.to_dict()


def bounds(name: str) -> tuple[float, float]:
    """Valid range of a scalar name (the range of its constant)."""
    return CONSTANT_SPECS[split_name(name)[0]][3]


def constants_from_experiment(exp: Experiment) -> Constants:
    """The shader's start constants: the ``[constants]`` table of the experiment (defaults:
    the seed's numbers; the sun's disc's: the scene's sun, :func:`sun_disc_starts`)."""
    c = exp.section("constants")
    kw = {k: tuple(v) if isinstance(v, list) else v for k, v in c.items() if k in CONSTANT_SPECS}
    kw.update(sun_disc_starts(exp))
    return Constants(**kw).validate()


def sun_disc_starts(exp: Experiment) -> dict:
    """Start values of the sun's disc constants (``specular = disc``) the experiment leaves to
    the scene (``SUN_DISC_STARTS``): ``sun_disc_radius``, the sun's angular radius in degrees,
    and ``sun_disc_radiance``, the largest channel of its linear RGB radiance (``lightcolor`` is
    the radiance divided by it)."""
    keys = [k for k in ("sun_disc_radius", "sun_disc_radiance") if f"constants.{k}" in exp.auto]
    if not keys:
        return {}
    sun = sun_summary(exp)
    lo, hi = CONSTANT_SPECS["sun_disc_radius"][3]
    found = {
        "sun_disc_radius": min(max(sun.get("radius_deg", exp.sun.radius), lo), hi),
        "sun_disc_radiance": max(sun["radiance"]),
    }
    return {k: found[k] for k in keys}


def at_resolution(
    exp: Experiment,
    inputs_full: ShaderInputs,
    reference_full: np.ndarray,
    resolution: tuple[int, int] | None = None,
    stderr_full: np.ndarray | None = None,
    supersample: int = 1,
):
    """What a model of ``exp`` is built from at ``resolution`` (width, height; default
    ``fit.resolution``): (the inputs at ``supersample`` times that size, the shading grid,
    ``reference_full`` (H, W, 3) linear RGB box-downsampled to ``resolution``, ``stderr_full``
    (the reference's per-pixel Monte Carlo standard error) carried through the box filter
    (``study._metrics.downsample_stderr``) or None, the reference scene's water mask (H, W)
    bool at ``resolution``)."""
    w, h = resolution or exp.fit.resolution
    fy, fx = reference_full.shape[0] // h, reference_full.shape[1] // w
    ref = downsample(reference_full, fy, fx) if (fy, fx) != (1, 1) else reference_full
    se = None
    if stderr_full is not None:
        se = downsample_stderr(stderr_full, fy, fx) if (fy, fx) != (1, 1) else stderr_full
    shading = inputs_full.with_resolution(w * supersample, h * supersample)
    return shading, ref, se, water_mask(exp, w, h)


@dataclass
class Diagnostics:
    """Per-pixel diagnostics of one port render, as (H, W) float32 arrays."""

    maps: dict

    def summary(self, mask: np.ndarray) -> dict:
        out = {}
        for k, v in self.maps.items():
            vals = v[mask]
            out[k] = {
                "mean": float(vals.mean()),
                "max": float(vals.max()),
                "min": float(vals.min()),
            }
        if "crossed" in self.maps:
            out["not_crossed_fraction"] = float(1.0 - self.maps["crossed"][mask].mean())
        if "nonfinite" in self.maps:
            out["nonfinite_pixels"] = int(self.maps["nonfinite"][mask].sum())
        if "discarded" in self.maps:  # a user's shader that ran `discard`
            out["discarded_pixels"] = int(self.maps["discarded"][mask].sum())
        return out


# the side in fit pixels of the image tiles whose residuals may share a model error
# (``study.fit.rounds.tile_errors``)
TILE = 8

_DRJIT_LOCK = threading.RLock()
# diagnostics that flag a sample (1 where it is so): a folded pixel is flagged when any is
_FLAGS = frozenset({"nonfinite", "discarded"})


def _thread_handoff(fn):
    """Model methods run on whatever thread calls them, including a solver's callback threads
    (``jax.pure_callback``), which XLA may run concurrently. Dr.Jit must not be entered by
    two threads at once (measured: a segmentation fault inside the Jacobian pass), and arrays
    shared between threads need a new Dr.Jit scope before and after: both are done here."""
    import functools

    @functools.wraps(fn)
    def wrapper(self, *a, **k):
        import drjit as dr

        be = dr.JitBackend.CUDA if self.backend == "cuda" else dr.JitBackend.LLVM
        with _DRJIT_LOCK:
            dr.detail.new_scope(be)
            try:
                return fn(self, *a, **k)
            finally:
                dr.detail.new_scope(be)

    return wrapper


class ReferenceModel:
    """A shader's renders of ``inputs`` against ``reference`` ((H, W, 3) float32 linear RGB, the
    inputs' size): the scored mask, residuals, Jacobians and the reverse-mode loss; the
    shader itself is two hooks, :meth:`_shade` (a ``ShaderOutput`` at given constants) and
    :meth:`_shade_with_jacobian` (with the image Jacobian (H, W, 3, k)). ``reference_mask``:
    (H, W) bool, the reference scene's water (the scored mask is the shader's coverage and it,
    eroded by one pixel); ``reference_stderr``: (H, W, 3) float32, the reference's Monte Carlo
    standard error per pixel, or None; ``backend``: "llvm" or "cuda", None for the run's
    (``shaders_port.pipeline.texture.resolve_backend``, set by ``study._backend.init_backend``).

    ``supersample`` (an int s >= 1): the shader runs on ``inputs`` of s times the reference's
    width and height, s x s samples at the sub-pixel centres of each fit pixel, and every image
    it gives (colour, Jacobian, diagnostics) is the box mean of its s x s samples
    (:meth:`fold`): a fit pixel sees the shading of the finer pixels of the resolution the
    shader runs at in the game (``fit.target_resolution``), not one sample at its centre. A
    pixel is in the scored mask only when the water covers all its samples."""

    #: what non-finite water pixels are called in errors
    what = "the port"

    def __init__(self, inputs, reference, backend=None, reference_mask=None,
                 reference_stderr=None, supersample: int = 1):  # fmt: skip
        self.inputs, self.backend = inputs, resolve_backend(backend)
        self.supersample = s = int(supersample)
        if (
            s < 1
            or reference.shape != (inputs.height // s, inputs.width // s, 3)
            or (inputs.height % s or inputs.width % s)
        ):
            raise ValueError(
                f"reference is {reference.shape}, inputs are {inputs.height}x{inputs.width}, "
                f"supersample {supersample}: the inputs must be supersample times the reference"
            )
        if reference_stderr is not None and reference_stderr.shape != reference.shape:
            raise ValueError(
                f"reference_stderr is {reference_stderr.shape}, the reference {reference.shape}"
            )
        self.reference = np.asarray(reference, np.float32)
        self.reference_stderr = (
            None if reference_stderr is None else np.asarray(reference_stderr, np.float32)
        )
        out = self.fold(self._shade(self.start_constants()).numpy())
        mask = out["mask"] > 1.0 - 1e-6  # every sample of the pixel on the water
        if "discarded" in out:  # pixels the shader discards (at its start constants) are no water
            mask &= out["discarded"] == 0
        if reference_mask is not None:
            mask &= reference_mask
        self.mask = erode(mask, 1)
        if not self.mask.any():
            raise ValueError("no water pixel in view: check the camera and pool.half_extent")
        if not np.isfinite(self.reference[self.mask]).all():
            raise ValueError("the reference has non-finite water pixels; render it again")
        self.n_renders = 0
        self.n_jacobians = 0

    def fold(self, images):
        """``images`` (an (sH, sW, ...) array, or a dict of them) at the shading grid ->
        the box mean of each pixel's s x s samples, (H, W, ...) (identity when s = 1)."""
        s = self.supersample
        if s == 1:
            return images
        if isinstance(images, Mapping):  # a flag (non-finite, discarded): any of the samples
            return {k: self._fold_any(v) if k in _FLAGS else self.fold(v)
                    for k, v in images.items()}  # fmt: skip
        a = np.asarray(images)
        return downsample(a, s, s).astype(a.dtype, copy=False)

    def _fold_any(self, flag):
        s = self.supersample
        a = np.asarray(flag)
        h, w = a.shape[0] // s, a.shape[1] // s
        return a.reshape(h, s, w, s, *a.shape[2:]).max(axis=(1, 3))

    def residual_tiles(self, size: int = TILE) -> np.ndarray:
        """(M,) int: the image tile (``size`` x ``size`` fit pixels, numbered row-major) of each
        entry of :meth:`residual` (water pixels in row-major order, three channels each)."""
        ys, xs = np.nonzero(self.mask)
        cols = -(-self.mask.shape[1] // size)
        return np.repeat((ys // size) * cols + xs // size, 3)

    def _shade(self, constants):
        raise NotImplementedError

    def _shade_with_jacobian(self, constants, names: list[str], lanes=None):
        raise NotImplementedError

    def start_constants(self, exp: Experiment | None = None):
        raise NotImplementedError

    @_thread_handoff
    def render(self, constants) -> tuple[np.ndarray, Diagnostics]:
        """The shader's image (H, W, 3) float32 linear RGB and its diagnostics."""
        with warnings.catch_warnings():
            warnings.simplefilter(
                "ignore", RuntimeWarning
            )  # non-finite pixels are in the diagnostics
            out = self.fold(self._shade(constants).numpy())
        self.n_renders += 1
        return out["color"], Diagnostics(
            {k: v for k, v in out.items() if k not in ("color", "mask")}
        )

    @_thread_handoff
    def residual(self, constants) -> np.ndarray:
        """(M,) float64 shader - reference over water pixels and RGB channels."""
        img, diag = self.render(constants)
        self._check(diag, constants)
        return (img[self.mask] - self.reference[self.mask]).astype(np.float64).ravel()

    @_thread_handoff
    def residual_and_jacobian(self, constants, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """(residual (M,), J (M, k)) with J the derivative w.r.t. the named scalar constants."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            out, jac = self._shade_with_jacobian(constants, names)
        o = self.fold(out.numpy())
        jac = self.fold(np.asarray(jac))
        self.n_jacobians += 1
        self._check(Diagnostics({k: v for k, v in o.items() if k not in ("color", "mask")}),
                    constants)  # fmt: skip
        r = (o["color"][self.mask] - self.reference[self.mask]).astype(np.float64).ravel()
        J = np.asarray(jac)[self.mask].reshape(-1, len(names)).astype(np.float64)
        if not np.all(np.isfinite(J)):
            raise FloatingPointError(f"{self.label}: non-finite Jacobian entries for {names}")
        return r, J

    @_thread_handoff
    def normal_equations(self, constants, names: list[str]):
        """The ``study.fit.normal_equations.NormalEquations`` of :meth:`residual_and_jacobian`
        with respect to the named scalar constants, formed in Dr.Jit where the shader runs
        (only the (k + 1)^2 numbers come back)."""
        if getattr(self, "_lane_reduction", None) is None:
            self._lane_reduction = LaneReduction(self.mask, self.reference, self.supersample)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            ne = self._shade_with_jacobian(constants, names, lanes=self._lane_reduction)
        self.n_jacobians += 1
        if ne.nonfinite:
            raise FloatingPointError(
                f"{self.what} produced {ne.nonfinite} non-finite water pixels at "
                f"{_constants_text(constants)}; " + _NOT_FINITE_FIX
            )
        if not (np.all(np.isfinite(ne.A)) and np.all(np.isfinite(ne.g))):
            raise FloatingPointError(f"{self.label}: non-finite Jacobian entries for {names}")
        return ne

    @_thread_handoff
    def loss_ad(self, constants):
        """Dr.Jit loss ``0.5 * sum over water pixels and channels of (shader - reference)^2``
        with the AD graph of any gradient-enabled constant attached (for reverse mode)."""
        import drjit as dr

        m = backend_types(self.backend)
        if not hasattr(self, "_ref_t"):
            self._ref_t = m.TensorXf(self.reference)
            self._mask_t = m.TensorXf(np.repeat(self.mask[..., None], 3, -1).astype(np.float32))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            out = self._shade(constants)
        self.n_renders += 1
        bad = out.diagnostics.get("nonfinite")
        if bad is not None and self.supersample > 1:  # a mean of flags is > 0 where any is
            bad = self._fold_ad(bad)
        if bad is not None and float(dr.sum(bad * self._mask_t[..., 0], axis=None).array[0]) > 0:
            raise FloatingPointError(
                f"{self.what} produced non-finite water pixels; see the 'nonfinite' diagnostic"
            )
        d = (self._fold_ad(out.color) - self._ref_t) * self._mask_t
        return (0.5 * dr.sum(d * d, axis=None)).array  # a size-1 Float

    def _fold_ad(self, image):
        """:meth:`fold` of a Dr.Jit (sH, sW, ...) tensor, kept in the AD graph."""
        import drjit as dr

        s = self.supersample
        if s == 1:
            return image
        h, w = self.reference.shape[:2]
        blocks = dr.reshape(type(image), image, (h, s, w, s, *image.shape[2:]))
        return dr.sum(dr.sum(blocks, axis=3), axis=1) * (1.0 / (s * s))

    def _check(self, diag: Diagnostics, constants=None) -> None:
        """FloatingPointError naming how many water pixels are non-finite, the first of them
        and the constants ``constants`` they came from (a dict or a dataclass of them)."""
        bad = diag.maps.get("nonfinite")
        if bad is None or not bad[self.mask].any():
            return
        ys, xs = np.nonzero((np.asarray(bad) != 0) & self.mask)
        at = _constants_text(constants)
        raise FloatingPointError(
            f"{self.what} produced {int(bad[self.mask].sum())} non-finite water pixels (first "
            f"at pixel ({xs[0]}, {ys[0]}))" + (f" at {at}" if at else "") + "; " + _NOT_FINITE_FIX
        )


_NOT_FINITE_FIX = (
    "the shader is not finite over its constants' ranges: narrow the range of the constant that "
    "reaches there (the fit's steps stay within the ranges)"
)


def _constants_text(constants) -> str:
    """``constants`` (a dict or a dataclass of them) as ``name=value, ...``."""
    vals = constants if isinstance(constants, dict) else getattr(constants, "__dict__", {})
    return ", ".join(f"{k}={np.round(np.asarray(v, float), 6).tolist()}" for k, v in vals.items())


class ShaderModel(ReferenceModel):
    """The port of the shader variant ``shader`` (a name in ``shaders_port.variants.VARIANTS``)
    on ``inputs`` compared against ``reference`` (same size; :class:`ReferenceModel`);
    ``translated``: the variant's GLSL executed through SPIR-V
    (``shaders_port.spirv.translated``) in place of its port. Constants are
    ``shaders_port.Constants``."""

    def __init__(
        self,
        shader: str,
        inputs: ShaderInputs,
        reference: np.ndarray,
        backend: str | None = None,
        reference_mask: np.ndarray | None = None,
        reference_stderr: np.ndarray | None = None,
        translated: bool = False,
        supersample: int = 1,
    ):
        self.shader = shader
        self.variant = get_variant(shader)
        if translated:  # its GLSL file executed through SPIR-V in place of the hand port
            self.variant = Translated(self.variant)
        super().__init__(inputs, reference, backend, reference_mask, reference_stderr, supersample)

    @classmethod
    def from_experiment(
        cls,
        exp: Experiment,
        inputs_full: ShaderInputs,
        reference_full: np.ndarray,
        shader: str | None = None,
        backend: str | None = None,
        resolution: tuple[int, int] | None = None,
        stderr_full: np.ndarray | None = None,
        translated: bool = False,
        supersample: int = 1,
    ) -> "ShaderModel":
        """The model at ``resolution`` (default ``fit.resolution``) against the box-downsampled
        ``reference_full``, shaded ``supersample`` x ``supersample`` per pixel
        (:func:`at_resolution`)."""
        inputs, ref, se, water = at_resolution(
            exp, inputs_full, reference_full, resolution, stderr_full, supersample
        )
        return cls(
            shader or exp.fit.shader,
            inputs,
            ref,
            backend,
            reference_mask=water,
            reference_stderr=se,
            translated=translated,
            supersample=supersample,
        )

    # ---- the parameters (``study.fit.protocol.CalibrationModel``) ----------------------------
    @property
    def label(self) -> str:
        """The variant's name, as reports and exports call the shader."""
        return self.shader

    @property
    def defines(self) -> list[str]:
        """The variant's ``#define`` switches."""
        return list(self.variant.defines)

    def parameter_names(self, requested: list[str]) -> list[str]:
        """The scalar names fitted for the seed's constants ``requested``: a variant fits its
        own in their place (``Variant.fit_names``, e.g. the Beer-Lambert absorptions for
        ``attenuation_distance``); colours expand to RGB."""
        return expand_parameters(self.variant.fit_names(requested))

    def bounds(self, name: str) -> tuple[float, float]:
        """The range of the scalar ``name`` (that of its constant in ``CONSTANT_SPECS``)."""
        return bounds(name)

    def start_constants(self, exp: Experiment | None = None) -> Constants:
        """The start constants: the experiment's ``[constants]`` table, else the seed's."""
        return Constants() if exp is None else constants_from_experiment(exp)

    # ---- the shader ------------------------------------------------------------------------
    def _shade(self, constants: Constants):
        return self.variant.render(self.inputs, constants, backend=self.backend)

    def _shade_with_jacobian(self, constants: Constants, names: list[str], lanes=None):
        return self.variant.render_with_jacobian(
            self.inputs, constants, names, backend=self.backend, lanes=lanes
        )
