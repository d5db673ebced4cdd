"""The study's jobs, one function per CLI command; each writes its artifacts into one folder."""
from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from ._backend import init_backend
from ._experiment import load_experiment
from ._exr import write_exr, write_png


def _progress(label: str):
    def report(done: int, total: int) -> None:
        print(f"\r{label}: {done}/{total}", end="" if done < total else "\n", file=sys.stderr, flush=True)
    return report


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def write_json(path: Path, data: dict) -> None:
    """Write JSON atomically; refuses NaN/inf (they are not JSON)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(data, indent=2, sort_keys=True, allow_nan=False) + "\n")
    tmp.replace(path)


def prepare(experiment, out, overrides=None, variant=None):
    """Load the experiment, initialise the backend, create the output folder."""
    exp = load_experiment(experiment, overrides)
    variant = init_backend(variant or exp["variant"])
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    return exp, variant, out


def run_render(experiment, out, overrides=None, variant=None, cache=None) -> dict:
    """``study render``: reference.exr (+ PNG), shader inputs (.npz and EXRs), summary.json."""
    from ._reference import load_or_render
    from ._shader_inputs import build_shader_inputs

    exp, variant, out = prepare(experiment, out, overrides, variant)
    t0 = time.perf_counter()
    ref = load_or_render(exp, variant, cache=cache, progress=_progress("reference passes"), log=_log)
    t_ref = time.perf_counter() - t0
    write_exr(out / "reference.exr", ref.image, ref.provenance)
    write_png(out / "reference.png", ref.image)
    t0 = time.perf_counter()
    inputs = build_shader_inputs(exp)
    t_inp = time.perf_counter() - t0
    save_shader_inputs(inputs, out / "inputs")
    summary = {"experiment": exp["name"], "variant": variant, "reference": ref.provenance,
               "timings": {"reference_s": t_ref, "inputs_s": t_inp},
               "outputs": sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())}
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
    write_exr(folder / "cubemap_cross.exr", inputs.cubemap.transpose(1, 0, 2, 3).reshape(f, 6 * f, 3))
    lut = np.zeros((1, len(inputs.fresnel_lut), 3), np.float32)
    lut[0, :, :2] = inputs.fresnel_lut
    write_exr(folder / "fresnel_lut.exr", lut)


def finite_or_none(x):
    return float(x) if x is not None and math.isfinite(x) else None
