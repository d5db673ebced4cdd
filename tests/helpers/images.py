"""Images of a failed comparison, written to ``tests/_failures/`` (ignored by git).

The writes are atomic (``study.write_exr``: a temporary file renamed into place), so two
pytest-xdist workers failing on the same name leave one whole file, never a torn one."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from helpers import TESTS

FAILURES = TESTS / "_failures"


def save_failure(name: str, **images) -> Path:
    """Write each of ``images`` (actual / expected / error, ...) to
    ``tests/_failures/<name>.<key>.exr``."""
    from study import write_exr

    FAILURES.mkdir(exist_ok=True)
    for key, img in images.items():
        write_exr(FAILURES / f"{name}.{key}.exr", img)
    return FAILURES


def save_comparison(name: str, actual: np.ndarray, expected: np.ndarray) -> Path:
    """Write the actual image and ``|actual - expected|``."""
    return save_failure(name, actual=actual, error=np.abs(actual - expected))
