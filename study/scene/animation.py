"""Animated experiments: the frames of an ``[animation]`` table and what the frames share.

The motion: the four normal-map layers translate with their own velocities, as the seed's
application moves them each frame. At frame ``k`` (time ``t = k * animation.time_step``
seconds) layer ``i`` is at

    wave_i(k) = waves.offsets[i] + k * animation.time_step * animation.velocities[i]

(texture units, float64). Both sides take frame ``k`` from one and the same still experiment,
:func:`frame_experiment`: its ``waves.offsets`` are ``wave_1..4(k)``, which the shader receives
as its ``wave1..wave4`` uniforms and the reference displaces its water mesh with
(``geometry.Waves``: ``H(x, z) = amplitude / 4 * sum_i h0((x, z) / normal_tile + wave_i)``),
so frame ``k`` of the reference and frame ``k`` of the shader show the same waves
(``tests/test_animation.py`` compares the port's normal map at frame ``k`` with the reference
surface's slopes at frame ``k``).

A frame experiment is a still experiment (``animation.*`` at their defaults, which no hash
reads): its reference and shader inputs are cached under the keys a still experiment with those
offsets has, so each frame is cached on its own and frame 0 is the still experiment itself.
What does not depend on the offsets (the Mitsuba scenes, whose water surface is moved from frame
to frame by :func:`~.mitsuba_scene.set_waves`, the world-y ray casts of the texture and of the
lighting grid, the dry render and floor albedo, the traced skylight's sample patterns, the normal
map, the sky cube map and the Fresnel LUT) is built once per animation and held by a
:class:`FrameShared`.
"""

from __future__ import annotations

import copy
import hashlib
import json
from typing import Callable

import numpy as np

from ..config.errors import ExperimentError
from ..config.experiment import Experiment
from ..config.schema import SCHEMA

ANIMATION_KEYS = ("animation.frames", "animation.time_step", "animation.velocities")


def is_animated(exp: Experiment) -> bool:
    """True when ``exp`` has more than one frame."""
    return int(exp.animation.frames) > 1


def refuse_animated(exp: Experiment, command: str) -> None:
    """Raise ExperimentError when ``exp`` is animated: ``command`` works on still frames only."""
    if is_animated(exp):
        raise ExperimentError(
            f"{command} works on one still frame, and {exp.name!r} has animation.frames = "
            f"{exp.animation.frames}: run `study calibrate` on it alone (it fits every "
            "frame), or pass --set animation.frames=1 to use its frame 0"
        )


def frame_offsets(exp: Experiment, k: int) -> np.ndarray:
    """(4, 2) float64 offsets wave1..wave4 of frame ``k`` (texture units; see module docstring)."""
    n = int(exp.animation.frames)
    if not 0 <= k < n:
        raise ValueError(f"frame {k} of an animation of {n} frames (animation.frames)")
    base = np.asarray(exp.waves.offsets, np.float64)
    vel = np.asarray(exp.animation.velocities, np.float64)
    return base + (k * float(exp.animation.time_step)) * vel


def frame_time(exp: Experiment, k: int) -> float:
    """The clock of frame ``k``, seconds: ``waves.time + k * animation.time_step`` (the ``time``
    a user's shader reads; ``waves.time`` is 0 unless set)."""
    return float(exp.waves.time) + k * float(exp.animation.time_step)


def frame_experiment(exp: Experiment, k: int) -> Experiment:
    """Frame ``k`` of ``exp`` as a still experiment: ``waves.offsets`` = :func:`frame_offsets`,
    with ``waves.source = "shader"`` ``waves.time`` = :func:`frame_time`, the ``animation.*``
    keys at their defaults (frame 0 of any animation is ``exp`` as a still)."""
    values = copy.deepcopy(exp.values)
    values["waves.offsets"] = frame_offsets(exp, k).tolist()
    if exp.waves.source == "shader":  # the shader's waves at the frame's clock
        values["waves.time"] = frame_time(exp, k)
    for key in ANIMATION_KEYS:
        values[key] = copy.deepcopy(SCHEMA[key].default)
    return Experiment(values, exp.path, dict(exp.digests), dict(exp.auto))


def frames_of(exp: Experiment) -> list[Experiment]:
    """The ``animation.frames`` frame experiments of ``exp`` (one for a still experiment)."""
    return [frame_experiment(exp, k) for k in range(int(exp.animation.frames))]


def offsets_free_key(exp: Experiment) -> str:
    """A hash of everything that affects ``exp``'s reference scene and shader inputs except the
    wave offsets: equal for all frames of one animation, different for any other scene."""
    still = copy.deepcopy(exp.values)
    still["waves.offsets"] = None
    still["waves.time"] = SCHEMA["waves.time"].default  # the shader's waves move with it
    other = Experiment(still, exp.path, dict(exp.digests), dict(exp.auto))
    data = [other.scene_hash(), other.inputs_hash()]
    return hashlib.sha256(json.dumps(data).encode()).hexdigest()[:32]


class FrameShared:
    """What the frames of one animation share, each part built on first use and then reused.

    ``get(exp, name, build)`` returns the part ``name`` (``build()`` the first time). The parts
    are keyed on :func:`offsets_free_key`: a frame of another experiment (a scene that differs in
    anything but the offsets) finds none of them and starts afresh. ``built`` lists the names
    built, in order, and ``reused`` counts the reuses (the report's and the tests' record)."""

    def __init__(self):
        self._key: str | None = None
        self._parts: dict = {}
        self.built: list[str] = []
        self.reused: dict[str, int] = {}

    def get(self, exp: Experiment, name: str, build: Callable):
        key = offsets_free_key(exp)
        if key != self._key:
            self._key, self._parts = key, {}
        if name in self._parts:
            self.reused[name] = self.reused.get(name, 0) + 1
            return self._parts[name]
        part = build()
        self._parts[name] = part
        self.built.append(name)
        return part

    def scene(self, exp: Experiment, name: str, build: Callable, move: Callable):
        """The Mitsuba scene ``name`` (``build()`` the first time) with its water surface at the
        waves of ``exp``: a scene built for another frame is moved by ``move(scene, exp)``
        (:func:`~.mitsuba_scene.set_waves`) when its offsets or ``waves.time`` differ from
        ``exp``'s."""
        state = [exp.waves.offsets, exp.waves.time]
        part = self.get(exp, name, lambda: [build(), copy.deepcopy(state)])
        if part[1] != state:
            move(part[0], exp)
            part[1] = copy.deepcopy(state)
        return part[0]


def shared_part(shared: FrameShared | None, exp: Experiment, name: str, build: Callable):
    """``shared.get(exp, name, build)``, or ``build()`` without a :class:`FrameShared`."""
    return build() if shared is None else shared.get(exp, name, build)
