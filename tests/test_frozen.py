"""Frozen kernels (``dr.freeze``, opt-in through ``pipeline.frame.USE_FROZEN``): a replay never
returns a wrong shape, each configuration records a bounded number of times, and replays equal
traces.

The reduction of the defect: a frozen function whose body builds a value of width
``dr.width(x)`` (a Python int, baked into the recording) replays it at the recorded width when
called with another lane count, so the outputs come back ragged (:func:`_width_literal`).
"""

from __future__ import annotations

import dataclasses
import warnings

import drjit as dr
import numpy as np
import pytest

from helpers.synthetic import synthetic_inputs
from shaders_port import Constants
from shaders_port.pipeline import frame as _frame
from shaders_port.ports import water_reflection, water_refraction
from shaders_port.pipeline.texture import backend_types

m = backend_types("llvm")


def _width_literal(x):
    return x + 1.0, dr.zeros(m.Float, dr.width(x))


def _lanes(n):
    return m.Float(np.linspace(0.0, 1.0, n, dtype=np.float32))


@dataclasses.dataclass
class _Frame:
    """The part of a port's shading state that call_frozen reads: lanes and upload number."""

    varyingVecWorldPosition: object
    upload: int = 0


def _frame_of(n, upload=0):
    return _Frame(m.Array3f(_lanes(n), 0.0, 0.0), upload)


def _shade_width_literal(m, P):
    return _width_literal(P.varyingVecWorldPosition.x)


def test_dr_freeze_replays_a_width_literal_at_the_recorded_width():
    """The defect itself, in Dr.Jit 1.5.0: called with 10, 20, 10, 30 lanes, some replay
    returns the second output at a recorded width (which call depends on whether the first
    recording's inputs were made opaque: 20 lanes -> 10 wide, or 30 -> 20). If this ever
    fails, Dr.Jit keys such recordings itself and the guard in call_frozen is belt and braces."""
    f = dr.freeze(_width_literal)
    widths = [(n,) + tuple(dr.width(v) for v in f(_lanes(n))) for n in (10, 20, 10, 30)]
    assert all(w[1] == w[0] for w in widths)  # the first output follows its input
    assert any(w[2] != w[0] for w in widths), widths  # the baked width does not


def test_call_frozen_replays_literal_outputs_at_the_lane_count(monkeypatch):
    """The same function through call_frozen, one frame (upload) at four lane counts: its
    literal output leaves the recording as a value and comes back at the caller's lane count;
    no warning, nothing traced."""
    monkeypatch.setattr(_frame, "USE_FROZEN", True)
    monkeypatch.setattr(_frame, "_BROKEN", set())
    key = ("width_literal_packed_test",)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for n in (10, 20, 10, 30):
            a, b = _frame.call_frozen(key, _shade_width_literal, m, _frame_of(n))
            assert dr.width(a) == dr.width(b) == n and not b.numpy().any()
    assert key not in _frame._BROKEN and _frame._FROZEN.pop(key + (0,)).n_recordings <= 2


def test_call_frozen_never_passes_a_ragged_replay_on(monkeypatch):
    """A recording that still bakes a width (here the raw function, frozen without packing) is
    caught by the width check: the call is traced once, with one warning, and from then on."""
    monkeypatch.setattr(_frame, "USE_FROZEN", True)
    monkeypatch.setattr(_frame, "_BROKEN", set())
    key = ("width_literal_test",)
    monkeypatch.setitem(_frame._FROZEN, key + (0,), dr.freeze(_shade_width_literal))
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        for n in (10, 20, 10, 30):
            a, b = _frame.call_frozen(key, _shade_width_literal, m, _frame_of(n))
            assert dr.width(a) == dr.width(b) == n
            assert np.array_equal(a.numpy(), np.linspace(0, 1, n, dtype=np.float32) + 1)
    msgs = [str(r.message) for r in rec if "frozen width_literal_test" in str(r.message)]
    assert len(msgs) == 1 and "a replay returned outputs of width" in msgs[0], msgs
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # traced from now on, silently
        a, b = _frame.call_frozen(key, _shade_width_literal, m, _frame_of(40))
    assert dr.width(b) == 40 and key in _frame._BROKEN


def test_recordings_are_bounded(monkeypatch):
    """A Python value that changes every call (a layout that never repeats) records at most
    MAX_RECORDINGS times; then the configuration is traced, with one warning."""
    monkeypatch.setattr(_frame, "USE_FROZEN", True)
    monkeypatch.setattr(_frame, "_BROKEN", set())
    key = ("bound_test",)

    def fn(m, P, scale):
        return P.varyingVecWorldPosition.x * scale

    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        for k in range(_frame.MAX_RECORDINGS + 4):
            out = _frame.call_frozen(key, fn, m, _frame_of(8), float(k + 1))
            assert np.allclose(out.numpy(), np.linspace(0, 1, 8) * (k + 1))
    msgs = [str(r.message) for r in rec if "frozen bound_test" in str(r.message)]
    assert len(msgs) == 1 and "recorded" in msgs[0]
    assert _frame._FROZEN.pop(key + (0,)).n_recordings == _frame.MAX_RECORDINGS + 1


@pytest.mark.parametrize("shader", [water_refraction, water_reflection])
def test_ports_replay_at_any_lane_count(shader, monkeypatch):
    """Renders and Jacobians of two cameras and three resolutions, interleaved: every frozen
    result equals the traced one bit for bit, and no configuration is recorded past the bound."""
    monkeypatch.setattr(_frame, "USE_FROZEN", True)
    monkeypatch.setattr(_frame, "_BROKEN", set())
    base = synthetic_inputs(40, 30)
    frames = [base, base.with_resolution(32, 24), base.with_resolution(48, 30), base]
    names = ["bumptex_mult", "water_color[1]"]
    c = Constants(bumptex_mult=0.8)
    with warnings.catch_warnings():
        warnings.simplefilter("error", _frame.FrozenReplayWarning)
        frozen = [
            (shader.render(f, c).numpy(), shader.render_with_jacobian(f, c, names)[1])
            for f in frames + frames
        ]
    monkeypatch.setattr(_frame, "USE_FROZEN", False)
    traced = [
        (shader.render(f, c).numpy(), shader.render_with_jacobian(f, c, names)[1])
        for f in frames + frames
    ]
    for (img, J), (img_t, J_t) in zip(frozen, traced):
        assert img["color"].shape == img_t["color"].shape
        for k in img_t:
            assert np.array_equal(img[k], img_t[k]), k
        assert np.array_equal(J, J_t)
    assert not _frame._BROKEN
    ups = {k for k in _frame._FROZEN if k[0].startswith(shader.__name__.split(".")[-1])}
    assert all(_frame._FROZEN[k].n_recordings <= 2 for k in ups)  # each frame records twice at most
