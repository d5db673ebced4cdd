"""The shader space: every technique of the five sources as one choice on an axis.

A *configuration* is one choice per axis of :data:`AXES` (a dict axis -> choice). Each
realisable configuration is one shader of the study: a GLSL file of ``glsl/`` and the
``#define`` names it is compiled with (:func:`realise`), named by :func:`name_of` (the names of
the shipped variants, ``water_refraction_beer_walls`` and so on, are names of this grammar, and
:func:`choices_of` reads any such name back). A configuration the files cannot realise is
refused with the reason (:class:`Unrealisable`), never silently mapped to another shader.

The axes and where each choice comes from (``SOURCE``):

* ``refraction``: ``raycast`` through the top-down textures (source 000), ``planar_distorted``
  (001's planar refraction of the depth-buffer point, distorted by the normal map with
  dispersion, 003), ``distorted`` (003 alone), ``planar`` (001 alone, flat water), ``none`` (no
  refracted light: the water's own colour, as 002 and 004 alone);
* ``reflection``: ``cube`` (000's sky cube map), ``raycast`` (000 section 3, cube map where
  nothing is hit), ``planar_distorted`` (004's mirrored camera distorted by the normal, 002),
  ``planar`` (004 alone), ``none``, ``box`` (Lagarde and Zanuttini's local cube map: a cube
  map of the dry pool looked up where the reflected ray leaves the box of its walls), ``ssr``
  (engines' screen-space reflection: the reflected ray marched over the camera's depth buffer
  of the dry scene, the sky cube map where it finds nothing);
* ``attenuation``: ``linear`` (000's clamped mix) or ``beer`` (Beer-Lambert per channel);
* ``specular``: ``phong`` (000), ``ggx``, ``none``, ``disc`` (the sun's disc mirrored by the
  normal, soft-edged: the sun's glitter as a mirror shows it);
* ``refine``: the crossing after the linear search, ``linear`` (000), ``binary``, ``secant``;
* ``walls``: ``off`` (000) or ``on`` (a crossing into a wall shaded as its submerged face);
* ``layers``: normal-map layers averaged, 4 (000), 2 or 1;
* ``normals``: how the layers make one normal: ``average`` (000: their normals averaged),
  ``slopes`` (their slopes averaged, the normal of their mean height: partial-derivative
  blending, Barre-Brisebois and Hill 2012; with two or four layers) or ``lean`` (LEAN mapping,
  Olano and Baker 2010: the layers' slopes and their squares read from a mipmapped map at the
  pixel's footprint, the normal of their mean slope there, and the variance of the slopes the
  pixel does not resolve widening the highlight: near, the sharp lobe; far, a wider one);
* ``parallax``: ``off`` (000: the layers read at the water plane's point) or ``offset``
  (parallax offset mapping, Kaneko et al. 2001: read where the eye ray meets the waves, the
  coordinates shifted along the view by the layers' mean height from a height map derived from
  the normal map; one more fetch per layer; not with ``normals = lean``);
* ``textures``: ``float`` or ``game`` (8-bit colour, half-float depth).

What the files realise: the raycast refraction with the cube-map, local cube-map, screen-space,
raycast or no reflection and every other axis free (``water_refraction.frag``,
``water_reflection.frag``); the screen-space refractions and no refraction with the planar or
cube-map reflection, the other axes at the original's choices (``water_baseline.frag``: nine
pairs, :data:`_BASELINE`), so each source's technique alone is one shader (001:
``water_baseline_flat_cube``; 003: ``water_baseline_noplanar_cube``; 004:
``water_baseline_flat_norefraction``; 002 on 004: ``water_baseline_norefraction``). The raycast
refraction takes 004's mirror distorted by 002 too (``water_refraction_mirror``,
``PLANAR_REFLECTION``); 004's undistorted mirror is that shader at ``reflect_distortion = 0``,
so ``planar`` with the raycast is refused with that.
"""

from __future__ import annotations

import itertools

AXES: dict[str, tuple] = {
    "refraction": ("raycast", "planar_distorted", "distorted", "planar", "none"),
    "reflection": ("cube", "raycast", "planar_distorted", "planar", "none", "box", "ssr"),
    "attenuation": ("linear", "beer"),
    "specular": ("phong", "ggx", "none", "disc"),
    "refine": ("linear", "binary", "secant"),
    "walls": ("off", "on"),
    "layers": (4, 2, 1),
    "normals": ("average", "slopes", "lean"),
    "parallax": ("off", "offset"),
    "textures": ("float", "game"),
}
ORIGINAL = {axis: choices[0] for axis, choices in AXES.items()}

# where each choice comes from: a source (000-004) or the study's own variants
SOURCE = {
    ("refraction", "raycast"): "000",
    ("refraction", "planar_distorted"): "001 + 003",
    ("refraction", "distorted"): "003",
    ("refraction", "planar"): "001",
    ("refraction", "none"): "002, 004 (no refraction)",
    ("reflection", "cube"): "000",
    ("reflection", "raycast"): "000 section 3",
    ("reflection", "planar_distorted"): "004 + 002",
    ("reflection", "planar"): "004",
    ("reflection", "none"): "000 (NOREFLECTION)",
    ("reflection", "box"): "Lagarde and Zanuttini (local cube map)",
    ("specular", "disc"): "the sun's disc in the mirror (ocean shaders' sun glint)",
    ("reflection", "ssr"): "screen-space reflection (engines' SSR)",
    ("normals", "slopes"): "Barre-Brisebois and Hill (partial-derivative blending)",
    ("normals", "lean"): "Olano and Baker (LEAN mapping)",
    ("parallax", "offset"): "Kaneko et al. (parallax offset mapping)",
}

# each source's technique alone (the original's choices elsewhere, the cube map where a source
# has no reflection of its own) and the games' composition of 001-004: a row of every front
ALONE = {
    "000 (the original)": {},
    "000 section 3 (raycast reflection)": {"reflection": "raycast"},
    "001 (planar refraction, flat)": {"refraction": "planar", "reflection": "cube"},
    "002 on 004 (distorted mirror)": {"refraction": "none", "reflection": "planar_distorted"},
    "003 (distorted refraction)": {"refraction": "distorted", "reflection": "cube"},
    "004 (mirror, flat)": {"refraction": "none", "reflection": "planar"},
    "Lagarde and Zanuttini (local cube map)": {"reflection": "box"},
    "the sun's disc in the mirror (ocean shaders' sun glint)": {"specular": "disc"},
    "screen-space reflection (engines' SSR)": {"reflection": "ssr"},
    "Barre-Brisebois and Hill (slope-blended normals)": {"normals": "slopes"},
    "Olano and Baker (LEAN mapping)": {"normals": "lean"},
    "Kaneko et al. (parallax offset mapping)": {"parallax": "offset"},
    "001-004 (the games' composition)": {
        "refraction": "planar_distorted",
        "reflection": "planar_distorted",
    },
}

# the #define of each choice in the raycast files (the original's choices have none)
_RAYCAST_DEFINES = {
    ("attenuation", "beer"): "BEER_ATTENUATION",
    ("specular", "ggx"): "GGX_SPECULAR",
    ("specular", "disc"): "SUN_DISC_SPECULAR",
    ("specular", "none"): "NO_SPECULAR",
    ("walls", "on"): "WALL_FACES",
    ("refine", "binary"): "BINARY_REFINE",
    ("refine", "secant"): "SECANT_REFINE",
    ("layers", 2): "TWO_NORMAL_LAYERS",
    ("layers", 1): "ONE_NORMAL_LAYER",
    ("normals", "slopes"): "SLOPE_NORMALS",
    ("normals", "lean"): "LEAN_NORMALS",
    ("parallax", "offset"): "PARALLAX_OFFSET",
    ("reflection", "planar_distorted"): "PLANAR_REFLECTION",
    ("reflection", "box"): "BOX_REFLECTION",
    ("reflection", "ssr"): "SSR_REFLECTION",
}
# name tokens, in name order (a name is the shader file then the tokens of its choices)
_TOKENS = (
    (("reflection", "none"), "noreflection"),
    (("reflection", "planar_distorted"), "mirror"),
    (("reflection", "box"), "box"),
    (("reflection", "ssr"), "ssr"),
    (("attenuation", "beer"), "beer"),
    (("specular", "ggx"), "ggx"),
    (("specular", "disc"), "disc"),
    (("specular", "none"), "nospecular"),
    (("walls", "on"), "walls"),
    (("refine", "binary"), "binary"),
    (("refine", "secant"), "secant"),
    (("layers", 2), "2layers"),
    (("layers", 1), "1layer"),
    (("normals", "slopes"), "slopes"),
    (("normals", "lean"), "lean"),
    (("parallax", "offset"), "parallax"),
    (("textures", "game"), "game_textures"),
)
# the screen-space file's (refraction, reflection) pairs: name and #defines. Planar refraction
# (001) is flat water, so it goes with an undistorted reflection; a normal-mapped refraction
# with the normal-mapped reflections
_BASELINE = {
    ("planar_distorted", "planar_distorted"): ("water_baseline", ()),
    ("distorted", "planar_distorted"): ("water_baseline_noplanar", ("NO_PLANAR_REFRACTION",)),
    ("planar", "planar"): ("water_baseline_flat", ("FLAT_WATER",)),
    ("planar_distorted", "cube"): ("water_baseline_cube", ("CUBE_REFLECTION",)),
    ("distorted", "cube"): (
        "water_baseline_noplanar_cube",
        ("NO_PLANAR_REFRACTION", "CUBE_REFLECTION"),
    ),
    ("planar", "cube"): ("water_baseline_flat_cube", ("FLAT_WATER", "CUBE_REFLECTION")),
    ("none", "planar_distorted"): ("water_baseline_norefraction", ("NO_REFRACTION",)),
    ("none", "planar"): ("water_baseline_flat_norefraction", ("FLAT_WATER", "NO_REFRACTION")),
    ("none", "cube"): ("water_baseline_norefraction_cube", ("NO_REFRACTION", "CUBE_REFLECTION")),
}


class Unrealisable(ValueError):
    """A configuration no shader file realises; the message says why and what would."""


def checked(choices: dict) -> dict:
    """``choices`` completed with the original's choice on every axis it leaves out; a
    ValueError names an unknown axis or choice."""
    unknown = sorted(set(choices) - set(AXES))
    if unknown:
        raise ValueError(f"unknown axis {unknown}; the axes: {', '.join(AXES)}")
    out = {**ORIGINAL, **choices}
    for axis, c in out.items():
        if c not in AXES[axis]:
            raise ValueError(f"{axis} = {c!r}; the choices: {', '.join(map(str, AXES[axis]))}")
    return out


def realise(choices: dict) -> tuple[str, tuple[str, ...], str]:
    """``(shader file, #define names, textures)`` of a configuration; :class:`Unrealisable`
    (with the reason) when no file realises it."""
    c = checked(choices)
    if c["refraction"] != "raycast":
        return _realise_screen_space(c)
    if c["reflection"] == "planar":
        raise Unrealisable(
            "reflection = planar (source 004 alone, a flat mirror) is in the screen-space "
            "shader only: with refraction = raycast choose reflection = planar_distorted "
            "(its reflect_distortion = 0 is the flat mirror)"
        )
    if c["normals"] == "slopes" and c["layers"] == 1:
        raise Unrealisable(
            "normals = slopes blends the layers, and one layer has nothing to blend: choose "
            "layers = 4 or 2 with it (one layer's normal is the same either way)"
        )
    if c["parallax"] == "offset" and c["normals"] == "lean":
        raise Unrealisable(
            "parallax = offset shifts where the normal map is read, and LEAN's level of detail "
            "is the unshifted coordinates': choose normals = average or slopes with it"
        )
    if c["reflection"] == "none" and c["specular"] != "none":
        raise Unrealisable(
            "reflection = none skips block [7], and the highlight is added to the reflection: "
            "choose specular = none with it"
        )
    shader = "water_reflection" if c["reflection"] == "raycast" else "water_refraction"
    defines = ["NOREFLECTION"] if c["reflection"] == "none" else []
    defines += [
        d
        for (axis, choice), d in _RAYCAST_DEFINES.items()
        if c[axis] == choice and not (c["reflection"] == "none" and axis == "specular")
    ]
    return shader, tuple(defines), c["textures"]


def _realise_screen_space(c: dict) -> tuple[str, tuple[str, ...], str]:
    fixed = (
        "attenuation",
        "specular",
        "refine",
        "walls",
        "layers",
        "normals",
        "parallax",
        "textures",
    )
    off = [f"{a} = {c[a]}" for a in fixed if c[a] != ORIGINAL[a]]
    if off:
        raise Unrealisable(
            f"the screen-space shader (water_baseline, refraction = {c['refraction']}) has the "
            "original's choices on the other axes only (depth tint, Phong highlight, no "
            "refinement, no wall faces, four layers averaged at the plane's point, float "
            "textures), not "
            f"{', '.join(off)}"
        )
    key = (c["refraction"], c["reflection"])
    if key not in _BASELINE:
        allowed = ", ".join(f"refraction = {r} with reflection = {f}" for r, f in _BASELINE)
        raise Unrealisable(
            f"refraction = {c['refraction']} with reflection = {c['reflection']}: the "
            "screen-space shader's planar refraction is flat water (undistorted reflections "
            "only), its normal-mapped refractions go with the normal-mapped reflections, and "
            "it has neither the raycast reflection, the screen-space reflection of the raycast "
            f"file nor the local cube map; it realises {allowed}"
        )
    return "water_baseline", _BASELINE[key][1], "float"


def name_of(choices: dict) -> str:
    """The configuration's name: its shader file then the tokens of its choices that differ
    from the original (``water_refraction_beer_walls``); :class:`Unrealisable` if none."""
    c = checked(choices)
    shader, _, _ = realise(c)
    if shader == "water_baseline":
        return _BASELINE[(c["refraction"], c["reflection"])][0]
    tokens = [t for (axis, choice), t in _TOKENS if c[axis] == choice]
    if c["reflection"] == "none":
        tokens = [t for t in tokens if t != "nospecular"]
    return "_".join([shader, *tokens])


def choices_of(name: str) -> dict:
    """The configuration named ``name`` (the inverse of :func:`name_of`); a ValueError says
    what part of the name is not a choice."""
    for (refraction, reflection), (baseline, _) in _BASELINE.items():
        if baseline == name:
            return checked({"refraction": refraction, "reflection": reflection})
    for shader, reflection in (("water_reflection", "raycast"), ("water_refraction", "cube")):
        if name == shader or name.startswith(shader + "_"):
            rest = name[len(shader) + 1 :]
            break
    else:
        if name.startswith("water_baseline"):
            names = ", ".join(n for n, _ in _BASELINE.values())
            raise ValueError(
                f"{name!r}: the screen-space shaders are {names} (their other axes are the "
                "original's choices)"
            )
        raise ValueError(
            f"{name!r} is not a shader of the space: a name starts with water_refraction, "
            "water_reflection or water_baseline"
        )
    choices = {"reflection": reflection}
    for token in _split_tokens(rest, name):
        (axis, choice) = next(k for k, t in _TOKENS if t == token)
        if axis in choices and not (axis == "reflection" and choices[axis] == reflection):
            raise ValueError(f"{name!r}: two choices of {axis}")
        choices[axis] = choice
    if choices.get("reflection") == "none":
        if reflection != "cube":
            raise ValueError(f"{name!r}: noreflection is a variant of water_refraction")
        choices.setdefault("specular", "none")
    c = checked(choices)
    if name_of(c) != name:
        raise ValueError(f"{name!r} is not in canonical form; the same shader is {name_of(c)!r}")
    return c


def _split_tokens(rest: str, name: str) -> list[str]:
    known = [t for _, t in _TOKENS]
    out, parts = [], rest.split("_") if rest else []
    while parts:
        two = "_".join(parts[:2])
        if two in known:
            out.append(two)
            parts = parts[2:]
        elif parts[0] in known:
            out.append(parts.pop(0))
        else:
            raise ValueError(
                f"{name!r}: {parts[0]!r} is not a choice; the name tokens: {', '.join(known)}"
            )
    return out


def configurations(fix: dict | None = None) -> list[dict]:
    """Every realisable configuration with the axes of ``fix`` pinned, in axis order."""
    fix = dict(fix or {})
    checked(fix)  # names an unknown axis or choice
    axes = {a: ((fix[a],) if a in fix else cs) for a, cs in AXES.items()}
    out = []
    for combo in itertools.product(*axes.values()):
        c = dict(zip(axes, combo))
        try:
            realise(c)
        except Unrealisable:
            continue
        out.append(c)
    return out


def neighbours(choices: dict, fix: dict | None = None) -> list[dict]:
    """The realisable configurations that differ from ``choices`` on one axis (not an axis of
    ``fix``), and on the coupled axis where one choice needs another (reflection = none
    brings specular = none; a screen-space refraction brings its planar reflection)."""
    c = checked(choices)
    out = []
    for axis, options in AXES.items():
        if fix and axis in fix:
            continue
        for option in options:
            if option == c[axis]:
                continue
            for n in _coupled({**c, axis: option}, axis):
                try:
                    realise(n)
                except Unrealisable:
                    continue
                if n not in out:
                    out.append(n)
    return out


def _coupled(c: dict, changed: str) -> list[dict]:
    if changed == "reflection" and c["reflection"] == "none":
        return [{**c, "specular": "none"}]
    if changed == "refraction" and c["refraction"] != "raycast":
        base = {**ORIGINAL, "refraction": c["refraction"]}
        return [{**base, "reflection": f} for r, f in _BASELINE if r == c["refraction"]]
    if changed == "refraction":  # back to the raycast: its cube map
        return [{**c, "reflection": "cube"}]
    return [c]


def describe(choices: dict) -> str:
    """One line for reports: the choices that differ from the original, with their sources."""
    c = checked(choices)
    parts = [
        f"{a} {v}" + (f" ({SOURCE[(a, v)]})" if (a, v) in SOURCE else "")
        for a, v in c.items()
        if v != ORIGINAL[a]
    ]
    return "the original shader" + (" with " + ", ".join(parts) if parts else "")


def parse_fix(entries: list[str]) -> dict:
    """``["axis=choice", ...]`` (``tradeoff.fix``) as a dict, choices typed as in ``AXES``."""
    out = {}
    for e in entries:
        axis, sep, choice = e.partition("=")
        axis, choice = axis.strip(), choice.strip()
        if not sep or axis not in AXES:
            raise ValueError(
                f"tradeoff.fix entry {e!r}: expected axis=choice with an axis of {', '.join(AXES)}"
            )
        typed = {str(c): c for c in AXES[axis]}
        if choice not in typed:
            raise ValueError(
                f"tradeoff.fix entry {e!r}: {axis} has the choices "
                f"{', '.join(map(str, AXES[axis]))}"
            )
        out[axis] = typed[choice]
    return out
