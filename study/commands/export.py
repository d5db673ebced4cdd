"""``study export``: a calibration's constants written into the shaders again."""

from __future__ import annotations

from pathlib import Path

from .._progress import log as _log
from ..export.shaders import export_shaders, export_user_shader, load_constants_json, user_shader_of


def run_export(constants_json, out, targets=None) -> list:
    """``study export``: the shipped shaders with the constants of a JSON file, in
    ``out/shaders`` (a user's shader's ``constants.json``: its file with them); ``targets``:
    engine targets, a comma-separated string or list, 'none', or None (every one the installed
    tools can make)."""
    if isinstance(targets, str):
        targets = [] if targets == "none" else [t for t in targets.split(",") if t]
    constants = load_constants_json(constants_json)
    out = Path(out)
    user = user_shader_of(constants_json)
    if user is None:
        paths = export_shaders(constants, out / "shaders", targets=targets)
    else:
        paths = export_user_shader(user, constants, out / "shaders", targets=targets)
    made = sorted(p.name for p in (out / "shaders").iterdir() if p.is_dir())
    _log(
        f"export: wrote {len(paths)} files to {out / 'shaders'} ({', '.join(made)}; GLSL compiled "
        "with glslangValidator, targets checked as listed in targets.json)"
    )
    return paths
