"""The frames a calibration runs over, from one loader.

A *frame* is one image the shader must match: an experiment's reference and the shader inputs
the fitted shader reads, at the experiment's resolution. Every calibration is a fit over a list
of frames:

* a still experiment is a list of one;
* an experiment with ``camera.views`` is one frame per view (``study.scene.views``);
* an animated experiment (``animation.frames`` > 1) is one frame per time step, each with its
  own reference and wave offsets (``study.scene.animation_data``);
* several experiments are one frame (or one per view) each.

:func:`load_frames` loads any of these; :class:`Frames` says which it is (``kind``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

from .._backend import init_backend
from .._progress import Stages
from .._progress import log as _log
from ..config.errors import ExperimentError
from ..config.experiment import Experiment, load_experiment
from ..fit.calibrate import scene_frozen
from ..scene.baseline_inputs import inputs_for_shader
from ..scene.animation_data import load_frames as load_animation
from ..scene.animation import is_animated, refuse_animated
from ..scene.reference import Reference, load_or_render
from ..scene.shader_inputs import load_or_build_shader_inputs
from ..scene.user_scene import check_scene
from ..scene.water_in_view import check_water_in_view
from ..scene.views import has_views, view_experiments, view_inputs


@dataclass
class Frame:
    """One image a calibration fits: ``exp`` (this frame's experiment: a view's or an animation
    frame's own), its ``ref`` (``Reference``, (H, W, 3) float32 linear RGB at
    ``exp.resolution``), ``inputs`` (``ShaderInputs`` at that resolution with what the shader
    reads), ``name`` (unique in its list), ``path`` (the experiment file as given) and
    ``frozen`` (constant -> why the scene's physics cannot identify it,
    ``study.fit.calibrate.scene_frozen``)."""

    name: str
    path: str
    exp: Experiment
    ref: Reference
    inputs: object
    frozen: dict = field(default_factory=dict)

    @classmethod
    def of(cls, exp: Experiment, ref: Reference, inputs, path=None, name=None) -> "Frame":
        """The frame of an experiment whose reference and inputs are loaded already (a sweep's
        scene)."""
        path = str(path if path is not None else exp.path)
        return cls(name or exp.name, path, exp, ref, inputs, scene_frozen(exp))


@dataclass
class Frames:
    """The frames of one calibration: ``kind`` 'still' (one frame), 'views' (one experiment's
    views), 'animated' (one experiment's time steps) or 'joint' (several experiments);
    ``variant`` (the Mitsuba variant, backend initialised), ``frames``, ``timings`` (stage ->
    seconds) and, for an animation, ``animation`` (what its frames share:
    ``study.scene.animation_data.load_frames``'s ``shared`` and ``base``)."""

    kind: str
    variant: str
    frames: list[Frame]
    timings: dict
    experiment: Experiment
    animation: dict | None = None

    def __len__(self) -> int:
        return len(self.frames)

    def __iter__(self):
        return iter(self.frames)

    def __getitem__(self, i) -> Frame:
        return self.frames[i]

    @property
    def first(self) -> Frame:
        return self.frames[0]


def load_experiments(experiments, overrides=None, variant=None) -> tuple[list, str]:
    """Each experiment file of ``experiments`` (one path or a list) loaded with ``overrides``
    and checked (its water in view, its scene's files), the backend of ``variant`` (default: the
    first experiment's) initialised. Returns (experiments on that backend, variant)."""
    paths = list(experiments) if isinstance(experiments, (list, tuple)) else [experiments]
    if not paths:
        raise ValueError("no experiment given")
    exps = [load_experiment(p, overrides) for p in paths]
    variant = init_backend(variant or exps[0].variant)
    exps = [exp.on_backend(variant) for exp in exps]  # a fit.resolution "auto" for the device
    for exp in exps:
        if "fit.resolution" in exp.auto:
            (w, h), (fw, fh) = exp.resolution, exp.fit.resolution
            _log(f'experiment: fit.resolution = "auto": {fw}x{fh} ({w}x{h} on {variant})')
        check_water_in_view(exp)
        check_scene(exp)
    return exps, variant


def load_frames(experiments, overrides=None, variant=None, cache=None) -> Frames:
    """Every frame of ``experiments`` (one path or a list; module docstring), each reference
    and its shader inputs cached (``study.scene.reference``, ``study.scene.shader_inputs``)."""
    t0 = time.perf_counter()
    paths = list(experiments) if isinstance(experiments, (list, tuple)) else [experiments]
    exps, variant = load_experiments(paths, overrides, variant)
    setup_s = time.perf_counter() - t0
    if len(exps) == 1 and is_animated(exps[0]) and not has_views(exps[0]):
        _refuse_decorrelated_frames(exps[0])  # before any frame is rendered
        frames = _animation(paths[0], exps[0], variant, cache)
        frames.timings = {"setup_s": setup_s, **frames.timings}
        return frames
    if len(exps) > 1:
        for exp in exps:
            if not has_views(exp):
                refuse_animated(exp, "a fit over several experiments")
    out, timings, seen = [], {"setup_s": setup_s}, {}
    for path, exp in zip(paths, exps):
        seen[exp.name] = seen.get(exp.name, 0) + 1
        name = exp.name if seen[exp.name] == 1 else f"{exp.name}#{seen[exp.name]}"
        out += _still_frames(path, exp, name, variant, cache, timings)
    kind = "joint" if len(exps) > 1 else ("views" if len(out) > 1 else "still")
    return Frames(kind, variant, out, timings, exps[0])


def _refuse_decorrelated_frames(exp) -> None:
    """ExperimentError when an animated ``exp`` asks for the texture-noise decorrelation, which
    the fit over frames does not do."""
    if exp.fit.input_noise != "ignore":
        raise ExperimentError(
            f'fit.input_noise = "{exp.fit.input_noise}" is not built for an animated '
            "experiment (its frames are fitted jointly by least squares); use fit.input_noise = "
            '"ignore", or --set animation.frames=1 to fit its frame 0 that way'
        )


def _still_frames(path, exp, name: str, variant: str, cache, timings: dict) -> list[Frame]:
    """The frames of one still experiment: itself, or one per view (``camera.views``), whose
    shader inputs are the first view's seen from each view's camera."""
    views = view_experiments(exp)  # refuses views of an animation
    if len(views) == 1:
        ref, inputs, t = load_scene_data(exp, variant, cache)
        for k, v in t.items():
            timings[k] = timings.get(k, 0.0) + v
        return [Frame(name, str(path), exp, ref, inputs, scene_frozen(exp))]
    frames, base = [], None
    for k, view in enumerate(views):
        _log(f"{name}: view {k + 1}/{len(views)}, camera at {view.camera.position}")
        ref = load_or_render(view, variant, cache=cache, log=_log)
        if base is None:
            base = load_or_build_shader_inputs(view, variant, cache=cache, log=_log)
        inputs = inputs_for_shader(view, view_inputs(view, base), view.fit.shader, variant,
                                   cache=cache, log=_log)  # fmt: skip
        frames.append(Frame(view.name, str(path), view, ref, inputs, scene_frozen(view)))
    return frames


def _animation(path, exp, variant: str, cache) -> Frames:
    data = load_animation(exp, variant, cache)
    frames = [
        Frame(f"frame{k}", str(path), e, r, i, scene_frozen(e))
        for k, (e, r, i) in enumerate(zip(data["frames"], data["refs"], data["inputs"]))
    ]
    shared = {"shared": data["shared"], "base": data["base"]}
    return Frames("animated", variant, frames, data["timings"], exp, shared)


def load_scene_data(exp, variant: str, cache=None):
    """Reference (cached) and shader inputs (with what ``fit.shader`` reads) of one still
    experiment at its resolution: (``Reference``, ``ShaderInputs``, stage -> seconds)."""
    st = Stages(log=_log)
    spp = exp.reference.spp
    with st.stage(
        "reference_s",
        f"reference: {exp.resolution[0]}x{exp.resolution[1]}, "
        + ("automatic spp (pilot, then final passes)" if spp == "auto" else f"{spp} spp"),
    ):
        ref = load_or_render(
            exp, variant, cache=cache, progress=st.counter("  reference passes"), log=_log
        )
    with st.stage("inputs_s", "shader inputs"):
        inputs = load_or_build_shader_inputs(exp, variant, cache=cache, log=_log, progress=st)
        inputs = inputs_for_shader(exp, inputs, exp.fit.shader, variant, cache=cache, log=_log)
    return ref, inputs, st.timings


def output_folder(out) -> Path:
    """``out`` as a created folder."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    return out


def prepare(experiment, out, overrides=None, variant=None):
    """One experiment loaded and checked for a command that takes one still frame (``render``,
    ``preview``, ``viewer``: an animated experiment's frame 0), its backend initialised and
    ``out`` created. Returns (experiment, variant, out)."""
    (exp,), variant = load_experiments([experiment], overrides, variant)
    if is_animated(exp):
        _log(
            f"experiment: {exp.name} has {exp.animation.frames} frames; this command uses "
            "frame 0 (study calibrate fits every frame)"
        )
    return exp, variant, output_folder(out)
