"""How much of the best shader's error is the reference's noise: the default scene's images of
the committed tradeoff study scored against an independent reference of many more samples.

Reads ``docs/results/tradeoff/images_default.exr`` (the study's reference and the panels of
``study tradeoff``: the original shader at its own and at fitted constants, the best within the
original's fetches, the recommendation), renders the experiment's reference again at
``--spp`` samples with another seed (cached like any reference), and prints FLIP and RMSE on the
scored water pixels (the calibration's mask) of each image against the committed reference and
against the new one; the committed reference against the new one is the noise floor: no shader
can score below it against a reference of that many samples.

    STUDY_CACHE=... .venv/bin/python benchmarks/bench_noise_floor.py [--spp 1024] [--seed 7]
        [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()

    from study import init_backend, load_experiment
    from study._io import read_exr
    from study._metrics import errors
    from study.calibration.frames import load_scene_data
    from study.fit.build import build_model
    from study.scene.reference import load_or_render

    variant = init_backend("llvm_ad_rgb")
    folder = REPO / "docs" / "results" / "tradeoff"
    rgb, _, layers = read_exr(folder / "images_default.exr")
    titles = json.loads((folder / "images_default.json").read_text())["panels"]
    exp = load_experiment(REPO / "experiments" / "default.toml")
    ref, inputs, _ = load_scene_data(exp, variant)
    model = build_model(exp, inputs, ref.image, resolution=tuple(exp.resolution))
    mask = model.mask
    over = [
        f"reference.spp={args.spp}",
        f"reference.seed={args.seed}",
        'reference.sampler="independent"',
    ]
    t0 = time.perf_counter()
    many = load_or_render(load_experiment(REPO / "experiments" / "default.toml", over), variant)
    render_s = time.perf_counter() - t0
    images = {"the reference (committed)": rgb}
    images.update({p["title"]: layers[p["layer"]] for p in titles if p["layer"] != "RGB"})
    rows = []
    for name, img in images.items():
        a, b = errors(rgb, img, mask), errors(many.image, img, mask)
        rows.append({"image": name, "vs_committed": a, "vs_many": b})
    print(f"reference of {many.spp} spp (seed {args.seed}, independent sampler): {render_s:.0f} s, "
          f"noise {many.noise:.4f}; the committed one: {ref.spp} spp, noise {ref.noise:.4f}; "
          f"{int(mask.sum())} scored water pixels")  # fmt: skip
    print("| image | FLIP vs committed reference | FLIP vs many-sample reference | "
          "RMSE vs committed | RMSE vs many-sample |")  # fmt: skip
    print("|---|---|---|---|---|")
    for r in rows:
        a, b = r["vs_committed"], r["vs_many"]
        print(f"| {r['image']} | {a['flip']:.4f} | {b['flip']:.4f} | {a['rmse']:.4f} | "
              f"{b['rmse']:.4f} |")  # fmt: skip
    if args.json:
        Path(args.json).write_text(json.dumps({"spp": many.spp, "seed": args.seed,
                                                "rows": rows}, indent=2) + "\n")  # fmt: skip


if __name__ == "__main__":
    main()
