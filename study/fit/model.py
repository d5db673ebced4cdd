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
from dataclasses import dataclass

import numpy as np

from shaders_port import CONSTANT_SPECS, Constants, ShaderInputs
from shaders_port.variants import get_variant

from ..scene.experiment import Experiment
from .._metrics import downsample, downsample_stderr, erode


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


def get_value(c: Constants, name: str) -> float:
    base, idx = split_name(name)
    v = getattr(c, base)
    return float(v[idx] if idx is not None else v)


def with_values(c: Constants, values: dict) -> Constants:
    """``c`` with scalar names set to ``values`` (floats, or Dr.Jit scalars for AD)."""
    changes: dict = {}
    for name, v in values.items():
        base, idx = split_name(name)
        if idx is None:
            changes[base] = v
        else:
            comps = list(changes.get(base, getattr(c, base)))
            comps[idx] = v
            changes[base] = tuple(comps)
    return c.replace(**changes)


def bounds(name: str) -> tuple[float, float]:
    """Valid range of a scalar name (the range of its constant)."""
    return CONSTANT_SPECS[split_name(name)[0]][3]


def constants_from_experiment(exp: Experiment) -> Constants:
    """The shader's start constants: the ``[constants]`` table of the experiment (defaults:
    the seed's numbers)."""
    c = exp.section("constants")
    kw = {k: tuple(v) if isinstance(v, list) else v for k, v in c.items() if k in CONSTANT_SPECS}
    return Constants(**kw).validate()


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
        return out


_DRJIT_LOCK = threading.RLock()


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


class ShaderModel:
    """The port of the shader variant ``shader`` (a name in ``shaders_port.variants.VARIANTS``)
    on ``inputs`` compared against ``reference`` (same size); ``translated``: the variant's
    GLSL executed through SPIR-V (``shaders_port.spirv.translated``) in place of its port."""

    def __init__(
        self,
        shader: str,
        inputs: ShaderInputs,
        reference: np.ndarray,
        backend: str = "llvm",
        reference_mask: np.ndarray | None = None,
        reference_stderr: np.ndarray | None = None,
        translated: bool = False,
    ):
        self.shader, self.inputs, self.backend = shader, inputs, backend
        self.variant = get_variant(shader)
        if translated:  # its GLSL file executed through SPIR-V in place of the hand port
            from shaders_port.spirv.translated import Translated

            self.variant = Translated(self.variant)
        if reference.shape != (inputs.height, inputs.width, 3):
            raise ValueError(
                f"reference is {reference.shape}, inputs are {inputs.height}x{inputs.width}"
            )
        if reference_stderr is not None and reference_stderr.shape != reference.shape:
            raise ValueError(
                f"reference_stderr is {reference_stderr.shape}, the reference {reference.shape}"
            )
        self.reference = np.asarray(reference, np.float32)
        # (H, W, 3) float32 Monte Carlo standard error of each reference pixel (linear RGB), or None
        self.reference_stderr = (
            None if reference_stderr is None else np.asarray(reference_stderr, np.float32)
        )
        out = self.variant.render(inputs, Constants(), backend=backend).numpy()
        mask = out["mask"] > 0.5
        if reference_mask is not None:
            mask &= reference_mask
        self.mask = erode(mask, 1)
        if not self.mask.any():
            raise ValueError("no water pixel in view: check the camera and pool.half_extent")
        self.n_renders = 0
        self.n_jacobians = 0

    @classmethod
    def from_experiment(
        cls,
        exp: Experiment,
        inputs_full: ShaderInputs,
        reference_full: np.ndarray,
        shader: str | None = None,
        backend: str = "llvm",
        resolution: tuple[int, int] | None = None,
        stderr_full: np.ndarray | None = None,
        translated: bool = False,
    ) -> "ShaderModel":
        """The model at ``resolution`` (default ``fit.resolution``) against the box-downsampled
        ``reference_full`` (H, W, 3); ``stderr_full`` (H, W, 3), the reference's per-pixel Monte
        Carlo standard error, is carried through the box filter
        (``study._metrics.downsample_stderr``) for :func:`study.fit.calibrate.noise_errors`."""
        from ..scene.reference import water_mask

        w, h = resolution or exp["fit.resolution"]
        fy, fx = reference_full.shape[0] // h, reference_full.shape[1] // w
        ref = downsample(reference_full, fy, fx) if (fy, fx) != (1, 1) else reference_full
        se = None
        if stderr_full is not None:
            se = downsample_stderr(stderr_full, fy, fx) if (fy, fx) != (1, 1) else stderr_full
        return cls(
            shader or exp["fit.shader"],
            inputs_full.with_resolution(w, h),
            ref,
            backend,
            reference_mask=water_mask(exp, w, h),
            reference_stderr=se,
            translated=translated,
        )

    @_thread_handoff
    def render(self, constants: Constants) -> tuple[np.ndarray, Diagnostics]:
        """Port image (H, W, 3) float32 linear RGB and its diagnostics."""
        with warnings.catch_warnings():
            warnings.simplefilter(
                "ignore", RuntimeWarning
            )  # non-finite pixels are in the diagnostics
            out = self.variant.render(self.inputs, constants, backend=self.backend).numpy()
        self.n_renders += 1
        return out["color"], Diagnostics(
            {k: v for k, v in out.items() if k not in ("color", "mask")}
        )

    @_thread_handoff
    def residual(self, constants: Constants) -> np.ndarray:
        """(M,) float64 port - reference over water pixels and RGB channels."""
        img, diag = self.render(constants)
        self._check(diag)
        return (img[self.mask] - self.reference[self.mask]).astype(np.float64).ravel()

    @_thread_handoff
    def residual_and_jacobian(
        self, constants: Constants, names: list[str]
    ) -> tuple[np.ndarray, np.ndarray]:
        """(residual (M,), J (M, k)) with J the derivative w.r.t. the named scalar constants."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            out, jac = self.variant.render_with_jacobian(
                self.inputs, constants, names, backend=self.backend
            )
        o = out.numpy()
        self.n_jacobians += 1
        self._check(Diagnostics({k: v for k, v in o.items() if k not in ("color", "mask")}))
        r = (o["color"][self.mask] - self.reference[self.mask]).astype(np.float64).ravel()
        J = np.asarray(jac)[self.mask].reshape(-1, len(names)).astype(np.float64)
        if not np.all(np.isfinite(J)):
            raise FloatingPointError(f"non-finite Jacobian entries for {names}")
        return r, J

    @_thread_handoff
    def loss_ad(self, constants: Constants):
        """Dr.Jit loss ``0.5 * sum over water pixels and channels of (port - reference)^2`` with
        the AD graph of any gradient-enabled constant attached (for reverse mode)."""
        import drjit as dr

        from shaders_port.pipeline.texture import backend_types

        m = backend_types(self.backend)
        if not hasattr(self, "_ref_t"):
            self._ref_t = m.TensorXf(self.reference)
            self._mask_t = m.TensorXf(np.repeat(self.mask[..., None], 3, -1).astype(np.float32))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            out = self.variant.render(self.inputs, constants, backend=self.backend)
        self.n_renders += 1
        bad = out.diagnostics.get("nonfinite")
        if bad is not None and float(dr.sum(bad * self._mask_t[..., 0], axis=None).array[0]) > 0:
            raise FloatingPointError(
                "the port produced non-finite water pixels; see the 'nonfinite' diagnostic"
            )
        d = (out.color - self._ref_t) * self._mask_t
        return (0.5 * dr.sum(d * d, axis=None)).array  # a size-1 Float

    def _check(self, diag: Diagnostics) -> None:
        bad = diag.maps.get("nonfinite")
        if bad is not None and bad[self.mask].any():
            raise FloatingPointError(
                f"the port produced {int(bad[self.mask].sum())} non-finite water "
                "pixels; see the 'nonfinite' diagnostic"
            )
