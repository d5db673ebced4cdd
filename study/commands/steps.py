"""The steps every command shares, written once. First: load and check the experiment,
initialise the backend, make the output folder; the reference and the shader inputs of a still
scene (with whatever the shader reads beyond the study's inputs); the sun the shader is lit by.
Last, for every calibration: the fitted shader exported (GLSL, or a user's file, and the engine
targets) and checked on OpenGL, the start and fitted constants scored at full resolution, the
figures, ``constants.json`` and ``report.md``."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from shaders_port import glsl_scalar

from .._backend import init_backend
from .._io import write_exr, write_json, write_text_atomic
from .._metrics import errors, information_criteria
from .._progress import Stages
from .._progress import log as _log
from ..config.experiment import load_experiment
from ..export.gl_check import (
    gl_check,
    gl_check_user,
    gles_check_user,
    hlsl_check_user,
    manifest_checks,
    target_checks,
)
from ..export.shaders import export_shaders, export_user_shader
from ..export.targets import resolve_targets
from ..export.textures import lut_image, texture_record, with_exported_textures, write_textures
from ..fit.build import build_model
from ..fit.calibrate import timed
from ..fit.model import constants_json
from ..fit.result import CalibrationResult
from ..report.calibration import comparison_figure, diagnostics_figure, loss_figure, write_report
from ..scene.baseline_inputs import inputs_for_shader
from ..scene.animation import is_animated, refuse_animated
from ..scene.reference import load_or_render
from ..scene.shader_inputs import load_or_build_shader_inputs
from ..scene.shader_waves import shader_waves
from ..scene.user_scene import check_scene, sun_summary
from ..scene.water_in_view import check_water_in_view


def prepare(experiment, out, overrides=None, variant=None, frames: bool = False):
    """Load the experiment (its files validated), initialise the backend, check what needs it
    (the mesh), create the output folder. ``frames``: the command handles every frame of an
    animated experiment (else it says that it uses frame 0)."""
    exp = load_experiment(experiment, overrides)
    variant = init_backend(variant or exp.variant)
    exp = exp.on_backend(variant)  # a fit.resolution "auto" for the device the run uses
    if "fit.resolution" in exp.auto:
        (w, h), (fw, fh) = exp.resolution, exp.fit.resolution
        _log(f'experiment: fit.resolution = "auto": {fw}x{fh} ({w}x{h} on {variant})')
    check_water_in_view(exp)
    if is_animated(exp) and not frames:
        _log(
            f"experiment: {exp.name} has {exp.animation.frames} frames; this command uses "
            "frame 0 (study calibrate fits every frame)"
        )
    check_scene(exp)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    return exp, variant, out


def load_scene_data(exp, variant, cache=None):
    """Reference (cached) and shader inputs at the experiment's resolution."""
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
    write_exr(folder / "fresnel_lut.exr", lut_image(inputs.fresnel_lut))


def refuse_animated_all(experiments, overrides, command: str) -> None:
    """ExperimentError if any of ``experiments`` is animated (``command`` takes still frames)."""
    for path in experiments:
        refuse_animated(load_experiment(path, overrides), command)


def export_calibration(exp, model, frames: list, cal, out: Path, timings: dict):
    """The fitted shader (``cal.fitted``; the binding sheets mark what ``cal.parameters`` says
    was fitted) exported into ``out/shaders``: a variant's core and compatibility GLSL,
    or a copy of a user's file with the fitted constants in place (``fit.write_back = "file"``:
    the file itself too, once the GL check passed); every engine target the installed tools
    make; the Fresnel LUT and normal map the constants assume, and every other texture a
    user's shader reads that the engine uploads, in ``shaders/textures/``
    (``study.export.textures``). Then run on OpenGL (llvmpipe), with those textures read back
    from their files, against the Dr.Jit shader on each of ``frames`` (shader inputs at the
    experiment's resolution), and the engine targets' checks. Returns (a GL check per frame,
    engine targets, what the result adds: the textures' record and, for a user's file, the
    file, its SHA-256 and declaration)."""
    shaders, fitted = out / "shaders", cal.fitted
    user = getattr(model, "user_shader", None)
    record = texture_record(exp, frames[0], user)
    normal_map = user.engine["normal_map"] if user is not None else None
    textures = (record, lambda folder: write_textures(record, frames[0], folder, normal_map))
    status = {glsl_scalar(n): p["status"] for n, p in cal.parameters.items()}
    with timed(timings, "export_s"):
        _log(f"calibrate: exporting and compiling {model.label} (and its vertex shader)")
        left_out = {}
        if user is None:
            export_shaders(fitted, shaders, [model.shader], None, textures, status)
        else:
            left_out = _export_user(user, fitted, shaders, textures, status)
    # the GL check runs the textures that ship: read back from the exported files
    frames = [with_exported_textures(i, shaders) for i in frames]
    with timed(timings, "gl_check_s"):
        _log(f"calibrate: running the exported shader on OpenGL (llvmpipe), {len(frames)} frame(s)")
        if user is None:
            gl = [gl_check(model.shader, i, fitted, shaders) for i in frames]
            targets = target_checks(model.shader, frames[0], fitted, shaders)
            return gl, targets, {"textures": record}
        ours = [user.render(i, fitted, backend=model.backend).numpy() for i in frames]
        gl = [gl_check_user(user, i, fitted, o) for i, o in zip(frames, ours)]
        engine_targets = manifest_checks(shaders)
        engine_targets.update({t: {"left_out": why} for t, why in left_out.items()})
        if "gles300" in engine_targets and "left_out" not in engine_targets["gles300"]:
            engine_targets["gles300"]["llvmpipe"] = gles_check_user(
                user, frames[0], fitted, ours[0], shaders
            )
        if "hlsl" in engine_targets and "left_out" not in engine_targets["hlsl"]:
            engine_targets["hlsl"]["llvmpipe"] = hlsl_check_user(
                user, frames[0], fitted, ours[0], shaders
            )
    text = user.source  # the file's text as the calibration leaves it
    if exp.fit.write_back == "file":
        if not all(g["passed"] is not False for g in gl):
            _log(f"calibrate: {user.label} not written back: the GL check failed")
        else:
            # the initializers replaced; a uniform without one stays so (its START, in the
            # declaration, stays the start value: the file must read back as it was declared)
            text = user.written(fitted, bare_initializers=False)
            write_text_atomic(Path(exp.fit.shader), text)
            _log(f"calibrate: wrote the fitted constants into {exp.fit.shader}")
            vtext = user.vertex_written(fitted, bare_initializers=False)
            if (
                vtext is not None
                and not user.vertex.shader.shared
                and vtext != user.vertex.shader.original
            ):
                write_text_atomic(Path(exp.fit.vertex), vtext)
                _log(f"calibrate: wrote the fitted constants into {exp.fit.vertex}")
    extra = {
        "textures": record,
        "shader_file": str(exp.fit.shader),
        "shader_sha256": hashlib.sha256(text.encode("utf-8")).hexdigest(),
        "declaration": {
            "constants": {n: user.declared_range(n) for n in user.constants},
            "bindings": dict(user.bindings),
            "values": {n: list(v) for n, v in user.engine_values().items()},
            **{k: v for k, v in user.engine.items() if v is not None},
        },
        "defines": list(user.defines),
        "include_paths": list(user.include_paths[1:]),  # after the file's own folder
    }
    if user.vertex is not None:  # the pair: its vertex shader and the grid it ran on
        extra["vertex_file"] = str(exp.fit.vertex)
        extra["vertex_grid"] = list(user.vertex.cells)
        extra["vertex_defines"] = list(user.vertex.shader.defines)
    if exp.waves.source == "shader":  # the reference's surface: how well it fits the normals
        extra["waves"] = shader_waves(exp).stats
    return gl, engine_targets, extra


def evaluate_calibration(exp, inputs, ref, model, cal, backend) -> dict:
    """The start and fitted constants at the experiment's full resolution: the model ``full``,
    images ``img0`` / ``img1`` ((H, W, 3) linear RGB), their errors ``e0`` / ``e1`` (rmse, flip
    on the water pixels), the fitted render's diagnostics ``diag1`` and the ``parsimony`` of the
    fit at the fit resolution (information criteria)."""
    w, h = exp.resolution
    full = build_model(exp, inputs, ref.image, backend=backend, resolution=(w, h))
    img0, _ = full.render(cal.start)
    img1, diag1 = full.render(cal.fitted)
    fitted_names = [n for n, p in cal.parameters.items() if p["status"] in ("fitted", "bound")]
    parsimony = {
        **information_criteria(model.residual(cal.fitted), len(fitted_names)),
        "fitted": fitted_names,
        "defines": list(model.defines),
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


def calibration_figures(out, exp, model, ref, ev, cal, solver) -> dict:
    """comparison.png, diagnostics.png, loss.png and the three EXRs (reference, default,
    fitted) in ``out``; returns figure name -> file name for the report."""
    figs = {"comparison": "comparison.png", "diagnostics": "diagnostics.png", "loss": "loss.png"}
    mask = ev["full"].mask
    comparison_figure(
        out / figs["comparison"],
        {"reference": ref.image, "default": ev["img0"], "fitted": ev["img1"]},
        {"default": ev["e0"], "fitted": ev["e1"]},
        mask,
        title=f"{exp.name}: {model.label}",
    )
    diagnostics_figure(
        out / figs["diagnostics"], ev["diag1"].maps, mask, title="diagnostics, fitted constants"
    )
    loss_figure(out / figs["loss"], {solver: cal.losses}, title="loss at each evaluation")
    write_exr(out / "fitted.exr", ev["img1"], {"constants": constants_json(cal.fitted)})
    write_exr(out / "default.exr", ev["img0"], {"constants": constants_json(cal.start)})
    write_exr(out / "reference.exr", ref.image, ref.provenance)
    return figs


def calibration_result(exp, variant, model, ref, cal, ev, solver, timings, gl):
    """The ``CalibrationResult`` of one scene's calibration."""
    e0, e1 = ev["e0"], ev["e1"]
    user = getattr(model, "user_shader", None)
    return CalibrationResult(
        shader=model.label,
        backend=variant,
        parameters=with_stages(cal.parameters, user),
        constants=constants_json(cal.fitted),
        error={
            "rmse": {"default": e0["rmse"], "fitted": e1["rmse"]},
            "flip": {"default": e0["flip"], "fitted": e1["flip"]},
        },
        solver=solver,
        fit=cal.fit_summary,
        identifiability=cal.identifiability,
        timings=timings,
        gl_check=gl,
        experiment=exp.name,
        fit_resolution=exp.fit.resolution,
        resolution=exp.resolution,
        step_sweep=cal.sweep,
        reference={
            "spp": ref.spp,
            **{k: ref.provenance.get(k) for k in ("spp_asked", "spp_per_pass", "n_seeds")},
            "sampler": ref.provenance.get("sampler"),
            "noise": ref.noise,
            "path": str(ref.path),
            "key": ref.provenance["key"],
        },
        diagnostics=ev["diag1"].summary(ev["full"].mask),
        sun=sun_summary(exp),
        parsimony=ev["parsimony"],
    )


def with_stages(parameters: dict, user) -> dict:
    """``parameters`` (scalar name -> the fit's record) with each one's ``stage`` ('fragment',
    'vertex' or 'both': the stages that read it) for a user's shader run after its own vertex
    shader (``user``, a ``UserShader``; else unchanged)."""
    if user is None or user.vertex is None:
        return parameters
    return {n: {**p, "stage": user.stage_of(n.split("[")[0])} for n, p in parameters.items()}


def write_result(out, result, figs, ev) -> dict:
    """constants.json and report.md of ``result`` in ``out``; returns the JSON object."""
    summary = result.to_json()
    write_json(out / "constants.json", summary)
    write_report(out, summary, figs)
    e0, e1 = ev["e0"], ev["e1"]
    _log(
        f"calibrate: RMSE {e0['rmse']:.4f} -> {e1['rmse']:.4f}, FLIP {e0['flip']:.4f} -> "
        f"{e1['flip']:.4f}; wrote {out}"
    )
    return summary


def _export_user(user, fitted: dict, shaders: Path, textures, status: dict) -> dict:
    """``export_user_shader`` into every engine target the user's files translate to: a target
    whose translation or compile check fails (a vertex shader writing ``gl_ClipDistance`` is
    no GLSL ES 3.00) is left out with a warning naming its error; ValueError when the core
    files themselves fail or no target is left. Returns {target left out: why}."""
    targets, left_out = list(resolve_targets(None)), {}
    while True:
        try:
            export_user_shader(user, fitted, shaders, targets, textures, status)
            return left_out
        except RuntimeError as exc:
            head = str(exc).splitlines()[0] if str(exc) else repr(exc)
            bad = [t for t in targets if f" on {t}/" in head]
            if not bad:
                raise ValueError(f"export of {user.label}: {exc}") from None
            targets.remove(bad[0])
            why = "; ".join(ln for ln in str(exc).splitlines()[1:] if "ERROR" in ln) or head
            _log(f"calibrate: WARNING: engine target {bad[0]} left out: {why}")
            left_out[bad[0]] = why
