"""Progress lines redraw one line of stderr; the next message starts on a line of its own."""

from __future__ import annotations

import io
import sys

from study._progress import Stages, end_line, log, progress_line
from study.sweep.engine import Progress


def test_a_message_after_an_unfinished_bar_starts_its_own_line(monkeypatch):
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    bar = Stages().counter("  reference passes")
    bar(3, 8)  # the reference comes from the cache before the bar ends
    log("reference: cached out/r.exr")
    lines = err.getvalue().split("\n")
    assert lines[0].startswith("\r  reference passes: 3/8 (")
    assert lines[1] == "reference: cached out/r.exr" and lines[2] == ""


def test_a_finished_bar_is_ended_once(monkeypatch):
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    bar = Stages().counter("passes")
    bar(1, 2)
    bar(2, 2)
    log("next")
    text = err.getvalue()
    assert text.count("\n") == 2 and text.endswith("s)\nnext\n"), repr(text)


def test_a_shorter_redraw_covers_the_longer_line_it_replaces(monkeypatch):
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    progress_line("fit: evaluation 9, loss 0.0123456")
    progress_line("fit: evaluation 10, loss 0.5")
    end_line()
    last = err.getvalue().split("\r")[-1]
    assert last.rstrip("\n").rstrip() == "fit: evaluation 10, loss 0.5"
    assert len(last.rstrip("\n")) == len("fit: evaluation 9, loss 0.0123456")
    end_line()  # nothing open: nothing written
    assert err.getvalue().endswith(" \n") and err.getvalue().count("\n") == 1


def test_a_sweep_bar_left_open_is_ended_by_the_next_message(monkeypatch):
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    p = Progress("screen", 3)
    p.update(True)
    log("tradeoff: 1 job failed")
    before, after = err.getvalue().split("\n")[:2]
    assert "screen [" in before and "1/3" in before
    assert after == "tradeoff: 1 job failed"
