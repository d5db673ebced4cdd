"""The study's jobs, one function per CLI command; each writes its artifacts into one folder."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ._backend import init_backend
from .scene.experiment import is_user_shader, load_experiment
from ._io import write_exr, write_json, write_png
from .export.gl_check import gl_check, target_checks
from ._progress import log as _log


def prepare(experiment, out, overrides=None, variant=None, frames: bool = False):
    """Load the experiment (its files validated), initialise the backend, check what needs it
    (the mesh), create the output folder. ``frames``: the command handles every frame of an
    animated experiment (else it says that it uses frame 0)."""
    from .scene.user_scene import check_scene
    from .scene.view import check_water_in_view

    exp = load_experiment(experiment, overrides)
    check_water_in_view(exp)
    from .scene.frames import is_animated

    if is_animated(exp) and not frames:
        _log(
            f"experiment: {exp['name']} has {exp['animation.frames']} frames; this command uses "
            "frame 0 (study calibrate fits every frame)"
        )
    variant = init_backend(variant or exp["variant"])
    check_scene(exp)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    return exp, variant, out


def run_render(experiment, out, overrides=None, variant=None, cache=None) -> dict:
    """``study render``: reference.exr (+ PNG), shader inputs (.npz and EXRs), summary.json."""
    t0 = time.perf_counter()
    exp, variant, out = prepare(experiment, out, overrides, variant)
    setup_s = time.perf_counter() - t0
    ref, inputs, timings = load_scene_data(exp, variant, cache)
    timings = {"setup_s": setup_s, **timings}
    write_exr(out / "reference.exr", ref.image, ref.provenance)
    write_png(out / "reference.png", ref.image)
    save_shader_inputs(inputs, out / "inputs")
    summary = {
        "experiment": exp["name"],
        "variant": variant,
        "reference": ref.provenance,
        "timings": timings,
        "outputs": sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()),
    }
    write_json(out / "summary.json", summary)
    _log(f"render: wrote {out}")
    return summary


def save_shader_inputs(inputs, folder: Path) -> None:
    """All shader inputs as one .npz plus EXRs of the image-like ones (GL row order)."""
    folder.mkdir(parents=True, exist_ok=True)
    inputs.save(folder / "shader_inputs.npz")
    write_exr(folder / "refraction_texture.exr", inputs.refraction_texture)
    write_exr(folder / "world_y.exr", np.repeat(inputs.world_y[..., None], 3, -1))
    write_exr(folder / "normal_map.exr", inputs.normal_map)
    write_exr(folder / "refl_world_y.exr", np.repeat(inputs.refl_world_y[..., None], 3, -1))
    write_exr(folder / "refl_texture.exr", inputs.refl_texture)
    f = inputs.cubemap.shape[1]
    write_exr(
        folder / "cubemap_cross.exr", inputs.cubemap.transpose(1, 0, 2, 3).reshape(f, 6 * f, 3)
    )
    lut = np.zeros((1, len(inputs.fresnel_lut), 3), np.float32)
    lut[0, :, :2] = inputs.fresnel_lut
    write_exr(folder / "fresnel_lut.exr", lut)


def load_scene_data(exp, variant, cache=None):
    """Reference (cached) and shader inputs at the experiment's resolution."""
    from .scene.reference import load_or_render
    from .scene.shader_inputs import load_or_build_shader_inputs

    from ._progress import Stages
    from .scene.baseline_inputs import inputs_for_shader  # e.g. the baseline's screen buffers

    st = Stages(log=_log)
    spp = exp["reference.spp"]
    with st.stage(
        "reference_s",
        f"reference: {exp['resolution'][0]}x{exp['resolution'][1]}, "
        + ("automatic spp (pilot, then final passes)" if spp == "auto" else f"{spp} spp"),
    ):
        ref = load_or_render(
            exp, variant, cache=cache, progress=st.counter("  reference passes"), log=_log
        )
    with st.stage("inputs_s", "shader inputs"):
        inputs = load_or_build_shader_inputs(exp, variant, cache=cache, log=_log, progress=st)
        if not is_user_shader(exp["fit.shader"]):  # a user's shader reads the study's inputs
            inputs = inputs_for_shader(
                exp, inputs, exp["fit.shader"], variant, cache=cache, log=_log
            )
    return ref, inputs, st.timings


def run_preview(experiment, out, overrides=None, variant=None, cache=None) -> dict:
    """``study preview``: the port with the experiment's start constants next to the reference,
    error map, diagnostics (PNG) and error figures on water pixels (preview.json)."""
    from ._backend import drjit_backend
    from .report.calibration import comparison_figure, diagnostics_figure
    from ._metrics import errors
    from .fit.model import ShaderModel, constants_from_experiment

    t_start = time.perf_counter()
    exp, variant, out = prepare(experiment, out, overrides, variant)
    setup_s = time.perf_counter() - t_start
    ref, inputs, timings = load_scene_data(exp, variant, cache)
    timings = {"setup_s": setup_s, **timings}
    w, h = exp["resolution"]
    t0 = time.perf_counter()
    model = ShaderModel.from_experiment(
        exp, inputs, ref.image, backend=drjit_backend(variant), resolution=(w, h)
    )
    constants = constants_from_experiment(exp)
    timings["model_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    img, diag = model.render(constants)
    timings["port_s"] = time.perf_counter() - t0
    err = errors(ref.image, img, model.mask)
    t0 = time.perf_counter()
    write_exr(out / "reference.exr", ref.image, ref.provenance)
    write_exr(out / "port.exr", img, {"shader": model.shader, "constants": constants.to_dict()})
    write_png(out / "reference.png", ref.image)
    write_png(out / "port.png", img)
    comparison_figure(
        out / "preview.png",
        {"reference": ref.image, "port (start constants)": img},
        {"port (start constants)": err},
        model.mask,
        title=f"{exp['name']}: {model.shader}",
    )
    diagnostics_figure(out / "diagnostics.png", diag.maps, model.mask, title="port diagnostics")
    timings["figures_s"] = time.perf_counter() - t0
    timings["total_s"] = time.perf_counter() - t_start
    summary = {
        "experiment": exp["name"],
        "shader": model.shader,
        "variant": variant,
        "constants": constants.to_dict(),
        "error": err,
        "water_pixels": int(model.mask.sum()),
        "reference": {"spp": ref.spp, "noise": ref.noise, "path": str(ref.path)},
        "diagnostics": diag.summary(model.mask),
        "timings": timings,
        "sun": _sun(exp),
    }
    write_json(out / "preview.json", summary)
    _log(
        f"preview: RMSE {err['rmse']:.4f}, FLIP {err['flip']:.4f} on "
        f"{summary['water_pixels']} water "
        f"pixels; wrote {out}"
    )
    return summary


def run_tradeoff(
    experiments,
    out,
    overrides=None,
    variant=None,
    tolerance=None,
    scheduler=None,
    workers=None,
    search=None,
    budget=None,
) -> dict:
    """``study tradeoff``: the speed-versus-accuracy study over ``experiments`` on the sweep engine
    (``study.studies.tradeoff``); tables, ``pareto.png``, ``report.md`` and shaders in ``out``."""
    from .studies.tradeoff import run_tradeoff as run

    return run(
        list(experiments),
        out,
        overrides,
        scheduler=scheduler,
        workers=workers,
        tolerance=tolerance,
        variant=variant or "llvm_ad_rgb",
        log=_log,
        search=search,
        budget=budget,
    )


def run_stability(
    experiments, out, overrides=None, variant=None, scheduler=None, workers=None, **options
) -> dict:
    """``study stability``: solvers from many starts, which residual, reference noise
    (``study.studies.stability``); tables, charts and ``stability.md`` in ``out``."""
    from .studies.stability import run_stability as run

    _refuse_animated(experiments, overrides, "study stability")
    return run(
        list(experiments),
        out,
        overrides,
        scheduler=scheduler,
        workers=workers,
        variant=variant or "llvm_ad_rgb",
        log=_log,
        **options,
    )


def _refuse_animated(experiments, overrides, command: str) -> None:
    """ExperimentError if any of ``experiments`` is animated (``command`` takes still frames)."""
    from .scene.frames import refuse_animated

    for path in experiments:
        refuse_animated(load_experiment(path, overrides), command)


def run_export(constants_json, out, targets=None) -> list:
    """``study export``: the shipped shaders with the constants of a JSON file, in
    ``out/shaders``; ``targets``: engine targets, a comma-separated string or list, 'none', or
    None (every one the installed tools can make)."""
    from .export.shaders import export_shaders, load_constants_json

    if isinstance(targets, str):
        targets = [] if targets == "none" else [t for t in targets.split(",") if t]
    constants = load_constants_json(constants_json)
    out = Path(out)
    paths = export_shaders(constants, out / "shaders", targets=targets)
    made = sorted(p.name for p in (out / "shaders").iterdir() if p.is_dir())
    _log(
        f"export: wrote {len(paths)} files to {out / 'shaders'} ({', '.join(made)}; GLSL compiled "
        "with glslangValidator, targets checked as listed in targets.json)"
    )
    return paths


def run_calibrate(experiment, out, overrides=None, variant=None, solver=None, cache=None) -> dict:
    """``study calibrate``: reference (cached), fit, export, GL check, figures, report.md and
    constants.json (a ``CalibrationResult``) in ``out``; an animated experiment
    (``animation.frames`` > 1) is fitted on all its frames (``study._anim_jobs``). Returns the JSON
    object written."""
    from ._backend import drjit_backend
    from .fit.calibrate import calibrate_model, scene_frozen, timed
    from .fit.decorrelated import half_models, texture_half_models
    from .fit.model import ShaderModel, constants_from_experiment
    from .fit.solvers import SOLVERS
    from .export.shaders import export_shaders

    if solver is not None and solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; choose one of {', '.join(SOLVERS)}")
    t_start = time.perf_counter()
    exp, variant, out = prepare(experiment, out, overrides, variant, frames=True)
    setup_s = time.perf_counter() - t_start
    if is_user_shader(exp["fit.shader"]):
        from ._user_jobs import calibrate_user_shader

        ref, inputs, timings = load_scene_data(exp, variant, cache)
        return calibrate_user_shader(
            exp, variant, out, ref, inputs, {"setup_s": setup_s, **timings}
        )
    solver = solver or exp["fit.solver"]
    from .scene.frames import is_animated

    if is_animated(exp):
        from ._anim_jobs import run_calibrate_animated

        return run_calibrate_animated(exp, variant, out, solver, cache, setup_s)
    ref, inputs, timings = load_scene_data(exp, variant, cache)
    timings = {"setup_s": setup_s, **timings}
    backend = drjit_backend(variant)
    start = constants_from_experiment(exp)
    with timed(timings, "model_s"):
        model = ShaderModel.from_experiment(
            exp, inputs, ref.image, backend=backend, stderr_full=ref.stderr
        )
        halves = half_models(exp, inputs, ref.image, backend=backend)
        check = halves or texture_half_models(exp, inputs, ref.image, backend=backend)
    _log(
        f"calibrate: fitting {exp['fit.parameters']} of {model.shader} with {solver} on "
        f"{int(model.mask.sum())} water pixels at "
        f"{exp['fit.resolution'][0]}x{exp['fit.resolution'][1]}"
    )
    with timed(timings, "fit_s"):
        cal = calibrate_model(
            model,
            start,
            exp["fit.parameters"],
            solver,
            exp["fit.max_steps"],
            frozen_by_scene=scene_frozen(exp),
            halves=halves,
            scan_basins=True,
            basin_check=check,
        )
    with timed(timings, "evaluate_s"):
        ev = _evaluate_calibration(exp, inputs, ref, model, cal, backend)
    with timed(timings, "export_s"):
        _log(f"calibrate: exporting and compiling {model.shader} (and its vertex shader)")
        export_shaders(cal.fitted, out / "shaders", [model.shader], targets=None)
    with timed(timings, "gl_check_s"):
        _log("calibrate: running the exported shader on OpenGL (llvmpipe)")
        gl = gl_check(model.shader, inputs, cal.fitted, out / "shaders")
        engine_targets = target_checks(model.shader, inputs, cal.fitted, out / "shaders")
    with timed(timings, "figures_s"):
        figs = _calibration_figures(out, exp, model, ref, ev, cal, solver)
    timings["total_s"] = time.perf_counter() - t_start  # up to the report (written last)
    result = _calibration_result(exp, variant, model, ref, cal, ev, solver, timings, gl)
    result.engine_targets = engine_targets
    return _write_result(out, result, figs, ev)


def _evaluate_calibration(exp, inputs, ref, model, cal, backend) -> dict:
    """The start and fitted constants at the experiment's full resolution: the model ``full``,
    images ``img0`` / ``img1`` ((H, W, 3) linear RGB), their errors ``e0`` / ``e1`` (rmse, flip
    on the water pixels), the fitted render's diagnostics ``diag1`` and the ``parsimony`` of the
    fit at the fit resolution (information criteria)."""
    from ._metrics import errors, information_criteria
    from .fit.model import ShaderModel

    w, h = exp["resolution"]
    full = ShaderModel.from_experiment(exp, inputs, ref.image, backend=backend, resolution=(w, h))
    img0, _ = full.render(cal.start)
    img1, diag1 = full.render(cal.fitted)
    fitted_names = [n for n, p in cal.parameters.items() if p["status"] in ("fitted", "bound")]
    parsimony = {
        **information_criteria(model.residual(cal.fitted), len(fitted_names)),
        "fitted": fitted_names,
        "defines": list(model.variant.defines),
    }
    return {
        "full": full,
        "img0": img0,
        "img1": img1,
        "diag1": diag1,
        "e0": errors(ref.image, img0, full.mask),
        "e1": errors(ref.image, img1, full.mask),
        "parsimony": parsimony,
    }


def _calibration_figures(out, exp, model, ref, ev, cal, solver) -> dict:
    """comparison.png, diagnostics.png, loss.png and the three EXRs (reference, default,
    fitted) in ``out``; returns figure name -> file name for the report."""
    from .report.calibration import comparison_figure, diagnostics_figure, loss_figure

    figs = {"comparison": "comparison.png", "diagnostics": "diagnostics.png", "loss": "loss.png"}
    mask = ev["full"].mask
    comparison_figure(
        out / figs["comparison"],
        {"reference": ref.image, "default": ev["img0"], "fitted": ev["img1"]},
        {"default": ev["e0"], "fitted": ev["e1"]},
        mask,
        title=f"{exp['name']}: {model.shader}",
    )
    diagnostics_figure(
        out / figs["diagnostics"], ev["diag1"].maps, mask, title="diagnostics, fitted constants"
    )
    loss_figure(out / figs["loss"], {solver: cal.losses}, title="loss at each evaluation")
    write_exr(out / "fitted.exr", ev["img1"], {"constants": cal.fitted.to_dict()})
    write_exr(out / "default.exr", ev["img0"], {"constants": cal.start.to_dict()})
    write_exr(out / "reference.exr", ref.image, ref.provenance)
    return figs


def _calibration_result(exp, variant, model, ref, cal, ev, solver, timings, gl):
    """The ``CalibrationResult`` of one scene's calibration."""
    from .fit.result import CalibrationResult

    e0, e1 = ev["e0"], ev["e1"]
    return CalibrationResult(
        shader=model.shader,
        backend=variant,
        parameters=cal.parameters,
        constants=cal.fitted.to_dict(),
        error={
            "rmse": {"default": e0["rmse"], "fitted": e1["rmse"]},
            "flip": {"default": e0["flip"], "fitted": e1["flip"]},
        },
        solver=solver,
        fit=cal.fit_summary,
        identifiability=cal.identifiability,
        timings=timings,
        gl_check=gl,
        experiment=exp["name"],
        fit_resolution=exp["fit.resolution"],
        resolution=exp["resolution"],
        step_sweep=cal.sweep,
        reference={
            "spp": ref.spp,
            "noise": ref.noise,
            "path": str(ref.path),
            "key": ref.provenance["key"],
        },
        diagnostics=ev["diag1"].summary(ev["full"].mask),
        sun=_sun(exp),
        parsimony=ev["parsimony"],
    )


def _write_result(out, result, figs, ev) -> dict:
    """constants.json and report.md of ``result`` in ``out``; returns the JSON object."""
    from .report.calibration import write_report

    summary = result.to_json()
    write_json(out / "constants.json", summary)
    write_report(out, summary, figs)
    e0, e1 = ev["e0"], ev["e1"]
    _log(
        f"calibrate: RMSE {e0['rmse']:.4f} -> {e1['rmse']:.4f}, FLIP {e0['flip']:.4f} -> "
        f"{e1['flip']:.4f}; wrote {out}"
    )
    return summary


def _sun(exp) -> dict:
    """The shader's sun (explicit, or found in the sky file: direction, solid angle, radiance)."""
    from .scene.user_scene import sun_summary

    return sun_summary(exp)


# ---- several scenes: the joint fit and leave-one-scene-out -----------------------------------


def run_failures(
    experiments,
    out,
    overrides=None,
    variant=None,
    shader=None,
    constants_json=None,
    scheduler=None,
    workers=None,
) -> list:
    """``study failures``: the failure catalogue of each experiment, one sweep job per experiment
    (``study.studies.failures``): ``<out>/<name>/failures.png``, ``failures.parquet``,
    ``report.md``."""
    from .export.shaders import load_constants_json
    from .studies.failures import run_failures as run

    _refuse_animated(experiments, overrides, "study failures")

    constants = load_constants_json(constants_json) if constants_json else None
    return run(
        list(experiments),
        out,
        overrides,
        variant=variant or "llvm_ad_rgb",
        shader=shader,
        constants=constants,
        scheduler=scheduler,
        workers=workers,
        log=_log,
    )
