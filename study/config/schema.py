"""The experiment schema: every key of an experiment file with its type, default, units, range
and meaning (``SCHEMA``: the scene's keys of ``schema_scene`` then the study's of
``schema_study``), the choices it refers to, and which keys touch only the shader's inputs or
only the reference's samples. The single source of truth for validation (``experiment``),
defaults and the key tables of the docs (:func:`schema_markdown`)."""

from __future__ import annotations

import json

from .schema_scene import FLOOR_SHAPES, SCENE_KEYS, Field
from .schema_study import FIT_PARAMETERS, SHADERS, SOLVERS, STUDY_KEYS

__all__ = [
    "FIT_PARAMETERS",
    "FLOOR_SHAPES",
    "REFERENCE_ONLY_KEYS",
    "SCHEMA",
    "SHADER_INPUT_KEYS",
    "SHADERS",
    "SOLVERS",
    "Field",
    "schema_markdown",
]

SCHEMA: dict[str, Field] = {**SCENE_KEYS, **STUDY_KEYS}

# keys that change only the shader's inputs, never the reference image
SHADER_INPUT_KEYS = frozenset(
    {
        "reference.texture_size",
        "reference.texture_spp",
        "reference.texture_method",
        "reference.lighting_size",
        "reference.wall_spp",
        "reference.wall_denoise",
        "reference.lighting_denoise",
        "reference.lighting_direct",
        "reference.sun_photons",
        "reference.sky_directions",
        "reference.bounce_spp",
        "reference.sun_bounces",
        "reference.refraction_lighting",
        "reference.fresnel_transmission",
        "waves.normal_map_size",
        "waves.slope_scale",
    }
)

# keys that change only the reference image's samples, never the shader's inputs
REFERENCE_ONLY_KEYS = frozenset(
    {"reference.spp", "reference.target_noise", "reference.max_spp", "reference.sampler"}
)


def schema_markdown() -> str:
    """The key table of docs/experiment-keys.md, generated from SCHEMA."""
    lines = ["| key | type | default | units | allowed | meaning |", "|---|---|---|---|---|---|"]
    for key, f in SCHEMA.items():
        rng = f"[{f.lo:g}, {f.hi:g}]" if f.lo is not None else ""
        names = ", ".join(f"`{c}`" for c in f.choices or ())
        allowed = "; ".join(a for a in (rng, names) if a) if f.kind == "vec2" else names or rng
        default = json.dumps(f.default)
        lines.append(f"| `{key}` | {f.kind} | `{default}` | {f.units} | {allowed} | {f.doc} |")
    return "\n".join(lines) + "\n"
