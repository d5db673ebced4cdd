"""Progress and timing of long stages, printed to stderr.

``Stages`` times named stages (``with stages.stage("inputs.dry_s", "top-down render"):``),
prints a line when each starts and ends, and keeps the seconds in ``timings`` (the report's
timing table). ``stages.counter(label)`` returns a ``(done, total)`` callback that redraws
one progress line (``label: 3/8``). ``Stages(quiet=True)`` times without printing.
"""

from __future__ import annotations

import contextlib
import sys
import time


# the stream that holds a progress line not yet ended, and that line's length
_open_line: list = [None, 0]


def progress_line(text: str, final: bool = False, stream=None) -> None:
    """Redraw the one progress line on ``stream`` (stderr) as ``text``, over what it held
    (padded where shorter); ``final`` ends the line. A line left open is ended by the next
    :func:`log` or :func:`end_line`, so the next message starts on a line of its own."""
    stream = sys.stderr if stream is None else stream
    held = _open_line[1] if _open_line[0] is stream else 0
    if _open_line[0] is not None and _open_line[0] is not stream:
        end_line(_open_line[0])
    pad = " " * max(0, held - len(text))
    print("\r" + text + pad, end="\n" if final else "", file=stream, flush=True)
    _open_line[:] = [None, 0] if final else [stream, len(text)]


def end_line(stream=None) -> None:
    """End the progress line left open on ``stream`` (stderr), if any."""
    stream = sys.stderr if stream is None else stream
    if _open_line[0] is stream:
        _open_line[:] = [None, 0]
        print(file=stream, flush=True)


def log(msg: str) -> None:
    """One progress line on stderr, flushed (the study's log: stdout stays free for results),
    on a line of its own (after a progress line left open)."""
    end_line(sys.stderr)
    print(msg, file=sys.stderr, flush=True)


class Stages:
    """Named, timed stages with progress lines on stderr (see module docstring)."""

    def __init__(self, log=None, quiet: bool = False, prefix: str = ""):
        self.timings: dict[str, float] = {}
        self.quiet = quiet
        self.prefix = prefix
        self._log = log

    def log(self, msg: str) -> None:
        if self.quiet:
            return
        if self._log is not None:
            self._log(msg)
        else:
            log(msg)

    @contextlib.contextmanager
    def stage(self, key: str, label: str):
        """Time the enclosed block as ``timings[prefix + key]``; log its start and its seconds."""
        self.log(f"{label} ...")
        t0 = time.perf_counter()
        try:
            yield self
        finally:
            dt = time.perf_counter() - t0
            self.timings[self.prefix + key] = dt
        self.log(f"{label}: {dt:.1f} s")

    def counter(self, label: str):
        """A ``(done, total)`` callback drawing ``label: done/total (elapsed s)`` on one line."""
        t0 = time.perf_counter()

        def report(done: int, total: int) -> None:
            if self.quiet:
                return
            progress_line(
                f"{label}: {done}/{total} ({time.perf_counter() - t0:.1f} s)", done >= total
            )

        return report


def render_in_passes(mi, scene, sensor, spp: int, seed: int, progress=None, max_passes: int = 8):
    """``mi.render`` of ``spp`` samples as the mean of up to ``max_passes`` equal passes with
    seeds ``seed * max_passes + i`` (so progress can be shown between passes); the pass count
    is the largest divisor of ``spp`` not above ``max_passes``, so the total stays ``spp``.
    Returns a float32 NumPy array (H, W, C). Deterministic for a given (spp, seed)."""
    import numpy as np

    n = max(d for d in range(1, min(spp, max_passes) + 1) if spp % d == 0)
    acc = None
    for i in range(n):
        img = np.array(
            mi.render(scene, sensor=sensor, spp=spp // n, seed=seed * max_passes + i),
            dtype=np.float32,
        )
        acc = img if acc is None else acc + img
        if progress:
            progress(i + 1, n)
    return (acc / np.float32(n)).astype(np.float32)
