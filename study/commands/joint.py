"""Calibrations over several experiments at once: ``study calibrate A.toml B.toml ...`` (one
constants block fitted on all scenes) and ``study generalise`` (that joint fit plus
leave-one-scene-out validation), for a shader of the study's or a user's alike."""

from __future__ import annotations

import time
from pathlib import Path

from .._backend import drjit_backend, init_backend
from .._io import write_json
from .._metrics import errors
from .._progress import log as _log
from ..config.experiment import load_experiment
from ..fit.build import build_model
from ..fit.calibrate import scene_frozen
from ..fit.joint import JointModel, joint_calibrate, leave_one_out, universality
from ..fit.model import constants_json
from ..fit.result import CalibrationResult, glsl_renamed, jsonable
from ..report.generalise import write_generalise_report, write_joint_report
from ..scene.baseline_inputs import inputs_for_shader
from ..scene.animation import refuse_animated
from ..scene.reference import load_or_render
from ..scene.shader_inputs import load_or_build_shader_inputs
from ..scene.views import has_views, view_experiments, view_inputs
from .steps import export_calibration, load_scene_data, with_stages
from .viewer import write_viewer


def load_scenes(experiments, overrides, variant, cache):
    """Load every experiment (same overrides for all), its reference, inputs and fit model.
    Returns (variant, list of dicts: name, exp, ref, inputs, model, frozen)."""
    if not experiments:
        raise ValueError("no experiment given")
    exps = [load_experiment(e, overrides) for e in experiments]
    variant = init_backend(variant or exps[0].variant)
    exps = [exp.on_backend(variant) for exp in exps]  # a fit.resolution "auto" for the device
    for exp in exps:
        if not has_views(exp):
            refuse_animated(exp, "a fit over several experiments")
    views = [view_experiments(exp) for exp in exps]  # refuses views of an animation
    scenes, seen = [], {}
    for path, exp, its_views in zip(experiments, exps, views):
        name = exp.name
        seen[name] = seen.get(name, 0) + 1
        if seen[name] > 1:
            name = f"{name}#{seen[name]}"
        base = None  # the first view's inputs: the scene's for every view
        for k, view in enumerate(its_views):
            if len(its_views) == 1:
                ref, inputs, _ = load_scene_data(view, variant, cache)
            else:
                _log(f"{name}: view {k + 1}/{len(its_views)}, camera at {view.camera.position}")
                ref = load_or_render(view, variant, cache=cache, log=_log)
                if base is None:
                    base = load_or_build_shader_inputs(view, variant, cache=cache, log=_log)
                inputs = inputs_for_shader(view, view_inputs(view, base), view.fit.shader,
                                           variant, cache=cache, log=_log)  # fmt: skip
            model = build_model(view, inputs, ref.image, backend=drjit_backend(variant))
            scenes.append(
                {
                    "name": view.name if len(its_views) > 1 else name,
                    "path": str(path),
                    "exp": view,
                    "ref": ref,
                    "inputs": inputs,
                    "model": model,
                    "frozen": scene_frozen(view),
                }
            )
    return variant, scenes


def evaluator(scenes, variant):
    """evaluate(i, constants) -> RMSE and FLIP of scene i at its full resolution (water pixels)."""
    full = {}

    def evaluate(i, constants):
        s = scenes[i]
        if i not in full:
            full[i] = build_model(
                s["exp"],
                s["inputs"],
                s["ref"].image,
                backend=drjit_backend(variant),
                resolution=tuple(s["exp"].resolution),
            )
        img, _ = full[i].render(constants)
        e = errors(s["ref"].image, img, full[i].mask)
        return {"rmse": float(e["rmse"]), "flip": float(e["flip"])}

    return evaluate


def run_calibrate_joint(
    experiments, out, overrides=None, variant=None, solver=None, cache=None
) -> dict:
    """``study calibrate A.toml B.toml ...``: one constants block fitted on all scenes (each
    weighted equally), exported and GL-checked like a single fit; constants.json and report.md
    with every scene's error under the start and the joint constants. The first experiment
    gives the start constants, ``fit.parameters``, ``fit.solver`` and ``fit.max_steps``."""
    variant, scenes = load_scenes(experiments, overrides, variant, cache)
    return joint_fit(scenes, variant, Path(out), solver)[0]


def joint_fit(scenes, variant, out: Path, solver):
    """The joint fit of ``scenes``, exported into ``out``. Returns (summary, calibration,
    evaluate)."""
    out.mkdir(parents=True, exist_ok=True)
    first, model = scenes[0]["exp"], scenes[0]["model"]
    solver = solver or first.fit.solver
    start = model.start_constants(first)
    t0 = time.perf_counter()
    cal = joint_calibrate(
        [s["model"] for s in scenes],
        start,
        first.fit.parameters,
        solver,
        first.fit.max_steps,
        [s["frozen"] for s in scenes],
        [s["name"] for s in scenes],
    )
    fit_s = time.perf_counter() - t0
    evaluate = evaluator(scenes, variant)
    per_scene = {
        s["name"]: {"default": evaluate(i, start), "fitted": evaluate(i, cal.fitted)}
        for i, s in enumerate(scenes)
    }
    timings = {"fit_s": fit_s}
    (gl,), engine_targets, extra = export_calibration(
        first, model, [scenes[0]["inputs"]], cal, out, timings
    )
    weights = JointModel([s["model"] for s in scenes]).weights
    result = CalibrationResult(
        shader=model.label,
        backend=variant,
        parameters=with_stages(cal.parameters, getattr(model, "user_shader", None)),
        constants=constants_json(cal.fitted),
        error=per_scene,
        solver=solver,
        fit=cal.fit_summary,
        identifiability=cal.identifiability,
        timings=timings,
        gl_check=gl,
        experiments=[s["path"] for s in scenes],
        scenes=[s["name"] for s in scenes],
        weights={s["name"]: float(w) for s, w in zip(scenes, weights)},
        engine_targets=engine_targets,
        textures=extra.pop("textures"),
        extra=extra,
    )
    summary = result.to_json()
    write_json(out / "constants.json", summary)
    write_joint_report(out, summary)
    write_viewer(out, first, scenes[0]["inputs"])
    _log(f"calibrate (joint, {len(scenes)} scenes): wrote {out}")
    return summary, cal, evaluate


def run_generalise(experiments, out, overrides=None, variant=None, solver=None, cache=None) -> dict:
    """``study generalise A.toml B.toml ...``: the joint fit (exported as by ``calibrate``) plus
    leave-one-scene-out validation (each scene scored under the seed's constants, the constants
    fitted on the other scenes and its own fit) and the universal/scene-specific verdict per
    constant; generalise.json and generalise.md."""
    variant, scenes = load_scenes(experiments, overrides, variant, cache)
    if len(scenes) < 2:
        raise ValueError(
            "study generalise needs at least two experiments or views (camera.views) to leave "
            "one out"
        )
    out = Path(out)
    joint, cal, evaluate = joint_fit(scenes, variant, out, solver)
    first = scenes[0]["exp"]
    rows = leave_one_out(
        [s["model"] for s in scenes],
        scenes[0]["model"].start_constants(first),
        first.fit.parameters,
        joint["solver"],
        first.fit.max_steps,
        evaluate,
        [s["frozen"] for s in scenes],
        [s["name"] for s in scenes],
        log=_log,
    )
    uni = universality({r["scene"]: r["own_calibration"] for r in rows}, cal)
    # the first scene's own constants on every scene: what a block fitted on one view (or
    # scene) loses on the others
    index = {s["name"]: i for i, s in enumerate(scenes)}
    first = next(r for r in rows if r["scene"] == scenes[0]["name"])["own_calibration"].fitted
    table = [
        {
            "scene": r["scene"],
            "seed": r["seed"],
            "others": r["others"],
            "own": r["own"],
            "first": evaluate(index[r["scene"]], first),
            "own_constants": {n: p["fitted"] for n, p in r["own_calibration"].parameters.items()},
            "own_status": {n: p["status"] for n, p in r["own_calibration"].parameters.items()},
        }
        for r in rows
    ]
    summary = {
        "experiments": joint["experiments"],
        "scenes": joint["scenes"],
        "joint": joint,
        "leave_one_out": table,
        "universality": uni,
    }
    summary = jsonable(summary)
    if "shader_file" not in joint:  # the study's shader: its constants by their GLSL names
        summary = glsl_renamed(summary)
    write_json(out / "generalise.json", summary)
    write_generalise_report(out, summary)
    _log(f"generalise: wrote {out / 'generalise.md'}")
    return summary
