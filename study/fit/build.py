"""The fit's model for an experiment's shader, whichever kind it is.

``fit.shader`` names a shader of the study's space (a hand port: :class:`ShaderModel`) or a
user's GLSL file (``*.frag``, executed through SPIR-V: :class:`SpirvModel`); every command
builds its models here, so each takes either kind.
"""

from __future__ import annotations

import numpy as np

from ..config.experiment import Experiment
from ..config.user_shader import is_user_shader, load_user_shader
from .model import ShaderModel
from .protocol import ImageModel
from .spirv_model import SpirvModel


def build_model(
    exp: Experiment,
    inputs_full,
    reference_full: np.ndarray,
    shader: str | None = None,
    backend: str | None = None,
    resolution: tuple[int, int] | None = None,
    stderr_full: np.ndarray | None = None,
    translated: bool = False,
) -> ImageModel:
    """The model of ``shader`` (default ``fit.shader``; a user's file is read with the
    experiment's ``fit.declare``) at ``resolution`` (default ``fit.resolution``) against the
    box-downsampled ``reference_full`` ((H, W, 3) float32 linear RGB at the experiment's
    resolution); ``stderr_full``: its per-pixel standard error; ``translated``: a hand port's
    GLSL executed through SPIR-V in its place."""
    shader = shader or exp.fit.shader
    if is_user_shader(shader):
        user = load_user_shader({**exp.values, "fit.shader": shader})
        return SpirvModel.from_experiment(
            exp, inputs_full, reference_full, backend, resolution, stderr_full, shader=user
        )
    return ShaderModel.from_experiment(
        exp, inputs_full, reference_full, shader, backend, resolution, stderr_full, translated
    )
