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
swizzle), ``textures.json`` (the record of :func:`texture_record`); for a shader of the space
with ``normals = "lean"`` also ``slope_moments.exr`` (S x S RGBA: the normal map's slopes and
their squares, ``shaders_port.pipeline.normal_maps``; mipmapped, sampled trilinearly), with
``parallax = "offset"`` ``height_map.exr`` (S x S, R: the normal map's wave heights in tile
lengths; bilinear, repeat).

A user's shader may read more textures the engine uploads (``shaders_port.spirv.
engine_inputs``, :func:`shader_textures`): each is written beside them, exactly the texels the
executor and the GL check bound, with its sampler state in the record and the shader's names
of it: ``dudv_map.exr`` (the DuDv map of the study's normal map), ``waves_normal_map.exr``
(the study's waves as a tangent-space normal map), ``user_normal_map.exr``
(the declaration's ``normal_map`` image as the shader read it, RGB / 255 or / 65535),
``sky_cube_{px,nx,py,ny,pz,nz}.exr`` (the sky as engines hold a cube map) and
``reflection_cube_*.exr`` (the study's ``reflectionTexture``, the sky at ``d * (1, -1, 1)``),
a cube map's faces in GL order with the face and axis table of ``docs/engine-inputs.md``. The
screen-space and top-down renders a shader reads (:data:`RENDERED`) are the engine's own render
targets: the record and the binding sheet name them, nothing is written.
"""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
from pathlib import Path

import numpy as np

from shaders_port.pipeline.normal_maps import height_map, slope_moments
from shaders_port.spirv.engine_inputs import (
    dudv_map,
    read_normal_map,
    sky_cube,
    waves_normal_map,
)

from .._io import read_exr, write_exr
from ..scene.topdown import NO_GEOMETRY, texture_extent

__all__ = [
    "FOLDER",
    "copy_textures",
    "expects_lines",
    "lut_image",
    "read_texture_record",
    "shader_textures",
    "texture_record",
    "with_exported_textures",
    "write_textures",
]

#: the textures' folder inside an export's ``shaders/``
FOLDER = "textures"


# a cube map's faces in GL order, as file-name suffixes
FACES = ("px", "nx", "py", "ny", "pz", "nz")
# texture inputs a user's shader may read that ship as files: input -> (file stem, encoding,
# filter, wrap, mipmaps)
SHIPPED = {
    "dudv_map": ("dudv_map", "RG = 0.5 + 0.5 (-dh/dx, -dh/dz) of the study's normal map "
                 "(0.5: no distortion), B = 0; linear floats", "linear", "repeat", False),
    "user_normal_map": ("user_normal_map", "the declaration's normal_map image as the shader "
                        "read it: RGB as stored / 255 (16-bit: / 65535), no sRGB decoding",
                        "linear", "repeat", True),
    "waves_normal_map": ("waves_normal_map", "the study's waves as a tangent-space normal map: "
                         "RGB = 0.5 + 0.5 (n_x, n_z, n_y) of the world normal (x along u, y "
                         "along v, z up); linear floats", "linear", "repeat", True),
    "sky_cube": ("sky_cube", "the sky as engines hold a cube map: the texel of direction d "
                 "holds the sky in d; linear RGB", "linear", "clamp", False),
    "reflectionTexture": ("reflection_cube", "the study's sky cube map: the texel of direction "
                          "d holds the sky in d * (1, -1, 1); linear RGB", "linear", "clamp",
                          False),
}  # fmt: skip
# the maps a shader of the space derives from the normal map (shaders_port.pipeline.
# normal_maps): record key (and file stem) -> (sampler, encoding, sampling, mipmaps, the
# (H, W, C) texels written of the normal map)
DERIVED = {
    "slope_moments": ("slopeMoments", "RGBA = (sx, sz, sx^2, sz^2): the slopes -n.xz / max(n.y, "
                      "0.05) of normal_map.exr's decoded normals and their squares; linear "
                      "floats", "trilinear (GL_LINEAR_MIPMAP_LINEAR, the implicit level of "
                      "detail), repeat; the levels box-filtered halvings down to 1 x 1 "
                      "(glGenerateMipmap)", True, slope_moments),
    "height_map": ("heightMap", "R = the height of the waves whose slopes normal_map.exr holds, "
                   "in tile lengths (world units / tile), mean 0; G = B = 0; linear floats",
                   "bilinear, repeat; row 0 of the file is t = 0 (upload in file order)", False,
                   lambda nm: np.pad(height_map(nm)[..., None], ((0, 0), (0, 0), (0, 2)))),
}  # fmt: skip
#: texture inputs the engine renders itself (never shipped): input -> what to render
RENDERED = {
    "sceneColor": "the scene without the water, this camera (screen space, a render target)",
    "sceneDepth": "the depth buffer of that view, window depth in [0, 1] (a render target)",
    "reflection_sampler": "the scene above the water seen by the camera mirrored in the water "
    "plane (a render target)",
    "refractionTexture": "the ground under the water seen from straight above (a top-down "
    "render of the engine's scene)",
    "worldYComponent": "the world height of that ground (a top-down render, R32F)",
    "worldYComponentReflection": "the world height of the geometry above the water seen from "
    "below (a top-down render, R32F)",
    "reflectionBottom": "that geometry's colour seen from below (a top-down render)",
}


def shader_textures(shader) -> dict:
    """Texture input -> the sampler names of the user's shader ``shader`` (``UserShader``)
    reading it, of the inputs of :data:`SHIPPED` and :data:`RENDERED`: by its own name in the
    code (comments left out), through the declaration or an engine's name
    (``UserShader.run_bindings``)."""
    code = re.sub(r"//[^\n]*|/\*.*?\*/", "", shader.source, flags=re.S)
    out: dict[str, list] = {}
    for name, inp in shader.run_bindings().items():
        if inp in SHIPPED or inp in RENDERED:
            out.setdefault(inp, []).append(name)
    for inp in (*SHIPPED, *RENDERED):
        if re.search(rf"\b{inp}\b", code) and inp not in out.get(inp, []):
            out.setdefault(inp, []).append(inp)
    return out


def _shipped_record(inp: str, names: list, inputs, shader) -> dict:
    """The record of the shipped texture ``inp`` the shader reads as ``names``."""
    stem, encoding, filt, wrap, mips = SHIPPED[inp]
    rec = {"bound_as": names, "encoding": encoding, "filter": filt, "wrap": wrap,
           "mipmaps": mips}  # fmt: skip
    if inp in ("sky_cube", "reflectionTexture"):
        f = int(inputs.cubemap.shape[1])
        layout = ("six faces in GL order +X, -X, +Y, -Y, +Z, -Z (world axes, +y up), each in "
                  "GL upload order (face and axis table: docs/engine-inputs.md), filtered per "
                  "face (GL_TEXTURE_CUBE_MAP_SEAMLESS off)")  # fmt: skip
        rec.update(files=[f"{stem}_{k}.exr" for k in FACES], size=[f, f], layout=layout)
        return rec
    a = _shipped_texels(inp, inputs, shader.engine["normal_map"])
    rec.update(file=f"{stem}.exr", size=[int(a.shape[1]), int(a.shape[0])])
    if inp == "user_normal_map":
        rec["source"] = Path(shader.engine["normal_map"]).name
    return rec


def _shipped_texels(inp: str, inputs, normal_map=None) -> np.ndarray:
    """The texels of the shipped texture ``inp`` as the executor and the GL check bind them:
    (H, W, 3) float32 in GL upload order, a cube map (6, F, F, 3)."""
    if inp == "dudv_map":
        return dudv_map(inputs.normal_map)
    if inp == "waves_normal_map":
        return waves_normal_map(inputs.normal_map)
    if inp == "user_normal_map":
        return read_normal_map(normal_map)
    if inp == "sky_cube":
        return sky_cube(inputs.cubemap).astype(np.float32)
    return np.asarray(inputs.cubemap, np.float32)  # reflectionTexture


def texture_record(exp, inputs, shader=None, lean: bool = False, heights: bool = False) -> dict:
    """What the constants assume of the textures (JSON-able): the LUT's law, index of
    refraction, size, layout and sampling; the normal map's encoding, size, tiling and
    sampling; for a user's shader ``shader`` (``UserShader``), every other texture it reads
    (:func:`shader_textures`): a shipped one's files, encoding, size, filter, wrap, mipmaps
    and the shader's names of it (``bound_as``), under ``shipped``; the engine's render
    targets it reads under ``rendered`` (input -> ``{"bound_as", "what"}``); ``lean``: the
    shader reads ``slopeMoments`` (``LEAN_NORMALS``), recorded under ``slope_moments``;
    ``heights``: it reads ``heightMap`` (``PARALLAX_OFFSET``), recorded under ``height_map``."""
    record = _study_record(exp, inputs)
    for key in (("slope_moments",) if lean else ()) + (("height_map",) if heights else ()):
        sampler, encoding, sampling, mipmaps, _ = DERIVED[key]
        record[key] = {"file": f"{key}.exr", "bound_as": [sampler], "encoding": encoding,
                       "size": int(inputs.normal_map.shape[0]), "sampling": sampling,
                       "filter": "linear", "wrap": "repeat", "mipmaps": mipmaps}  # fmt: skip
    if shader is not None:
        reads = shader_textures(shader)
        record["shipped"] = {i: _shipped_record(i, n, inputs, shader)
                             for i, n in reads.items() if i in SHIPPED}  # fmt: skip
        record["rendered"] = {i: {"bound_as": n, "what": RENDERED[i]}
                              for i, n in reads.items() if i in RENDERED}  # fmt: skip
    return record


def scene_record(exp, inputs) -> dict:
    """The values the fit used that an engine sets, as the short binding sheet gives them:
    the light (``lightpos`` world units, ``lightcolor`` linear RGB, the sun's radiance over its
    largest channel, which ``SPECULAR_STRENGTH`` multiplies), the waves (offsets of the four
    normal-map layers at t = 0, texture units, and their velocities, per second), the top-down
    camera (its world rectangle, texture size and ``uTextureMatrix0``, rows)."""
    x0, z0, x1, z1 = (float(v) for v in texture_extent(exp))
    return {
        "lightpos": [float(v) for v in inputs.lightpos],
        "lightcolor": [float(v) for v in inputs.lightcolor],
        "wave_offsets": np.asarray(inputs.waves, float).tolist(),
        "wave_velocities": np.asarray(exp.animation.velocities, float).tolist(),
        "top_down": {
            "extent": [x0, z0, x1, z1],
            "size": int(inputs.world_y.shape[0]),
            "no_geometry": NO_GEOMETRY,
            "tex_matrix0": np.asarray(inputs.tex_matrix0, float).tolist(),
        },
    }


def _study_record(exp, inputs) -> dict:
    """The Fresnel LUT's and the normal map's record (:func:`texture_record`), and the values
    an engine sets (:func:`scene_record`)."""
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
            "filter": "nearest",
            "wrap": "clamp",
            "mipmaps": False,
            "too_bright_with_usual_lut": ior**2 if radiance else 1.0,
        },
        "normal_map": {
            "file": "normal_map.exr",
            "encoding": "0.5 * n + 0.5 per channel (linear floats, not sRGB)",
            "size": int(inputs.normal_map.shape[0]),
            "tile": float(exp.waves.normal_tile),
            "sampling": "bilinear, repeat; row 0 of the file is t = 0 (upload in file order)",
            "filter": "linear",
            "wrap": "repeat",
            "mipmaps": False,
            "layers": "sampled four times at vTexCoord0..3 = (x, z) / tile + wave1..4",
        },
        "colour_space": "linear RGB",
        "scene": scene_record(exp, inputs),
    }


def lut_image(fresnel_lut: np.ndarray) -> np.ndarray:
    """The (N, 2) LUT [transmission, reflection] as the (1, N, 3) float32 image an engine uploads:
    R transmission, G reflection, B 0."""
    img = np.zeros((1, len(fresnel_lut), 3), np.float32)
    img[0, :, :2] = fresnel_lut
    return img


def write_textures(record: dict, inputs, shaders_dir: Path, normal_map=None) -> Path:
    """``shaders_dir/textures/``: the LUT and the normal map of ``inputs`` as float32 EXR, the
    record's ``shipped`` textures (``normal_map``: the path of a user's normal-map image) and
    ``textures.json`` (``record``). Returns the folder."""
    folder = Path(shaders_dir) / FOLDER
    folder.mkdir(parents=True, exist_ok=True)
    lut = lut_image(inputs.fresnel_lut)
    write_exr(folder / record["fresnel_lut"]["file"], lut, {"texture": record["fresnel_lut"]})
    write_exr(
        folder / record["normal_map"]["file"], inputs.normal_map, {"texture": record["normal_map"]}
    )
    for key, (*_, texels) in DERIVED.items():
        if key in record:
            rec = record[key]
            write_exr(folder / rec["file"], texels(inputs.normal_map), {"texture": rec})
    for inp, rec in record.get("shipped", {}).items():
        a = _shipped_texels(inp, inputs, normal_map)
        files = rec["files"] if "files" in rec else [rec["file"]]
        for f, texels in zip(files, a if "files" in rec else [a]):
            write_exr(folder / f, texels, {"texture": {**rec, "input": inp}})
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
    which = "textures" if record.get("shipped") else "two textures"
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
        f"The fitted constants hold only with the {which} they were fitted with, shipped in "
        "`shaders/textures/` as float32 OpenEXR (upload them as float textures):",
        "",
        f"* `fresnelLookup` = `{lut['file']}`: {lut['layout']}; {law}; indexed by "
        f"{lut['index']}; {lut['sampling']}.",
        f"* `normalMap` = `{nm['file']}` ({nm['size']} x {nm['size']}): {nm['encoding']}; "
        f"{nm['sampling']}; {nm['layers']} (tile {nm['tile']:g}).",
        *(line for key in DERIVED for line in _derived_lines(record.get(key))),
        *_shipped_lines(record.get("shipped", {})),
        f"* Every colour is {record['colour_space']}; world units, +y up, the water plane at "
        "y = 0.",
        "",
        *_rendered_lines(record.get("rendered", {})),
        *scene_lines(record.get("scene")),
    ]


def _derived_lines(rec: dict | None) -> list[str]:
    """The bullet of a map derived from the normal map (:data:`DERIVED`: ``slopeMoments`` of a
    LEAN shader, ``heightMap`` of a parallax one), or none."""
    if not rec:
        return []
    return [
        f"* `{rec['bound_as'][0]}` = `{rec['file']}` ({rec['size']} x {rec['size']}): "
        f"{rec['encoding']}; {rec['sampling']}; read at the normal map's coordinates."
    ]


def _vec(v) -> str:
    """A vector as (x, y, z), rounding errors below 1e-9 shown as 0."""
    return "(" + ", ".join(f"{0.0 if abs(x) < 1e-9 else x:.6g}" for x in v) + ")"


def scene_lines(scene: dict | None) -> list[str]:
    """The "Values the fit used" part of a binding sheet (:func:`scene_record`'s)."""
    if not scene:
        return []
    td = scene["top_down"]
    x0, z0, x1, z1 = td["extent"]
    waves = "; ".join(
        f"`wave{k + 1}` = {_vec(o)} + t * {_vec(v)}"
        for k, (o, v) in enumerate(zip(scene["wave_offsets"], scene["wave_velocities"]))
    )
    rows = " ".join(_vec(r) for r in td["tex_matrix0"])
    return [
        "### Values the fit used",
        "",
        "Set them as the study did, or from your scene with the same meaning:",
        "",
        f"* `lightpos` = {_vec(scene['lightpos'])} (world units: the sun far away) and "
        f"`lightcolor` = {_vec(scene['lightcolor'])} (linear RGB: the sun's radiance over its "
        "largest channel). `SPECULAR_STRENGTH` multiplies this colour: a colour normalised "
        "otherwise changes the highlight by the ratio.",
        f"* The waves, texture units at time t seconds (offsets of the normal-map layers, "
        f"`wave_i(t) = offset + t * velocity`): {waves}.",
        f"* The top-down renders (`refractionTexture`, `worldYComponent`): an orthographic camera "
        f"straight down over x in [{x0:g}, {x1:g}], z in [{z0:g}, {z1:g}], {td['size']} x "
        f"{td['size']} texels, texel (row, column) = (t, s) with s = (x - ({x0:g})) / "
        f"{x1 - x0:g} and t = (z - ({z0:g})) / {z1 - z0:g}; `worldYComponent` holds world y, "
        f"{td['no_geometry']:g} where nothing is below. `uTextureMatrix0` (rows) = {rows}: the "
        "same map (any top-down camera works if this matrix is its bias * projection * view).",
        "",
    ]


def _names(rec: dict) -> str:
    return " / ".join(f"`{n}`" for n in rec["bound_as"])


def _shipped_lines(shipped: dict) -> list[str]:
    """A line per shipped texture of a user's shader: its names, files, encoding, sampling."""
    lines = []
    for inp, r in shipped.items():
        files = f"`{r['files'][0]}` ... `{r['files'][-1]}`" if "files" in r else f"`{r['file']}`"
        mips = ("mipmapped: build its mip chain (`glGenerateMipmap`), trilinear"
                if r["mipmaps"] else "no mipmaps")  # fmt: skip
        src = f", from `{r['source']}`" if "source" in r else ""
        each = " each" if "files" in r else ""
        lay = f"; {r['layout']}" if "layout" in r else ""
        lines.append(
            f"* {_names(r)} = {files} ({r['size'][0]} x {r['size'][1]}{each}, `{inp}`{src}): "
            f"{r['encoding']}{lay}; {r['filter']}, {r['wrap']}, {mips}."
        )
    return lines


def _rendered_lines(rendered: dict) -> list[str]:
    """The engine's own render targets a user's shader reads: named, never shipped."""
    if not rendered:
        return []
    return [
        "The shader also reads textures the engine renders itself, every frame for its camera "
        "(not shipped: the study rendered its own for the calibration, the viewer gets them as "
        "data):",
        "",
        *[f"* {_names(r)} (`{inp}`): {r['what']}." for inp, r in rendered.items()],
        "",
    ]
