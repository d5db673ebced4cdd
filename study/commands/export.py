"""``study export``: a calibration's or a tradeoff's constants written into their shader again,
with the textures they assume."""

from __future__ import annotations

from pathlib import Path

from .._progress import log as _log
from ..calibration.shader import Shader
from ..export.shaders import read_calibration
from ..export.textures import copy_textures, read_texture_record


def run_export(constants_json, out, targets=None, shaders=None) -> list:
    """``study export``: the constants of a JSON file written into their shader, in
    ``out/shaders`` (a user's shader's ``constants.json``: its file with them), with the textures
    the constants assume (``shaders/textures/`` beside the JSON, or ``textures/`` with it, when
    the calibration or tradeoff wrote them). ``shaders``: the shaders of the space to write, a
    comma-separated string or list (default: the one the JSON says the constants were fitted
    for, else every shipped one); ``targets``: engine targets, a comma-separated string or list,
    'none', or None (every one the installed tools can make)."""
    if isinstance(targets, str):
        targets = [] if targets == "none" else [t for t in targets.split(",") if t]
    saved = read_calibration(constants_json)
    out = Path(out)
    src = Path(constants_json).parent / "shaders"  # a calibration's own export
    if read_texture_record(src) is None:
        src = Path(constants_json).parent  # an export folder with the JSON inside
    record = read_texture_record(src)
    textures = None
    if record is None and "parameters" in saved.data:  # a calibration's, written before them
        _log(
            f"export: no textures beside {constants_json} (shaders/textures/): the Fresnel LUT "
            "and normal map the constants assume are not exported; calibrate again to get them"
        )
    elif record is not None:
        textures = (record, lambda folder: copy_textures(src, folder))
    shader = Shader.of_saved(saved)
    folder = out / "shaders"
    names = _shaders(saved.data, shaders)
    shader.export(saved.constants, folder, textures, saved.status, targets, names)
    paths = sorted(p for p in folder.rglob("*") if p.is_file())
    made = sorted(p.name for p in folder.iterdir() if p.is_dir())
    _log(
        f"export: wrote {len(paths)} files to {folder} ({', '.join(made)}; GLSL compiled "
        "with glslangValidator, targets checked as listed in targets.json)"
    )
    return paths


def _shaders(data: dict, shaders) -> list[str] | None:
    """The shaders to export: those named (``shaders``), else the one the JSON object ``data``
    says the constants were fitted for (``shader``), else None (every shipped one)."""
    if isinstance(shaders, str):
        shaders = [n for n in shaders.split(",") if n]
    if shaders:
        return list(shaders)
    fitted = data.get("shader")
    return [fitted] if isinstance(fitted, str) and fitted else None
