"""Export fitted constants into the shipped GLSL (both dialects), compile-checked.

Only the tunable-constants block of each fragment shader changes
(``shaders_port.write_constants``); the vertex shader is copied as shipped. Every written
shader is compiled with ``glslangValidator`` before anything reaches the output folder, and
the new folder is written beside the old one and swapped in by two renames, so a failed
export leaves no half-written shaders and the previous export in place.

Every variant named otherwise than its shader file (e.g. ``water_refraction_beer``, compiled
with ``#define BEER_ATTENUATION``) also gets a file of its own name, ``<variant>.frag``: the
shader file with the constants and the variant's ``#define`` lines right after ``#version``, so
that file alone reproduces the variant (``study.export.gl_check`` runs exactly it; a variant
with ``textures = 'game'`` needs the application to upload its textures at that precision).

``targets`` adds the engine targets of ``study.export.targets`` (GLSL ES 3.00, HLSL, Metal,
SPIR-V, each with its binding sheet), translated from the core files and checked in the same
temporary folder, so they too are written all or not at all.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

from shaders_port import CONSTANT_SPECS, Constants
from shaders_port.glsl_text import compile_check, read_source, write_constants
from shaders_port.variants import SHIPPED, VARIANTS, get_variant

from .._io import disk_full
from .targets import resolve_targets, translate_targets

# every fragment shader file a registered variant uses, in registration order
FRAGMENT_SHADERS = tuple(dict.fromkeys(VARIANTS[n].shader for n in SHIPPED))


def load_constants_json(path) -> Constants:
    """Constants from ``constants.json`` of ``study calibrate`` (its ``constants`` table) or from a
    flat JSON object ``{name: value}`` with names of ``CONSTANT_SPECS``."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"constants file {path} does not exist")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path} is not valid JSON ({exc})") from exc
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a JSON object of constants, got {type(data).__name__}")
    table = data.get("constants", data)
    if not isinstance(table, dict):
        raise ValueError(f"{path}: 'constants' must be an object of name -> value")
    unknown = sorted(set(table) - set(CONSTANT_SPECS))
    if unknown:
        names = ", ".join(repr(u) if len(u) <= 80 else repr(u[:80]) + "..." for u in unknown[:5])
        more = f" and {len(unknown) - 5} more" if len(unknown) > 5 else ""
        raise ValueError(
            f"{path}: unknown constant(s) {names}{more}; known: {sorted(CONSTANT_SPECS)}"
        )
    try:
        return Constants.from_dict(table)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: {exc}") from exc


def export_shaders(constants: Constants, out_dir, shaders=None, targets=()) -> list[Path]:
    """Write ``out_dir/{compat,core}/water.vert`` and the fragment shaders of the shaders named
    in ``shaders`` (any of the shader space; default: every shipped one --
    ``water_refraction.frag``, ``water_reflection.frag``, ...) with ``constants``; return the
    written paths. Constants
    are fitted for one shader, so a calibration exports that shader alone. ``targets``: engine
    targets to add (``study.export.targets.TARGETS``; None: every one the installed tools can
    make). Raises ValueError on bad constants or an unknown name and RuntimeError if a shader
    does not compile or translate (nothing is written then)."""
    constants.validate()
    names = list(SHIPPED) if shaders is None else list(shaders)
    if not names:
        raise ValueError("export: no shader named; name one of the space's shaders")
    for n in names:
        get_variant(n)  # a shader of the space is registered on first use; else a ValueError
    texts = {}
    for dialect in ("compat", "core"):
        texts[(dialect, "water.vert")] = read_source("water", "vert", dialect)
        bases = {}
        for name in names:
            v = VARIANTS[name]
            if v.shader not in bases:
                bases[v.shader] = write_constants(read_source(v.shader, "frag", dialect), constants)
            text = (
                bases[v.shader] if v.name == v.shader else v.source(dialect, text=bases[v.shader])
            )
            texts[(dialect, f"{v.name}.frag")] = text
    for (dialect, fname), text in texts.items():
        compile_check(text, fname.rsplit(".", 1)[1])
    extra = {}
    targets = resolve_targets(targets)
    if targets:
        core = {f: t for (d, f), t in texts.items() if d == "core"}
        with disk_full(out_dir):  # the tools' scratch files (nothing reaches out_dir yet)
            extra, _ = translate_targets(core, targets, constants)
    out_dir = Path(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out_dir.parent, prefix=f".{out_dir.name}."))
    try:
        with disk_full(out_dir):
            for (dialect, fname), text in texts.items():
                (tmp / dialect).mkdir(exist_ok=True)
                (tmp / dialect / fname).write_text(text, encoding="utf-8")
            for rel, data in extra.items():
                (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
                (tmp / rel).write_bytes(data)
        old = None
        if out_dir.exists():
            old = Path(tempfile.mkdtemp(dir=out_dir.parent, prefix=f".{out_dir.name}.old."))
            os.replace(out_dir, old / out_dir.name)
        os.replace(tmp, out_dir)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return sorted(out_dir.rglob("*.*"))
