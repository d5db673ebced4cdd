"""The water-shader calibration study: experiments, Mitsuba references, shader inputs,
the fit of the shader's constants, export and reports.

No Mitsuba variant is set on import; the entry points call ``init_backend``.

Commands (what the CLI runs, ``study.commands``): ``run_render``, ``run_preview``,
``run_calibrate``, ``run_tradeoff``, ``run_export``. Sweeps: ``study.sweep`` (``run_sweep`` on
Dask).
Building blocks: experiments (``load_experiment``), references (``load_or_render``), shader
inputs (``build_shader_inputs``), the port against a reference (``ShaderModel``), the fit
(``FitProblem``, ``Param``, ``fit``, ``identify``, ``make_jax_residual``), export
(``export_shaders``, ``load_constants_json``), metrics (``rmse``, ``flip``).
"""

from ._backend import BackendError, init_backend
from ._io import read_exr, write_exr, write_png
from ._metrics import flip, rmse
from .commands import run_calibrate, run_export, run_preview, run_render, run_tradeoff
from .config.experiment import Experiment, ExperimentError, load_experiment, validate
from .export.shaders import export_shaders, load_constants_json
from .fit.jax_residual import DrJitResidual, NonFiniteResidualError, make_jax_residual
from .fit.identify import IdentifyReport, identify, probe_gradient_solver, sweep_1d, sweep_2d
from .fit.model import ShaderModel, constants_from_experiment
from .fit.solvers import SOLVERS, FitProblem, FitResult, Param, fit
from .scene.reference import Reference, load_or_render
from .scene.shader_inputs import build_shader_inputs

__all__ = [
    "BackendError",
    "init_backend",
    "DrJitResidual",
    "NonFiniteResidualError",
    "make_jax_residual",
    "Experiment",
    "ExperimentError",
    "load_experiment",
    "validate",
    "export_shaders",
    "load_constants_json",
    "read_exr",
    "write_exr",
    "write_png",
    "SOLVERS",
    "FitProblem",
    "FitResult",
    "Param",
    "fit",
    "IdentifyReport",
    "identify",
    "probe_gradient_solver",
    "sweep_1d",
    "sweep_2d",
    "run_calibrate",
    "run_export",
    "run_preview",
    "run_render",
    "run_tradeoff",
    "flip",
    "rmse",
    "ShaderModel",
    "constants_from_experiment",
    "Reference",
    "load_or_render",
    "build_shader_inputs",
]
