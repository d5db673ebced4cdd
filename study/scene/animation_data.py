"""The data of every frame of an animated experiment (``study.scene.animation``): references and
shader inputs per frame, cached per frame, what the frames share built once."""

from __future__ import annotations

import dataclasses

from .._progress import Stages
from .._progress import log as _log
from .baseline_inputs import inputs_for_shader
from .animation import FrameShared, frame_time, frames_of
from .mitsuba_scene import build_scene, set_waves
from .reference import load_or_render
from .shader_inputs import load_or_build_shader_inputs


def load_frames(exp, variant: str, cache=None) -> dict:
    """Every frame of ``exp``: ``frames`` (the frame experiments), ``refs`` (``Reference``),
    ``inputs`` (``ShaderInputs`` with what ``fit.shader`` reads, ``time`` the frame's clock,
    ``animation.frame_time``), ``base`` (the study's shader
    inputs without a shader's extra buffers: ``baseline_inputs.inputs_for_shader`` adds them
    for another shader), ``timings`` (per frame and summed: ``reference_s``,
    ``inputs_s``) and ``shared`` (the ``FrameShared`` record: what was built once, how often it
    was reused)."""
    shared = FrameShared()
    frames = frames_of(exp)
    n = len(frames)
    refs, inputs, base, timings = [], [], [], {}
    for k, e in enumerate(frames):
        st = Stages(log=_log, prefix=f"frame{k}.")

        def scene(e=e):
            return shared.scene(e, "reference_scene", lambda: build_scene(e), set_waves)

        with st.stage("reference_s", f"frame {k + 1}/{n}: reference"):
            refs.append(
                load_or_render(
                    e,
                    variant,
                    cache=cache,
                    progress=st.counter("  reference passes"),
                    log=_log,
                    scene=scene,
                    keep_passes=True,
                )
            )
        with st.stage("inputs_s", f"frame {k + 1}/{n}: shader inputs"):
            i = load_or_build_shader_inputs(
                e, variant, cache=cache, log=_log, progress=st, shared=shared
            )
            # the frame's clock, the `time` a user's shader reads (spirv.engine_inputs)
            i = dataclasses.replace(i, time=frame_time(exp, k))
            base.append(i)
            i = inputs_for_shader(e, i, e.fit.shader, variant, cache=cache, log=_log)
            inputs.append(i)
        timings.update(st.timings)
    for what in ("reference_s", "inputs_s"):
        timings[what] = sum(timings[f"frame{k}.{what}"] for k in range(n))
    record = {"built_once": list(shared.built), "reused": dict(shared.reused)}
    return {"frames": frames, "refs": refs, "inputs": inputs, "base": base, "timings": timings,
            "shared": record}  # fmt: skip
