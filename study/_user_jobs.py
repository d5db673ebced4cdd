"""``study calibrate`` of the user's own GLSL shader (``fit.shader = "my_water.frag"``).

The shader (``shaders_port.spirv.user_shader.UserShader``, declared by ``// @study`` pragmas and
``fit.declare``) is executed through SPIR-V on the experiment's shader inputs at
``fit.resolution``, fitted to the box-downsampled reference on the scored water pixels (the
shader's coverage and the reference's water, eroded by one pixel) by
``study.fit.user_shader.calibrate``, written back into a copy of its file with the fitted
constants in place of the initializers (every other byte kept), and that file run on OpenGL
(llvmpipe) against the executor with the GL check's thresholds. Writes ``shaders/<file>``,
``constants.json``, ``report.md``, ``fit.png``, ``reference.exr`` and ``fitted.exr``; with
``fit.write_back = "file"`` the fitted constants also go into the user's file itself.
"""

from __future__ import annotations

import time
from pathlib import Path


from ._io import write_exr, write_json
from ._metrics import downsample, errors
from ._progress import log as _log
from .export.gl_check import gl_check_user
from .scene.experiment import load_user_shader


def _fmt(v) -> str:
    if isinstance(v, (tuple, list)):
        return "(" + ", ".join(f"{float(x):.6g}" for x in v) + ")"
    return f"{float(v):.6g}"


def _report(exp, shader, fit, gl: dict, cost: dict, err: dict, timings: dict) -> str:
    rows = []
    for name, p in fit.parameters.items():
        lo, hi = shader.bounds(name)
        se = p["rel_std_error"]
        rows.append(
            f"| `{name}` | {_fmt(p['start'])} | {_fmt(p['value'])} | [{lo:g}, {hi:g}] | "
            f"{p['status']} | {'-' if se is None else f'{100 * se:.2g} %'} |"
        )
    held = [f"`{n}`: {p['reason']}" for n, p in fit.parameters.items() if p["status"] != "fitted"]
    gl_line = (
        f"mean |diff| {gl['mean_abs']:.2e}, 99.9th percentile {gl['p999']:.2e} on "
        f"{gl['pixels']} pixels: {'passed' if gl['passed'] else 'FAILED'}"
        if gl["ran"]
        else f"not run ({gl['why']})"
    )
    return "\n".join(
        [
            f"# {exp['name']}: {shader.label} calibrated",
            "",
            f"Fitted through SPIR-V by {fit.solver} on {fit.pixels} water pixels at "
            f"{exp['fit.resolution'][0]}x{exp['fit.resolution'][1]}: {fit.iterations} "
            f"iterations, stopped: {fit.reason}.",
            "",
            f"RMSE (linear RGB): start {fit.rmse_start:.5f}, fitted {fit.rmse:.5f}; FLIP of the "
            f"fitted shader {err['flip']:.4f}.",
            "",
            "| constant | start | fitted | range | status | standard error |",
            "|---|---|---|---|---|---|",
            *rows,
            "",
            *([f"On a bound or held: {'; '.join(held)}.", ""] if held else []),
            f"Cost per water pixel (counted from the translated code): {cost['fetches']:.2f} "
            f"texture fetches, {cost['iterations']:.2f} loop iterations on average.",
            "",
            f"`shaders/{shader.label}` (the file, fitted constants in place) on OpenGL against "
            f"the executor: {gl_line}.",
            "",
            f"Seconds: {', '.join(f'{k} {v:.1f}' for k, v in timings.items())}.",
            "",
        ]
    )


def calibrate_user_shader(exp, variant, out: Path, ref, inputs, timings: dict) -> dict:
    """Fit, write back, GL-check and report ``fit.shader`` (module doc). Returns the JSON
    object written to ``constants.json``."""
    from .fit.user_shader import calibrate
    from .report.calibration import comparison_figure
    from .scene.reference import water_mask

    shader = load_user_shader(exp.values)
    w, h = exp["fit.resolution"]
    fy, fx = ref.image.shape[0] // h, ref.image.shape[1] // w
    target = downsample(ref.image, fy, fx) if (fy, fx) != (1, 1) else ref.image
    small = inputs.with_resolution(w, h)
    _log(f"calibrate: fitting {', '.join(shader.scalar_names())} of {shader.label} (SPIR-V)")
    t0 = time.perf_counter()
    fit = calibrate(shader, small, target, reference_mask=water_mask(exp, w, h),
                    max_iterations=exp["fit.max_steps"], solver=exp["fit.solver"])  # fmt: skip
    timings["fit_s"] = time.perf_counter() - t0
    (out / "shaders").mkdir(exist_ok=True)
    written = out / "shaders" / shader.label
    written.write_text(shader.written(fit.values), encoding="utf-8")
    t0 = time.perf_counter()
    ours = shader.render(small, fit.values).numpy()
    start = shader.render(small).numpy()
    gl = gl_check_user(shader, small, fit.values, ours)
    timings["gl_check_s"] = time.perf_counter() - t0
    if exp["fit.write_back"] == "file":
        if gl["passed"] is False:
            _log(f"calibrate: {shader.label} not written back: the GL check failed")
        else:
            Path(exp["fit.shader"]).write_text(written.read_text(encoding="utf-8"), "utf-8")
            _log(f"calibrate: wrote the fitted constants into {exp['fit.shader']}")
    mask = fit.mask
    err = errors(target, ours["color"], mask)
    cost = {k: float(ours[k][mask].mean()) for k in ("fetches", "iterations")}
    comparison_figure(
        out / "fit.png",
        {"reference": target, "start": start["color"], "fitted": ours["color"]},
        {"start": errors(target, start["color"], mask), "fitted": err},
        mask,
        title=f"{exp['name']}: {shader.label}",
    )
    write_exr(out / "reference.exr", target, ref.provenance)
    write_exr(out / "fitted.exr", ours["color"], {"shader": shader.label})
    (out / "report.md").write_text(_report(exp, shader, fit, gl, cost, err, timings))
    result = {
        "experiment": exp["name"],
        "shader": str(exp["fit.shader"]),
        "variant": variant,
        "constants": {k: list(v) if isinstance(v, tuple) else v for k, v in fit.values.items()},
        "start": {k: list(v) if isinstance(v, tuple) else v for k, v in shader.defaults().items()},
        "rmse_start": fit.rmse_start,
        "rmse": fit.rmse,
        "flip": float(err["flip"]),
        "iterations": fit.iterations,
        "stopped": fit.reason,
        "solver": fit.solver,
        "parameters": fit.parameters,
        "identifiability": fit.identifiability,
        "cost": cost,
        "gl_check": gl,
        "timings": timings,
    }
    write_json(out / "constants.json", result)
    _log(f"calibrate: wrote {out} (RMSE {fit.rmse_start:.4f} -> {fit.rmse:.4f})")
    return result
