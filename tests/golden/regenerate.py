"""Golden images of the Dr.Jit water-shader ports (LLVM backend) on tests/synthetic.py inputs.

``python tests/golden/regenerate.py`` rewrites every ``<scene>.exr`` in this folder (RGB,
float32 linear, 48 x 64, row 0 at the top). Regenerate only after a deliberate change of the
shader arithmetic, and say why in the commit. ``SCENES`` and the per-scene thresholds are
used by tests/test_water_refraction.py and tests/test_water_reflection.py.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import numpy as np
import OpenEXR

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
for p in (str(ROOT), str(HERE.parent)):
    if p not in sys.path:
        sys.path.insert(0, p)

from shaders_port import Constants  # noqa: E402

WIDTH, HEIGHT = 64, 48

CUSTOM = Constants(
    attenuation_distance=2.0,
    steps_grazing=14.0,
    steps_steep=2.0,
    loop_cap=6,
    bumptex_mult=0.4,
    refr_coeff=0.7,
    water_color=(0.1, 0.3, 0.2, 1.0),
    reflect_color=(0.9, 0.8, 1.0, 1.0),
    specular_strength=3.0,
    specular_exponent=64.0,
    refl_steps_steep=0.7,
    refl_steps_grazing=6.0,
    refl_loop_cap=20,
    refl_height_cut=0.5,
)

# scene -> (shader, reflection flag, constants, max |diff| threshold, mean |diff| threshold)
# Thresholds: float32 rounding of a different CPU / LLVM version moves colours by ~1e-6;
# a crossing step that flips on a tie moves one pixel by up to the floor's contrast, so the
# max threshold allows no such flip and the mean threshold bounds the total drift.
SCENES = {
    "water_refraction_default": ("water_refraction", True, Constants(), 1e-4, 1e-6),
    "water_refraction_norefl_custom": ("water_refraction", False, CUSTOM, 1e-4, 1e-6),
    "water_reflection_default": ("water_reflection", True, Constants(), 1e-4, 1e-6),
    "water_reflection_custom": ("water_reflection", True, CUSTOM, 1e-4, 1e-6),
}


def render_scene(scene: str) -> np.ndarray:
    """(HEIGHT, WIDTH, 3) float32 colour of ``scene`` rendered by the port."""
    from helpers.synthetic import synthetic_inputs
    from shaders_port.ports import water_reflection, water_refraction

    shader, reflection, constants, _, _ = SCENES[scene]
    inputs = synthetic_inputs(WIDTH, HEIGHT)
    if shader == "water_refraction":
        out = water_refraction.render(
            inputs, constants, defines=() if reflection else ("NOREFLECTION",)
        )
    else:
        out = water_reflection.render(inputs, constants)
    return np.asarray(out.color.numpy(), dtype=np.float32)


def write_exr(path, rgb: np.ndarray) -> None:
    """Write (H, W, 3) float32 RGB to ``path`` atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".exr.tmp")
    os.close(fd)
    try:
        OpenEXR.File(header, {"RGB": np.ascontiguousarray(rgb, dtype=np.float32)}).write(tmp)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def read_exr(path) -> np.ndarray:
    """(H, W, 3) float32 RGB of an EXR written by :func:`write_exr`."""
    with OpenEXR.File(str(path)) as f:
        return np.array(f.channels()["RGB"].pixels, dtype=np.float32)


def main() -> None:
    for scene in SCENES:
        write_exr(HERE / f"{scene}.exr", render_scene(scene))
        print(f"wrote {HERE / (scene + '.exr')}")


if __name__ == "__main__":
    main()
