"""The studies that run as sweeps on the Dask engine: ``study tradeoff``, ``study stability`` and
``study failures`` (``study.studies``); a re-run resumes from their tables."""

from __future__ import annotations

from .._progress import log as _log
from ..export.shaders import load_constants_json
from ..studies import failures, stability, tradeoff
from ..config.experiment import load_experiment
from ..scene.frames import refuse_animated


def run_tradeoff(
    experiments,
    out,
    overrides=None,
    variant=None,
    tolerance=None,
    scheduler=None,
    workers=None,
    search=None,
    budget=None,
) -> dict:
    """``study tradeoff``: the speed-versus-accuracy study over ``experiments`` on the sweep engine
    (``study.studies.tradeoff``); tables, ``pareto.png``, ``report.md`` and shaders in ``out``."""
    return tradeoff.run_tradeoff(
        list(experiments),
        out,
        overrides,
        scheduler=scheduler,
        workers=workers,
        tolerance=tolerance,
        variant=variant or "llvm_ad_rgb",
        log=_log,
        search=search,
        budget=budget,
    )


def run_stability(
    experiments, out, overrides=None, variant=None, scheduler=None, workers=None, **options
) -> dict:
    """``study stability``: solvers from many starts, which residual, reference noise
    (``study.studies.stability``); tables, charts and ``stability.md`` in ``out``."""
    refuse_animated_all(experiments, overrides, "study stability")
    return stability.run_stability(
        list(experiments),
        out,
        overrides,
        scheduler=scheduler,
        workers=workers,
        variant=variant or "llvm_ad_rgb",
        log=_log,
        **options,
    )


def run_failures(
    experiments,
    out,
    overrides=None,
    variant=None,
    shader=None,
    constants_json=None,
    scheduler=None,
    workers=None,
) -> list:
    """``study failures``: the failure catalogue of each experiment, one sweep job per experiment
    (``study.studies.failures``): ``<out>/<name>/failures.png``, ``failures.parquet``,
    ``report.md``."""
    refuse_animated_all(experiments, overrides, "study failures")

    constants = load_constants_json(constants_json) if constants_json else None
    return failures.run_failures(
        list(experiments),
        out,
        overrides,
        variant=variant or "llvm_ad_rgb",
        shader=shader,
        constants=constants,
        scheduler=scheduler,
        workers=workers,
        log=_log,
    )


def refuse_animated_all(experiments, overrides, command: str) -> None:
    """ExperimentError if any of ``experiments`` is animated (``command`` takes still frames)."""
    for path in experiments:
        refuse_animated(load_experiment(path, overrides), command)
