"""What every solver family records while it steps (the trace of losses and values) and how an
aborted residual becomes a result."""

from __future__ import annotations

import math
import time

import numpy as np

from .bridge import DrJitResidual


class Trace:
    """Lowest loss seen and seconds since the start, after each solver step."""

    def __init__(self, t0: float, loss0: float):
        self.t0, self.best = t0, loss0
        self.losses, self.seconds = [], []

    def note(self, loss: float) -> None:
        if math.isfinite(loss):
            self.best = min(self.best, float(loss))
        self.losses.append(self.best)
        self.seconds.append(time.perf_counter() - self.t0)

    def stalled(self, ftol: float | None, window: int) -> bool:
        """The lowest loss fell by less than ``ftol * loss`` over the last ``window`` steps."""
        if ftol is None or len(self.losses) <= window:
            return False
        return self.losses[-window - 1] - self.losses[-1] <= ftol * self.losses[-1]


def aborted(res: DrJitResidual, exc: Exception, u0, steps: int):
    """A jitted optimistix solve or step raised. A non-finite model value inside it (JAX wraps the
    callback's error) is reported and the best point evaluated returned, as the solvers' result
    tuple; any other error is a bug and propagates."""
    if not isinstance(res.last_error, FloatingPointError):
        raise (res.last_error or exc) from exc
    cause = res.last_error
    best = res.stats.best_x if res.stats.best_x is not None else np.asarray(u0)
    first = str(cause).strip().splitlines()[0] if str(cause).strip() else repr(cause)
    return (
        np.asarray(best),
        steps,
        False,
        (f"solver aborted ({type(cause).__name__}): {first}; returning the best point evaluated"),
    )
