"""Scene data for sweep jobs: a scene is named by a JSON-able *scene spec*, rendered once per sweep
(reference and shader inputs, through the locked render cache) and then loaded by each job.

A scene spec is ``{"experiment": "<path to TOML>", "overrides": ["key=value", ...]}``. Jobs carry
their spec under ``job["scene"]``; the engine runs :func:`prepare_scene` once per distinct spec
before the jobs that need it, and a job calls :func:`load_scene` (a cache hit, memoised per
worker process).
"""

from __future__ import annotations

import functools
import json
import os

from .._progress import log as _log
from ..config.experiment import load_experiment
from ..scene.reference import load_or_render
from ..scene.shader_inputs import load_or_build_shader_inputs


def scene_spec(experiment, overrides=()) -> dict:
    """The canonical spec of an experiment file with ``--set`` overrides."""
    return {
        "experiment": os.path.abspath(str(experiment)),
        "overrides": [str(o) for o in overrides],
    }


def spec_text(spec: dict) -> str:
    return json.dumps(spec, sort_keys=True)


def prepare_scene(spec: dict, variant: str = "llvm_ad_rgb") -> dict:
    """Render (or find cached) the reference and shader inputs of ``spec``; return a summary
    (reference key, spp, noise). Runs in a worker; concurrent calls on one key render once."""
    exp, ref, _ = load_scene(spec, variant)
    return {
        "reference_key": ref.provenance.get("key"),
        "spp": ref.spp,
        "noise": ref.noise,
        "experiment": exp.name,
    }


@functools.lru_cache(maxsize=4)
def _load(text: str, variant: str):
    spec = json.loads(text)
    exp = load_experiment(spec["experiment"], spec.get("overrides") or [])
    ref = load_or_render(exp, variant, log=_log)
    inputs = load_or_build_shader_inputs(exp, variant, log=_log)
    return exp, ref, inputs


def load_scene(spec: dict, variant: str = "llvm_ad_rgb"):
    """``(experiment, Reference, ShaderInputs)`` of a scene spec (from the render cache)."""
    return _load(spec_text(spec), variant)
