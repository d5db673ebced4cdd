"""``study render`` and ``study preview``: the reference and the shader inputs of an experiment,
and its shader with the start constants beside the reference."""

from __future__ import annotations

import time

from pathlib import Path

import numpy as np

from .._io import write_exr, write_json, write_png
from .._progress import log as _log
from ..calibration.frames import Frame, load_scene_data, prepare
from ..calibration.scoring import Scorer
from ..calibration.shader import Shader
from ..export.textures import lut_image
from ..fit.model import constants_json
from ..report.calibration import comparison_figure, diagnostics_figure
from ..scene.user_scene import sun_summary


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
        "experiment": exp.name,
        "variant": variant,
        "reference": ref.provenance,
        "timings": timings,
        "outputs": sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()),
    }
    write_json(out / "summary.json", summary)
    _log(f"render: wrote {out}")
    return summary


def run_preview(experiment, out, overrides=None, variant=None, cache=None) -> dict:
    """``study preview``: the port with the experiment's start constants next to the reference,
    error map, diagnostics (PNG) and error figures on water pixels (preview.json)."""
    t_start = time.perf_counter()
    exp, variant, out = prepare(experiment, out, overrides, variant)
    setup_s = time.perf_counter() - t_start
    ref, inputs, timings = load_scene_data(exp, variant, cache)
    timings = {"setup_s": setup_s, **timings}
    t0 = time.perf_counter()
    scorer = Scorer(Shader.of(exp), [Frame.of(exp, ref, inputs)], variant)
    model = scorer.model(0)
    constants = model.start_constants(exp)
    timings["model_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    score = scorer(0, constants)
    img, diag, err = score.image, score.diagnostics, score.errors
    timings["port_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    write_exr(out / "reference.exr", ref.image, ref.provenance)
    write_exr(
        out / "port.exr", img, {"shader": model.label, "constants": constants_json(constants)}
    )
    write_png(out / "reference.png", ref.image)
    write_png(out / "port.png", img)
    comparison_figure(
        out / "preview.png",
        {"reference": ref.image, "port (start constants)": img},
        {"port (start constants)": err},
        model.mask,
        title=f"{exp.name}: {model.label}",
    )
    diagnostics_figure(out / "diagnostics.png", diag.maps, model.mask, title="port diagnostics")
    timings["figures_s"] = time.perf_counter() - t0
    timings["total_s"] = time.perf_counter() - t_start
    summary = {
        "experiment": exp.name,
        "shader": model.label,
        "variant": variant,
        "constants": constants_json(constants),
        "error": err,
        "water_pixels": int(model.mask.sum()),
        "reference": {"spp": ref.spp, "noise": ref.noise, "path": str(ref.path)},
        "diagnostics": diag.summary(model.mask),
        "timings": timings,
        "sun": sun_summary(exp),
    }
    write_json(out / "preview.json", summary)
    _log(
        f"preview: RMSE {err['rmse']:.4f}, FLIP {err['flip']:.4f} on "
        f"{summary['water_pixels']} water "
        f"pixels; wrote {out}"
    )
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
    write_exr(folder / "fresnel_lut.exr", lut_image(inputs.fresnel_lut))
