"""A user's own GLSL shader against a reference: the fit's model of a shader executed through
SPIR-V.

:class:`SpirvModel` is a :class:`~study.fit.model.ReferenceModel` (the scored mask, residuals,
Jacobians, non-finite checks) whose shader is a ``shaders_port.spirv.user_shader.UserShader``: its
renders and forward-mode derivatives come from the SPIR-V executor, its constants are a dict
``{GLSL name: float | tuple}`` (scalar names ``NAME`` and ``NAME[i]``), its parameters and their
ranges are those its declaration names (``// @study constant NAME LOW HIGH`` or
``fit.declare``). :func:`study.fit.calibrate.calibrate_model` fits it as it fits a hand port.
"""

from __future__ import annotations

import warnings

import numpy as np

from shaders_port.spirv.dialects import ShaderError

from ..config.experiment import Experiment
from ..config.user_shader import load_user_shader
from .model import ReferenceModel, at_resolution


class SpirvModel(ReferenceModel):
    """``shader`` (a ``UserShader``) on ``inputs`` (``shaders_port.ShaderInputs``) against
    ``reference`` ((H, W, 3) float32 linear RGB at the inputs' size); the rest as
    :class:`~study.fit.model.ReferenceModel`."""

    what = "the shader"

    def __init__(self, shader, inputs, reference: np.ndarray, backend: str | None = None,
                 reference_mask=None, reference_stderr=None, supersample: int = 1):  # fmt: skip
        self.user_shader = shader
        super().__init__(inputs, reference, backend, reference_mask, reference_stderr, supersample)
        self.check_vertex_constants()

    @classmethod
    def from_experiment(
        cls,
        exp: Experiment,
        inputs_full,
        reference_full: np.ndarray,
        backend: str | None = None,
        resolution: tuple[int, int] | None = None,
        stderr_full: np.ndarray | None = None,
        shader=None,
        supersample: int = 1,
    ) -> "SpirvModel":
        """The model of ``shader`` (default: ``fit.shader`` with ``fit.declare``) at
        ``resolution`` (default ``fit.resolution``) against the box-downsampled
        ``reference_full`` (``study.fit.model.at_resolution``)."""
        inputs, ref, se, water = at_resolution(
            exp, inputs_full, reference_full, resolution, stderr_full, supersample
        )
        shader = shader or load_user_shader(exp.values)
        with warnings.catch_warnings():  # check_finite says it, with the pixels
            warnings.filterwarnings("ignore", r".*were non-finite", RuntimeWarning)
            model = cls(shader, inputs, ref, backend, water, se, supersample)
        model.check_finite()
        return model

    def check_finite(self, constants: dict | None = None) -> None:
        """ShaderError if the shader's colour with ``constants`` (default: the start values) is
        NaN or infinite on some water pixel: how many, the first few (x, y) pixel coordinates
        (x from the left, y from the top, at the model's resolution) and their bounding box."""
        with warnings.catch_warnings():  # the error below says it, with the pixels
            warnings.filterwarnings("ignore", r".*were non-finite", RuntimeWarning)
            out = self.user_shader.render(self.inputs, constants, backend=self.backend).numpy()
        bad = (self.fold(out)["nonfinite"] > 0.5) & self.mask
        if not bad.any():
            return
        ys, xs = np.nonzero(bad)
        first = ", ".join(f"({x}, {y})" for x, y in list(zip(xs, ys))[:5])
        h, w = bad.shape
        raise ShaderError(
            f"{self.label}: the shader's colour is not finite (NaN or inf) on {int(bad.sum())} of "
            f"{int(self.mask.sum())} water pixels at the start values ({w}x{h}; pixel (x, y) "
            f"from the top left: {first}; all within x {xs.min()}..{xs.max()}, y "
            f"{ys.min()}..{ys.max()}); guard what can fail there (sqrt or log of a negative, "
            "pow of a negative base, a division by zero, normalize of a zero vector)"
        )

    def check_vertex_constants(self) -> None:
        """ShaderError for a constant only the user's vertex shader reads that moves the
        vertices (``gl_Position``) but changes the colour of no scored pixel at its start value:
        it changes only which pixels the water covers, which the fit does not see (its
        derivatives hold the coverage fixed)."""
        shader = self.user_shader
        if shader.vertex is None:
            return
        names = [s for n, c in shader.constants.items() if shader.stage_of(n) == "vertex"
                 for s in c.scalar_names()]  # fmt: skip
        if not names:
            return
        moves = shader.vertex_motion(self.inputs, None, names, self.backend)
        if not any(moves):
            return
        _, J = self._shade_with_jacobian(shader.defaults(), names)
        J = self.fold(np.asarray(J))
        for j, s in enumerate(names):
            if moves[j] > 0.0 and not np.any(J[..., j][self.mask]):
                raise ShaderError(
                    f"{shader.vertex.label}: the constant {s} moves the vertices (gl_Position) "
                    f"but changes no interpolant {shader.label} reads: it changes only which "
                    "pixels the water covers, which the fit does not see (its derivatives hold "
                    f"the coverage fixed); remove {s.split('[')[0]} from the declaration, or "
                    "pass on what it shapes as an output the fragment shader reads"
                )

    # ---- the parameters (``study.fit.protocol.CalibrationModel``) ----------------------------
    @property
    def label(self) -> str:
        """The shader's file name."""
        return self.user_shader.label

    @property
    def shader(self) -> str:
        return self.user_shader.label

    defines: list = []

    def parameter_names(self, requested: list[str] | None) -> list[str]:
        """The scalar names of the declared constants ``requested`` (every declared one when
        None): each float, and a vector's first three components (RGB; an alpha is never
        compared)."""
        constants = self.user_shader.constants
        if requested is None:
            return self.user_shader.scalar_names()
        unknown = [n for n in requested if n not in constants]
        if unknown:
            raise ValueError(
                f"{self.label}: {', '.join(unknown)} is no constant of its declaration; it "
                f"declares {', '.join(constants)}"
            )
        return [s for n in requested for s in constants[n].scalar_names()]

    def bounds(self, name: str) -> tuple[float, float]:
        """The declared range of the scalar ``name``."""
        return self.user_shader.bounds(name)

    def start_constants(self, exp: Experiment | None = None) -> dict:
        """The declaration's start values: each constant's initializer in the file."""
        return self.user_shader.defaults()

    # ---- the shader ------------------------------------------------------------------------
    def _shade(self, constants: dict):
        return self.user_shader.render(self.inputs, constants, backend=self.backend)

    def _shade_with_jacobian(self, constants: dict, names: list[str], lanes=None):
        return self.user_shader.render_with_jacobian(
            self.inputs, constants, names, backend=self.backend, lanes=lanes
        )

    def loss_ad(self, constants):
        raise NotImplementedError(
            f"{self.label}: a shader executed through SPIR-V has forward-mode derivatives only; "
            "fit it with a least-squares solver (fit.solver = levenberg_marquardt, dogleg, ...), "
            "not Adam"
        )
