"""Does the calibration stop when it is done? Shipped experiments and new scenes, side by side.

For each scene, ``study calibrate``'s fit (``calibrate_model``: identifiability, the default
solver with its loss-stall rule, KKT bounds, standard-error rounds) and a table of: solver
steps to stop, steps to reach 0.1 % of the final loss (``steps_to_0.1pct``), their ratio (the
target: <= 2), the fit rounds (a constant frozen for its standard error triggers a refit),
and every constant's status (``fitted``, ``bound``, ``frozen``) with its relative standard
error. Renders are small by default (``--small``: 128x128 references at 64 spp, 64-spp
top-down texture, fit at 64x64) and cached under ``$STUDY_CACHE``; ``--full`` uses each
experiment as shipped (1024-spp references, fit at 128x128).

    .venv/bin/python benchmarks/bench_stop.py            # shipped + new scenes, small renders
    .venv/bin/python benchmarks/bench_stop.py --only steps teal
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

SMALL = [
    "resolution=[128,128]",
    "fit.resolution=[64,64]",
    "reference.spp=64",
    "reference.texture_spp=64",
]
# new scenes a user would try first, on top of the default experiment with the specular pair
# fitted (the default fit.parameters already list it)
NEW = {
    "steps": ['floor.shape="steps"', "sun.elevation=70"],
    "teal": [
        'floor.shape="terrain"',
        "floor.depth=3.0",
        "water.sigma_t=[0.9,0.12,0.18]",
        "camera.position=[0.0,1.2,7.5]",
        "camera.target=[0.0,-0.6,0.0]",
    ],
    "shallow": [
        'floor.shape="flat"',
        "floor.depth=0.4",
        "camera.position=[0.0,9.0,1.5]",
        "camera.target=[0.0,-0.4,0.0]",
    ],
}
SHIPPED = ["default", "calm", "clear", "grazing", "murky", "seed_lut"]


def run_one(path: Path, overrides: list[str]) -> dict:
    from study import init_backend, load_experiment
    from study.calibration.frames import load_scene_data
    from study.fit.calibrate import calibrate_experiment
    from study.fit.model import ShaderModel

    variant = init_backend("llvm_ad_rgb")
    exp = load_experiment(path, overrides)
    ref, inputs, _ = load_scene_data(exp, variant)
    model = ShaderModel.from_experiment(exp, inputs, ref.image)
    t0 = time.perf_counter()
    cal = calibrate_experiment(model, exp)
    fs = cal.fit_summary
    return {
        "seconds": time.perf_counter() - t0,
        "iterations": fs.get("iterations", 0),
        "to_0.1pct": fs.get("steps_to_0.1pct_per_round", []),
        "rounds": fs.get("rounds", 0),
        "per_round": fs.get("iterations_per_round", []),
        "converged": fs.get("converged"),
        "params": cal.parameters,
        "message": fs.get("message", ""),
    }


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--full", action="store_true", help="experiments as shipped (slow first run)")
    ap.add_argument("--only", nargs="*", default=None, help="scene names to run (default: all)")
    args = ap.parse_args()
    base = [] if args.full else SMALL
    scenes = [(n, REPO / "experiments" / f"{n}.toml", base) for n in SHIPPED]
    scenes += [(n, REPO / "experiments" / "default.toml", base + o) for n, o in NEW.items()]
    if args.only:
        scenes = [s for s in scenes if s[0] in args.only]
    rows = []
    for name, path, ov in scenes:
        print(f"[{name}] ...", file=sys.stderr, flush=True)
        rows.append((name, run_one(path, ov)))
    print(
        "\nper fit round; round 1 starts cold from the experiment's constants, a "
        "later round (a constant\n"
        "frozen for its standard error) warm from the previous solution and stops "
        "after the 3-step stall\n"
        "window, so it takes >= 4 steps even when it starts within 0.1 % of its final loss"
    )
    print(
        "| scene | steps to stop | steps to 0.1 % of final loss | round-1 ratio (<= 2) | seconds |"
        " statuses (rel. std. error) |"
    )
    print("|---|---|---|---|---|---|")
    for name, r in rows:
        ratio = (
            r["per_round"][0] / r["to_0.1pct"][0]
            if r["to_0.1pct"] and r["to_0.1pct"][0]
            else float("nan")
        )
        st = ", ".join(
            f"{n}: {p['status']}"
            + (f" ({p['rel_std_error']:.2g})" if p.get("rel_std_error") else "")
            for n, p in r["params"].items()
        )
        print(
            f"| {name} | {r['per_round']} | {r['to_0.1pct']} | {ratio:.2f} | "
            f"{r['seconds']:.1f} | {st} |"
        )


if __name__ == "__main__":
    main()
