"""What the fitted constants assume ships with them: the Fresnel LUT and the normal map they were
fitted with, written beside the exported shaders as float images, with what an engine must know
to upload them.

The constants hold only with these two textures. The LUT's transmission channel is the
experiment's choice (``reference.fresnel_transmission``): ``energy`` is the usual ``T = 1 - R``;
``radiance`` is ``(1 - R) / n^2``, the law of radiance crossing into Snell's window, which the
shader's ``vRefraction * FresnelCoeffs.r`` otherwise leaves out. Constants fitted with the
radiance LUT and shipped with an engine's usual one show the water ``n^2`` (1.78 for water) times
too bright through the surface. Both textures are written as float32 OpenEXR, exactly the values
the fit and the GL check used (no 8-bit quantisation), and the GL check reads them back from
these files (:func:`with_exported_textures`).

``shaders/textures/``: ``fresnel_lut.exr`` (1 x N: R transmission, G reflection, B 0),
``normal_map.exr`` (S x S: ``0.5 n + 0.5``, +y up in world space before the shader's own
swizzle), ``textures.json`` (the record of :func:`texture_record`).
"""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np

from .._io import read_exr, write_exr

__all__ = [
    "FOLDER",
    "copy_textures",
    "expects_lines",
    "lut_image",
    "read_texture_record",
    "texture_record",
    "with_exported_textures",
    "write_textures",
]

#: the textures' folder inside an export's ``shaders/``
FOLDER = "textures"


def texture_record(exp, inputs) -> dict:
    """What the constants assume of the two textures (JSON-able): the LUT's law, index of
    refraction, size, layout and sampling; the normal map's encoding, size, tiling and
    sampling."""
    ior = float(exp.water.ior)
    radiance = exp.reference.fresnel_transmission == "radiance"
    return {
        "fresnel_lut": {
            "file": "fresnel_lut.exr",
            "law": "radiance" if radiance else "energy",
            "transmission": "(1 - R) / n^2" if radiance else "1 - R",
            "ior": ior,
            "size": int(len(inputs.fresnel_lut)),
            "layout": "N x 1 texels; R = transmission, G = reflection (B unused), linear floats",
            "index": "s = cos(theta) between the normal and the view ray; texel i at (i + 0.5) / N",
            "sampling": "nearest, clamp to edge",
            "too_bright_with_usual_lut": ior**2 if radiance else 1.0,
        },
        "normal_map": {
            "file": "normal_map.exr",
            "encoding": "0.5 * n + 0.5 per channel (linear floats, not sRGB)",
            "size": int(inputs.normal_map.shape[0]),
            "tile": float(exp.waves.normal_tile),
            "sampling": "bilinear, repeat; row 0 of the file is t = 0 (upload in file order)",
            "layers": "sampled four times at vTexCoord0..3 = (x, z) / tile + wave1..4",
        },
        "colour_space": "linear RGB",
    }


def lut_image(fresnel_lut: np.ndarray) -> np.ndarray:
    """The (N, 2) LUT [transmission, reflection] as the (1, N, 3) float32 image an engine uploads:
    R transmission, G reflection, B 0."""
    img = np.zeros((1, len(fresnel_lut), 3), np.float32)
    img[0, :, :2] = fresnel_lut
    return img


def write_textures(record: dict, inputs, shaders_dir: Path) -> Path:
    """``shaders_dir/textures/``: the LUT and the normal map of ``inputs`` as float32 EXR and
    ``textures.json`` (``record``). Returns the folder."""
    folder = Path(shaders_dir) / FOLDER
    folder.mkdir(parents=True, exist_ok=True)
    lut = lut_image(inputs.fresnel_lut)
    write_exr(folder / record["fresnel_lut"]["file"], lut, {"texture": record["fresnel_lut"]})
    write_exr(
        folder / record["normal_map"]["file"], inputs.normal_map, {"texture": record["normal_map"]}
    )
    (folder / "textures.json").write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    return folder


def read_texture_record(shaders_dir: Path) -> dict | None:
    """The ``textures.json`` of an export, or None when it has none (an export written before
    the textures were)."""
    path = Path(shaders_dir) / FOLDER / "textures.json"
    return json.loads(path.read_text(encoding="utf-8")) if path.is_file() else None


def with_exported_textures(inputs, shaders_dir: Path):
    """``inputs`` (``ShaderInputs``) with the LUT and the normal map read back from the export's
    files: what the GL check runs, so that it checks the textures that ship."""
    folder = Path(shaders_dir) / FOLDER
    lut, _, _ = read_exr(folder / "fresnel_lut.exr")
    normals, _, _ = read_exr(folder / "normal_map.exr")
    return dataclasses.replace(
        inputs, fresnel_lut=np.ascontiguousarray(lut[0, :, :2]), normal_map=normals
    )


def copy_textures(src_shaders: Path, dst_shaders: Path) -> bool:
    """Copy the textures of one export into another (``study export`` of a calibration's
    ``constants.json``); False when the source has none."""
    src = Path(src_shaders) / FOLDER
    if not (src / "textures.json").is_file():
        return False
    shutil.copytree(src, Path(dst_shaders) / FOLDER, dirs_exist_ok=True)
    return True


def expects_lines(record: dict | None) -> list[str]:
    """The "What this shader expects" section of a binding sheet and of the report."""
    if not record:
        return []
    lut, nm = record["fresnel_lut"], record["normal_map"]
    law = (
        f"transmission {lut['transmission']} with n = {lut['ior']:g} (the radiance law): an "
        "engine's usual LUT (T = 1 - R) makes the water "
        f"{lut['too_bright_with_usual_lut']:.2f}x too bright through the surface"
        if lut["law"] == "radiance"
        else f"transmission {lut['transmission']} with n = {lut['ior']:g} (the usual LUT)"
    )
    return [
        "## What this shader expects",
        "",
        "The fitted constants hold only with the two textures they were fitted with, shipped in "
        "`shaders/textures/` as float32 OpenEXR (upload them as float textures):",
        "",
        f"* `fresnelLookup` = `{lut['file']}`: {lut['layout']}; {law}; indexed by "
        f"{lut['index']}; {lut['sampling']}.",
        f"* `normalMap` = `{nm['file']}` ({nm['size']} x {nm['size']}): {nm['encoding']}; "
        f"{nm['sampling']}; {nm['layers']} (tile {nm['tile']:g}).",
        f"* Every colour is {record['colour_space']}; world units, +y up, the water plane at "
        "y = 0.",
        "",
    ]
