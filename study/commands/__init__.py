"""The study's commands, one function per ``study`` subcommand; each writes its artifacts into
one folder. The work they share is the calibration pipeline of ``study.calibration`` (frames,
shader handle, fit, score, export, result); ``calibrate`` is one command for a still scene, its
views, several scenes or moving water, of the study's shaders or a user's own alike."""

from .calibrate import run_calibrate
from .export import run_export
from .generalise import run_generalise
from .render import run_preview, run_render
from .sweeps import run_failures, run_stability, run_tradeoff
from .viewer import run_viewer

__all__ = [
    "run_calibrate",
    "run_export",
    "run_failures",
    "run_generalise",
    "run_preview",
    "run_render",
    "run_stability",
    "run_tradeoff",
    "run_viewer",
]
