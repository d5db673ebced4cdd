"""The user's own shader in ``study tradeoff`` (``fit.shader = "my_water.frag"``): charted, placed
and recommended like the study's shaders.

Beside the points the search measures, each experiment whose ``fit.shader`` is a GLSL file gets one
more point measured in full, as :func:`~.tradeoff_jobs.point_job` measures the study's shaders: the
declared constants fitted at ``fit.resolution`` by the experiment's solver (the study's one
calibration, ``study.calibration.fitting.fit_frames``, of a ``SpirvModel``), FLIP and RMSE on
the water pixels at ``resolution``, texture fetches and loop iterations per water pixel counted
from the translated code, the GL frame times of the written-back file beside the fixed reference
shader, and the executor's own frame time at 512x512. Its variant name is ``user:<file name>``; it
is one point (``kind`` ``fixed``: the loops it has are its own, their counts are measured, not
swept), on the front and a candidate for the recommendation like any other. Its job carries the
SHA-256 of what the shader's images depend on (:func:`shader_sha256`: its text, its text after
``#include`` s and ``fit.defines``, the defines, its declaration, its vertex shader's text and
grid), so an edited shader, include file, define or vertex shader is measured again, never read
back from the table.

:func:`~.tradeoff_analysis.placement` says where it stands among the points of its scene;
``study.studies.tradeoff_export`` calibrates and exports it as ``study calibrate`` does.
"""

from __future__ import annotations

import hashlib
import json

from shaders_port.spirv import dialects

from .._metrics import information_criteria
from ..calibration.scoring import Scorer
from ..calibration.shader import Shader
from ..fit.model import get_value
from .tradeoff_jobs import job_fit, timed_frames

__all__ = ["own_shaders", "shader_sha256", "user_jobs", "user_point_job"]


def shader_sha256(shader) -> str:
    """Hex SHA-256 of what a ``UserShader``'s images depend on: its file's text, the text
    after preprocessing (every ``#include`` d file's contents and the defines applied), its
    defines, bindings, declared constants, engine values and options (the normal-map image's
    bytes), and with ``fit.vertex`` the vertex shader's text, grid and engine values."""
    decl = json.dumps({"bindings": shader.bindings, "constants": {
        n: [c.lo, c.hi] for n, c in shader.constants.items()}, "values": shader.values,
        "engine": shader.engine_record()}, sort_keys=True)  # fmt: skip
    expanded = dialects.front_end(
        shader.source, shader.label, shader.defines, shader.include_paths, True
    )
    vertex = ""
    if shader.vertex is not None:
        v = shader.vertex
        vertex = json.dumps([v.shader.original, list(v.cells), v.shader.values], sort_keys=True)
    parts = [shader.source, expanded, json.dumps(list(shader.defines)), decl, vertex]
    return hashlib.sha256("\0".join(parts).encode()).hexdigest()


def own_shaders(exp) -> list:
    """[the user's own shader (``Shader``)] of an experiment whose ``fit.shader`` is a GLSL
    file; [] for a shader of the space (the search charts those)."""
    shader = Shader.of(exp)
    return [shader] if shader.is_user else []


def user_jobs(exps, specs) -> list[dict]:
    """One job per experiment whose ``fit.shader`` is a GLSL file (see the module doc)."""
    jobs = []
    for exp, spec in zip(exps, specs):
        for shader in own_shaders(exp):
            jobs.append(_user_job(exp, spec, shader))
    return jobs


def _user_job(exp, spec: dict, shader) -> dict:
    sha = shader_sha256(shader.user)
    return {
        "scene": spec,
        "experiment": exp.name,
        "variant": shader.table_name,
        "kind": "fixed",
        "scale": None,
        "schedule": {},
        "shader_sha256": sha,
    }


def user_point_job(job: dict) -> dict:
    """The user's shader fitted and measured (module doc) as ``point_job`` measures the study's
    shaders; flat figures, ``fitted`` (scalar name -> value) and ``status_of`` (scalar name ->
    fitted | bound | frozen)."""
    mv = job.get("mitsuba_variant", "llvm_ad_rgb")
    shader, frame, fit, fit_s = job_fit(job)
    cal = fit.calibration
    fitted = [n for n, p in cal.parameters.items() if p["status"] in ("fitted", "bound")]
    ic = information_criteria(fit.models[0].residual(cal.fitted), len(fitted))
    score = Scorer(shader, [frame], mv)(0, cal.fitted)
    out = {
        "flip": score.flip,
        "rmse": score.rmse,
        "fit_seconds": fit_s,
        "fit_iterations": int(cal.fit_summary["iterations"]),
        "water_pixels": int(score.mask.sum()),
        "n_fitted": len(fitted),
        "aic": ic["aic"],
        "bic": ic["bic"],
        **score.per_pixel(("fetches", "iterations")),
    }
    out.pop("not_crossed", None)
    user = shader.user
    out.update(
        timed_frames(
            lambda f: user.gl_renderer(f, cal.fitted),
            None,
            lambda f: user.render(f, cal.fitted),
            frame.inputs,
            frame.exp.tradeoff.gl_repeats,
        )
    )
    out["fitted"] = {n: get_value(cal.fitted, n) for n in cal.parameters}
    out["status_of"] = {n: p["status"] for n, p in cal.parameters.items()}
    return out
