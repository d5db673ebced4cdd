"""The user's own shader in ``study tradeoff`` (``fit.shader = "my_water.frag"``): charted, placed
and recommended like the study's shaders.

Beside the points the search measures, each experiment whose ``fit.shader`` is a GLSL file gets one
more point measured in full, as :func:`~.tradeoff_jobs.point_job` measures the study's shaders: the
declared constants fitted at ``fit.resolution`` by the experiment's solver (the study's one
calibration, ``study.fit.calibrate.calibrate_experiment``, of a ``SpirvModel``), FLIP and RMSE on
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
:func:`export_user` writes its file with the fitted constants into the study's ``shaders/`` folder
and checks it on OpenGL.
"""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

import numpy as np

from shaders_port.spirv import dialects

from .._io import write_text_atomic
from .._metrics import erode, errors, information_criteria
from ..config.user_shader import is_user_shader, load_user_shader
from ..export.gl_check import gl_check_user
from ..fit.build import build_model
from ..fit.calibrate import calibrate_experiment
from ..fit.model import get_value
from ..scene.reference import water_mask
from ..sweep import load_scene
from .tradeoff_analysis import USER, constants_of, is_user
from .tradeoff_jobs import timed_frames

__all__ = ["shader_sha256", "user_jobs", "user_point_job", "user_image", "export_user", "is_user"]


def _shader_of(exp):
    return load_user_shader(exp.values) if is_user_shader(exp.fit.shader) else None


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


def user_jobs(exps, specs) -> list[dict]:
    """One job per experiment whose ``fit.shader`` is a GLSL file (see the module doc)."""
    jobs = []
    for exp, spec in zip(exps, specs):
        shader = _shader_of(exp)
        if shader is None:
            continue
        sha = shader_sha256(shader)
        jobs.append(
            {
                "scene": spec,
                "experiment": exp.name,
                "variant": USER + shader.label,
                "kind": "fixed",
                "scale": None,
                "schedule": {},
                "shader_sha256": sha,
            }
        )
    return jobs


def _scored_mask(exp, out: dict) -> np.ndarray:
    """(H, W) bool at the size of the render ``out`` (``ShaderOutput.numpy()``): the shader's
    coverage and the reference's water, eroded by one pixel (the mask
    ``study.fit.model.ShaderModel`` scores the study's shaders on)."""
    cover = out["mask"] > 0.5
    return erode(cover & water_mask(exp, cover.shape[1], cover.shape[0]), 1)


def user_point_job(job: dict) -> dict:
    """The user's shader fitted and measured (module doc); flat figures, ``fitted`` (scalar name
    -> value) and ``status_of`` (scalar name -> fitted | bound | frozen)."""
    exp, ref, inputs = load_scene(job["scene"], job.get("mitsuba_variant", "llvm_ad_rgb"))
    model = build_model(exp, inputs, ref.image)
    t0 = time.perf_counter()
    cal = calibrate_experiment(model, exp)
    fit_s = time.perf_counter() - t0
    fitted = [n for n, p in cal.parameters.items() if p["status"] in ("fitted", "bound")]
    ic = information_criteria(model.residual(cal.fitted), len(fitted))
    full = build_model(exp, inputs, ref.image, resolution=tuple(exp.resolution))
    img, diag = full.render(cal.fitted)
    mask = full.mask
    err = errors(ref.image, img, mask)
    out = {
        "flip": err["flip"],
        "rmse": err["rmse"],
        "fit_seconds": fit_s,
        "fit_iterations": int(cal.fit_summary["iterations"]),
        "water_pixels": int(mask.sum()),
        "n_fitted": len(fitted),
        "aic": ic["aic"],
        "bic": ic["bic"],
        "nonfinite_pixels": int(diag.maps["nonfinite"][mask].sum()),
    }
    for k in ("fetches", "iterations"):
        v = diag.maps[k][mask]
        out[f"{k}_mean"], out[f"{k}_p99"] = float(v.mean()), float(np.percentile(v, 99))
    shader = model.user_shader
    out.update(
        timed_frames(
            lambda frame: shader.gl_renderer(frame, cal.fitted),
            None,
            lambda frame: shader.render(frame, cal.fitted),
            inputs,
            exp.tradeoff.gl_repeats,
        )
    )
    out["fitted"] = {n: get_value(cal.fitted, n) for n in cal.parameters}
    out["status_of"] = {n: p["status"] for n, p in cal.parameters.items()}
    return out


def _values(shader, row: dict) -> dict:
    return shader.with_scalars(shader.defaults(), constants_of(row))


def user_image(exp, inputs, constants: dict) -> tuple[np.ndarray, np.ndarray]:
    """The user's shader with fitted ``constants`` (scalar name -> value, a row's ``fitted``) at
    the inputs' size: (image (H, W, 3) float32 linear RGB, the scored mask (H, W) bool)."""
    shader = _shader_of(exp)
    values = shader.with_scalars(shader.defaults(), constants)
    out = shader.render(inputs, values).numpy()
    return out["color"], _scored_mask(exp, out)


def export_user(exps, specs, rows: list, out: Path, variant: str, log) -> dict:
    """Per experiment with a user's shader: its file with the fitted constants in ``shaders/``
    (one experiment) or ``shaders/<name>/``, every other byte as the user wrote it, and that
    file on OpenGL against the executor at ``resolution`` (``gl_check_user``). Returns
    {experiment: {"file", "variant", "label", "constants", "gl_check"}}."""
    result = {}
    for exp, spec in zip(exps, specs):
        shader = _shader_of(exp)
        row = next(
            (r for r in rows if r.get("job.experiment") == exp.name
             and is_user(r.get("job.variant")) and r["status"] == "ok"), None)  # fmt: skip
        if shader is None or row is None:
            continue
        values = _values(shader, row)
        folder = out / "shaders" if len(exps) == 1 else out / "shaders" / exp.name
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / shader.label
        write_text_atomic(path, shader.written(values))
        _, _, inputs = load_scene(spec, variant)
        gl = gl_check_user(shader, inputs, values, shader.render(inputs, values).numpy())
        result[exp.name] = {
            "file": str(path.relative_to(out)),
            "variant": USER + shader.label,
            "label": USER + shader.label,
            "constants": constants_of(row),
            "gl_check": gl,
        }
        verdict = "not run" if not gl["ran"] else ("passed" if gl["passed"] else "FAILED")
        log(f"tradeoff: {exp.name}: wrote your shader, fitted, to {path} (GL check {verdict})")
    return result
