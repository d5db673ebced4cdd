"""The views of an experiment: ``camera.position`` / ``camera.target`` and each entry of
``camera.views``, the same scene seen by several cameras.

Each view is a still experiment of its own (:func:`view_experiments`: its camera, ``camera.views``
emptied), so its reference is cached under the key an experiment with that one camera has. What
the camera does not change is built once: the shader inputs of the first view give every other
view's (:func:`view_inputs`: the top-down textures, the normal map, the sky cube map, the Fresnel
LUT and the light stay; the camera's matrix and position are the view's). The buffers a shader
reads in screen space (the scene without the water, its depth, the mirrored camera's image) are
each view's own (``baseline_inputs.inputs_for_shader``).
"""

from __future__ import annotations

import copy
import dataclasses
import json

import numpy as np

from shaders_port import ShaderInputs

from ..config.errors import ExperimentError
from ..config.experiment import Experiment
from .animation import is_animated
from .mitsuba_scene import camera_view_proj

# the ShaderInputs fields a camera sets; every other field is the scene's
CAMERA_FIELDS = ("view_proj", "viewpos", "scene_color", "scene_depth", "reflection_color",
                 "reflection_view_proj")  # fmt: skip


def has_views(exp: Experiment) -> bool:
    """True when ``exp`` names more views than its camera's (``camera.views``)."""
    return bool(exp.camera.views)


def _views(exp: Experiment) -> list:
    """``[position, target]`` of every view of ``exp``, the camera's first."""
    return [[exp.camera.position, exp.camera.target], *exp.camera.views]


def view_overrides(exp: Experiment, k: int) -> list[str]:
    """The ``--set`` overrides that make ``exp`` its view ``k`` (:func:`view_experiments`): its
    camera, ``camera.views`` = [] and the name ``<name>-view<k>``."""
    position, target = _views(exp)[k]
    return [
        f"camera.position={json.dumps(list(position))}",
        f"camera.target={json.dumps(list(target))}",
        "camera.views=[]",
        f"name={json.dumps(f'{exp.name}-view{k}')}",
    ]


def view_experiments(exp: Experiment) -> list[Experiment]:
    """``[exp]`` for one view; else one still experiment per view, the first ``exp``'s own
    camera, each with ``camera.views`` = [] and named ``<name>-view<k>``."""
    if not has_views(exp):
        return [exp]
    if is_animated(exp):
        raise ExperimentError(
            f"{exp.name!r} has camera.views and animation.frames = {exp.animation.frames}: "
            "calibrate its views as a still (--set animation.frames=1) or its frames from one "
            "view (--set camera.views=[])"
        )
    out = []
    for k, (position, target) in enumerate(_views(exp)):
        values = copy.deepcopy(exp.values)
        values["camera.position"], values["camera.target"] = list(position), list(target)
        values["camera.views"] = []
        values["name"] = f"{exp.name}-view{k}"
        out.append(Experiment(values, exp.path, dict(exp.digests), dict(exp.auto)))
    return out


def view_inputs(view: Experiment, base: ShaderInputs) -> ShaderInputs:
    """``base`` (the shader inputs of another view of the same scene, without a shader's
    screen-space buffers) seen from ``view``'s camera: its ``view_proj`` (at ``view``'s
    resolution) and ``viewpos``; the camera's screen-space buffers left unset."""
    w, h = view.resolution
    unset = {f: None for f in CAMERA_FIELDS if f not in ("view_proj", "viewpos")}
    return dataclasses.replace(
        base,
        view_proj=camera_view_proj(view, w, h),
        viewpos=np.asarray(view.camera.position),
        width=w,
        height=h,
        **unset,
    )
