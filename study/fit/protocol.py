"""What the fit needs of a shader: the one interface every calibrated model implements.

:func:`study.fit.calibrate.calibrate_model` fits any :class:`CalibrationModel`:

* :class:`study.fit.model.ShaderModel`: a hand port of the study (or its GLSL executed through
  SPIR-V, ``translated=True``), constants a ``shaders_port.Constants``;
* :class:`study.fit.spirv_model.SpirvModel`: a user's GLSL file executed through SPIR-V,
  constants a dict ``{GLSL name: float | tuple}``;
* :class:`study.fit.joint.JointModel`: several scenes or frames of one shader, stacked;
* the losses of :mod:`study.fit.losses` (``fit.loss``): a model seen through another residual.

Constants are addressed by *scalar names*: ``NAME`` for a float, ``NAME[i]`` for a vector's
component (``study.fit.model.get_value`` / ``with_values`` read and set them in either kind of
constants). Residuals are (M,) float64 over the scored pixels and the RGB channels, linear RGB;
Jacobians (M, k) float64, one column per name.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class CalibrationModel(Protocol):
    """A shader against a reference, as the fit sees it."""

    #: the shader's name in reports (a variant's name, or the user's file name)
    label: str
    #: the shader's ``#define`` switches (empty for a user's file)
    defines: list[str]
    #: (H, W, 3) float32 Monte Carlo standard error of the reference, or None
    reference_stderr: np.ndarray | None

    def parameter_names(self, requested: list[str]) -> list[str]:
        """The scalar names to fit for the constants ``requested``."""

    def bounds(self, name: str) -> tuple[float, float]:
        """The range ``(lo, hi)`` of the scalar ``name``."""

    def start_constants(self, exp: Any = None) -> Any:
        """The constants the fit starts from (``exp``: the experiment, when it sets them)."""

    def residual(self, constants) -> np.ndarray:
        """(M,) float64: shader - reference on the scored pixels, RGB."""

    def residual_and_jacobian(self, constants, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """(residual (M,), Jacobian (M, len(names))) in the scalar ``names``."""

    def loss_ad(self, constants):
        """Dr.Jit loss ``0.5 * ||residual||^2`` with the AD graph of gradient-enabled
        constants attached (reverse mode, Adam); NotImplementedError where a model has none."""


@runtime_checkable
class ImageModel(CalibrationModel, Protocol):
    """A :class:`CalibrationModel` of one image: its reference, scored mask and renders."""

    #: (H, W, 3) float32 linear RGB
    reference: np.ndarray
    #: (H, W) bool: the scored water pixels
    mask: np.ndarray
    #: renders and Jacobian passes so far (cost counters)
    n_renders: int
    n_jacobians: int

    def render(self, constants) -> tuple[np.ndarray, Any]:
        """(image (H, W, 3) float32 linear RGB, ``study.fit.model.Diagnostics``)."""
