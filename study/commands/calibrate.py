"""``study calibrate``: one command for every calibration, through the one pipeline of
``study.calibration`` (``study.calibration.run.calibrate``): a still experiment, its views, an
animation's frames, or several experiments fitted jointly."""

from __future__ import annotations

import time

from ..calibration.fitting import FitOptions, check_solver
from ..calibration.frames import load_frames
from ..calibration.run import calibrate


def run_calibrate(experiment, out, overrides=None, variant=None, solver=None, cache=None) -> dict:
    """``study calibrate``: reference (cached), fit, export, GL check, figures, report.md and
    constants.json in ``out``, for a shader of the study's space or a user's GLSL file alike.
    ``experiment``: one experiment file, or a list (fitted jointly: one constants block for all
    of them); an experiment with views is fitted on all its views, an animated one on all its
    frames. Returns the JSON object written."""
    t_start = time.perf_counter()
    check_solver(solver)  # before any rendering
    frames = load_frames(experiment, overrides, variant, cache)
    options = FitOptions.of(frames.first.exp, solver)
    return calibrate(frames, out, options, t_start=t_start)[0]
