"""The water-shader calibration study: experiments, Mitsuba references, shader inputs,
the fit of the shader's constants, export and reports.

No Mitsuba variant is set on import; the entry points call ``init_backend``.
"""
from ._backend import BackendError, init_backend
from ._experiment import Experiment, ExperimentError, load_experiment, validate
from ._exr import read_exr, write_exr, write_png

__all__ = ["BackendError", "init_backend", "Experiment", "ExperimentError", "load_experiment",
           "validate", "read_exr", "write_exr", "write_png"]
