"""Golden reference renders: the scenes, their per-scene thresholds, and the code that
regenerates them (``python tests/golden/reference_scenes.py``).

Each golden is a 32x32 reference at 64 spp (4 fixed seeds) of a shipped experiment, shrunk.
The renders are deterministic for a given Mitsuba/Dr.Jit/LLVM, but a different CPU vector
width can change the float rounding of a few paths, which then diverge like fresh noise.
The threshold is therefore a fraction of the golden's own measured noise. With the same seeds,
a scene change keeps most paths correlated, so it moves the RMSE by much less than the noise
(measured on `default`: IOR 1.333 -> 1.36 gives 0.56 x noise, sigma_t red 0.25 -> 0.30 gives
0.36 x noise, another seed 1.3 x noise, an unchanged renderer exactly 0). A threshold of 0.1 x
noise catches both changes and tolerates about 0.5 % of pixels diverging by rounding.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent

# scene name -> (experiment file, overrides, RMSE threshold as a fraction of the golden's noise)
SCENES = {
    "default": ("default.toml", {}, 0.1),
    "murky": ("murky.toml", {}, 0.1),
    "clear": ("clear.toml", {}, 0.1),
}
SMALL = {
    "resolution": "[32, 32]",
    "fit.resolution": "[32, 32]",
    "reference.spp": "64",
    "reference.water_mesh": "96",
    "reference.texture_size": "64",
    "reference.texture_spp": "8",
    "waves.normal_map_size": "64",
}


def experiment(name: str):
    from study import load_experiment

    file, overrides, _ = SCENES[name]
    ov = dict(SMALL, **overrides)
    return load_experiment(REPO / "experiments" / file, [f"{k}={v}" for k, v in ov.items()])


def golden_path(name: str) -> Path:
    return HERE / f"reference_{name}.exr"


def render(name: str):
    from study.scene.reference import render_reference

    return render_reference(experiment(name), "llvm_ad_rgb")


def main() -> None:
    from study import init_backend, write_exr

    init_backend("llvm_ad_rgb")
    for name in SCENES:
        ref = render(name)
        prov = {k: ref.provenance[k] for k in ("spp", "noise", "scene_hash", "versions", "n_seeds")}
        write_exr(golden_path(name), ref.image, prov)
        print(f"{name}: wrote {golden_path(name)} (noise {ref.noise:.3e})")


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    main()
