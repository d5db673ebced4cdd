"""Constants for the game's resolution: FLIP at 1920 x 1080 of the constants fitted at several
fit resolutions, each with one sample per fit pixel and with the 1080p pixel footprint
(``fit.target_resolution = "1080p"``: ``study.config.resolution.supersample_factor`` samples
per side of a fit pixel).

    .venv/bin/python benchmarks/bench_resolution_transfer.py [EXPERIMENT.toml ...]
        [--spp N] [--set KEY=VALUE ...] [--out docs/results/resolution-transfer]

Per experiment (default: experiments/default.toml): the reference path traced once at 1080p
with ``--spp`` samples a pixel (cached; its measured noise recorded, the floor under every
FLIP below), then one fit per row of :data:`FITS` from the experiment's start constants, and
the fitted constants scored at 1080p on the water pixels (FLIP and RMSE, as ``study
calibrate`` scores). Writes ``<out>/<experiment>.json`` (atomic), which
``scripts/build_docs.py`` turns into the table of docs/results/resolution-transfer/.
Run alone: the fit seconds are wall times on this machine.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

TARGET = (1920, 1080)
# (fit resolution, the game's resolution its pixels stand for: None for one sample a pixel)
FITS = [
    ((128, 72), None),
    ((128, 72), TARGET),
    ((240, 135), None),
    ((240, 135), TARGET),
    ((480, 270), None),
    ((960, 540), None),
]


def transfer(path: str, spp: int, overrides: list[str]) -> dict:
    """The rows of one experiment (module docstring)."""
    from study import init_backend
    from study.calibration.fitting import FitOptions, fit_frames
    from study.calibration.frames import load_frames
    from study.calibration.scoring import Scorer
    from study.calibration.shader import Shader
    from study.fit.model import get_value

    init_backend("llvm_ad_rgb")
    sets = ['resolution="1080p"', "fit.resolution=[128, 72]", f"reference.spp={spp}", *overrides]
    frames = load_frames(path, sets)
    exp = frames.first.exp
    shader = Shader.of(exp)
    scorer = Scorer(shader, frames, frames.variant)
    start = scorer.model(0).start_constants(exp)
    s0 = scorer(0, start)
    rows = []
    for res, target in FITS:
        options = FitOptions.of(exp, resolution=res, target_resolution=target)
        t0 = time.perf_counter()
        fit = fit_frames(frames, shader, frames.variant, options)
        seconds = time.perf_counter() - t0
        cal = fit.calibration
        score = scorer(0, cal.fitted)
        names = list(cal.parameters)  # scalar names: 'water_color[1]'
        rows.append(
            {
                "fit_resolution": list(res),
                "target_resolution": None if target is None else list(target),
                "supersample": options.supersample(exp),
                "fit_seconds": round(seconds, 2),
                "iterations": cal.fit_summary.get("iterations"),
                "flip_1080p": score.flip,
                "rmse_1080p": score.rmse,
                "constants": {n: float(get_value(cal.fitted, n)) for n in names},
                "status": {n: p["status"] for n, p in cal.parameters.items()},
                "errors": _errors(cal.identifiability.get("solution", {})),
            }
        )
        print(
            f"{exp.name}: fit {res[0]}x{res[1]} x{rows[-1]['supersample']}: FLIP@1080p "
            f"{score.flip:.4f} ({seconds:.0f} s)",
            file=sys.stderr,
        )
    return {
        "experiment": Path(path).name,
        "shader": shader.label,
        "scored_at": list(TARGET),
        "reference": {"spp": spp, "noise": float(frames.first.ref.noise)},
        "start": {"flip_1080p": s0.flip, "rmse_1080p": s0.rmse},
        "rows": rows,
        "machine": f"{platform.machine()}, {__import__('os').cpu_count()} cores",
        "command": "benchmarks/bench_resolution_transfer.py "
        + " ".join([Path(path).as_posix(), f"--spp {spp}", *[f"--set {o}" for o in overrides]]),
    }


def _errors(sol: dict) -> dict:
    """constant -> its relative standard errors at the solution: Gauss-Newton (``gauss_newton``)
    and over image tiles (``tiles``, ``study.fit.rounds.tile_errors``)."""
    keys = (("gauss_newton", "rel_std_error"), ("tiles", "rel_tile_error"))
    return {
        n: {k: (sol.get(key) or [None] * len(sol["names"]))[i] for k, key in keys}
        for i, n in enumerate(sol.get("names", []))
    }


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("experiments", nargs="*", default=["experiments/default.toml"])
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    ap.add_argument("--out", default=str(REPO / "docs" / "results" / "resolution-transfer"))
    args = ap.parse_args()
    from study._io import write_text_atomic

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for path in args.experiments:
        result = transfer(path, args.spp, args.overrides)
        name = Path(path).stem
        write_text_atomic(out / f"{name}.json", json.dumps(result, indent=1) + "\n")
        print(f"wrote {out / f'{name}.json'}", file=sys.stderr)


if __name__ == "__main__":
    main()
