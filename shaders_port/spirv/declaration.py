"""The constants a user's shader pair declares to fit: where each is declared (the fragment
shader, the user's own vertex shader, or both), its type, start value and range; and a file's
text with values in place of its constants' initializers.

A constant is a one-line declaration, ``float``, ``vec2``, ``vec3`` or ``vec4``: with an
initializer, ``const float NAME = 0.35;`` or ``uniform float NAME = 0.35;`` (desktop GLSL 1.20
and later), whose value is the start value; or a uniform without one, ``uniform float NAME;``,
as an engine's material sets it, whose start value the declaration gives (``LOW HIGH START``;
a vector's START is one number or its components joined by commas). A name declared in both
stages is one constant (GL links the uniforms of one name into one): both declarations take
the fitted value, and their initializers, where both have one, must agree.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

__all__ = [
    "UserConstant",
    "Site",
    "find_constants",
    "written_text",
    "declared",
    "STAGES",
    "without_initializers",
]

DECL = re.compile(
    r"^(?P<head>[ \t]*(?:const|uniform)[ \t]+(?:(?:lowp|mediump|highp)[ \t]+)?"
    r"(?P<type>float|vec2|vec3|vec4)[ \t]+(?P<name>\w+)[ \t]*=[ \t]*)(?P<value>[^;\n]*)"
    r"(?P<tail>;)",
    re.M,
)
BARE = re.compile(
    r"^[ \t]*uniform[ \t]+(?:(?:lowp|mediump|highp)[ \t]+)?(?P<type>float|vec2|vec3|vec4)[ \t]+"
    r"(?P<name>\w+)[ \t]*(?P<tail>;)",
    re.M,
)
SIZES = {"float": 1, "vec2": 2, "vec3": 3, "vec4": 4}
STAGES = ("fragment", "vertex")


@dataclass(frozen=True)
class Site:
    """One declaration of a constant: ``stage`` ('fragment' or 'vertex'), ``span`` the (start,
    end) character offsets of its initializer in that stage's file (a uniform without
    initializer, ``bare``: both the offset of its ``;``; one an ``#include`` d file declares:
    ``(-1, -1)``, never written back); ``assign``: of a uniform with an initializer, the
    offsets of `` = <value>`` (empty otherwise)."""

    stage: str
    span: tuple
    bare: bool
    assign: tuple = ()  # a uniform with an initializer: the offsets of `` = <value>``


@dataclass(frozen=True)
class UserConstant:
    """A constant to fit: GLSL ``name``, ``type`` ('float', 'vec2', 'vec3', 'vec4'), the start
    value ``default`` (a tuple of floats, one per component), the range ``lo`` <= value <=
    ``hi`` (every component), and its declarations ``sites`` (one :class:`Site` per stage that
    declares it, fragment first)."""

    name: str
    type: str
    default: tuple
    lo: float
    hi: float
    sites: tuple

    @property
    def stage(self) -> str:
        """'fragment', 'vertex' or 'both': the stages whose files declare it."""
        return "both" if len(self.sites) == 2 else self.sites[0].stage

    @property
    def bare(self) -> bool:
        """Every declaration a uniform without initializer (its start value is the
        declaration's START)."""
        return all(s.bare for s in self.sites)

    @property
    def uniform(self) -> bool:
        """Whether the constant is a uniform (the engine may set it), not a ``const``."""
        return any(s.bare or s.assign for s in self.sites)

    @property
    def span(self) -> tuple:
        """The span of its fragment-stage declaration (``(-1, -1)`` if it has none)."""
        s = self.site("fragment")
        return s.span if s is not None else (-1, -1)

    def site(self, stage: str) -> Site | None:
        return next((s for s in self.sites if s.stage == stage), None)

    def scalar_names(self) -> list[str]:
        """Each float; both components of a ``vec2``; the first three of a ``vec3`` or ``vec4``
        (RGB: an alpha is never compared)."""
        n = SIZES[self.type]
        return [self.name] if n == 1 else [f"{self.name}[{i}]" for i in range(min(n, 3))]


def parse_value(text: str, gtype: str, where: str) -> tuple:
    """The components of an initializer ``text`` of type ``gtype`` (``vec3(0.1)`` repeats)."""
    t = text.strip()
    if gtype == "float":
        parts = [t]
    else:
        m = re.fullmatch(rf"{gtype}\s*\((.*)\)", t)
        if m is None:
            raise ValueError(f"{where}: the initializer {t!r} is not {gtype}(...) of numbers")
        parts = [p.strip() for p in m[1].split(",")]
        parts = parts * SIZES[gtype] if len(parts) == 1 else parts
    try:
        vals = tuple(float(p.rstrip("fF")) for p in parts)
    except ValueError:
        raise ValueError(f"{where}: the initializer {t!r} is not made of number literals") from None
    if len(vals) != SIZES[gtype]:
        raise ValueError(f"{where}: {gtype} needs {SIZES[gtype]} components, got {len(vals)}")
    return vals


def start_value(text, gtype: str, where: str) -> tuple:
    """A declared start value (a number, or a vector's components joined by commas) as the
    tuple of its components."""
    parts = [p for p in str(text).split(",") if p.strip()] if isinstance(text, str) else [text]
    if isinstance(text, (list, tuple)):
        parts = list(text)
    try:
        vals = tuple(float(p) for p in parts)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: the start value {text!r} is not a number") from None
    vals = vals * SIZES[gtype] if len(vals) == 1 else vals
    if len(vals) != SIZES[gtype]:
        n = SIZES[gtype]
        raise ValueError(f"{where}: {gtype} needs {n} start components, got {len(vals)}")
    return vals


def literal(x: float) -> str:
    """The shortest GLSL float literal that reads back as the same float32."""
    r = str(np.float32(x))
    return r if ("e" in r or "." in r or "n" in r) else r + ".0"


def declared(source: str) -> tuple[dict, dict]:
    """``(with initializer, without)``: name -> the match of each one-line declaration of
    ``source`` of a constant with an initializer, and of a uniform without one."""
    decls = {m["name"]: m for m in DECL.finditer(source)}
    bare = {m["name"]: m for m in BARE.finditer(source)}
    return decls, {n: m for n, m in bare.items() if n not in decls}


def _one_site(stage: str, name: str, source: str, label: str, found: tuple):
    """``(Site, start value or None (bare), type, where)`` of one stage's declaration."""
    decls, bare = found
    m = decls.get(name) or bare.get(name)
    where = f"{label}:{source.count(chr(10), 0, m.start()) + 1}"
    if name in bare:
        return Site(stage, (m.start("tail"), m.start("tail")), True), None, m["type"], where
    value = parse_value(m["value"], m["type"], where)
    assign = (m.end("name"), m.end("value")) if m["head"].lstrip().startswith("uniform") else ()
    site = Site(stage, (m.start("value"), m.end("value")), False, assign)
    return site, value, m["type"], where


def _no_declaration(name: str, labels: list[str]) -> ValueError:
    files = " or ".join(labels)
    return ValueError(
        f"{labels[0]}: the constant {name} to fit has no one-line declaration in {files}: "
        f"`const float {name} = <value>;`, `uniform float {name} = <value>;` (desktop GLSL 1.20 "
        f"and later) or `uniform float {name};` with its start value in the declaration "
        "(`constant NAME LOW HIGH START`); float, vec2, vec3 or vec4"
    )


def find_constants(ranges: dict, texts: dict, included: dict | None = None) -> dict:
    """Name -> :class:`UserConstant` of each declared ``ranges`` entry (name -> ``(lo, hi)`` or
    ``(lo, hi, start)``), found in ``texts`` (stage -> ``(source, label)``, the fragment
    shader's first, the vertex shader's when it is a file of its own) or, for a uniform
    without initializer only an ``#include`` d file of the fragment shader declares, in
    ``included`` (name -> (its match in a stage's preprocessed text, that stage)). ValueError
    naming the problem."""
    found = {stage: declared(src) for stage, (src, _) in texts.items()}
    out = {}
    for name, (lo, hi, *start) in ranges.items():
        stages = [s for s in texts if name in found[s][0] or name in found[s][1]]
        if not stages and name in (included or {}):
            out[name] = _included_constant(name, *included[name], texts, lo, hi, start)
            continue
        if not stages:
            raise _no_declaration(name, [label for _, label in texts.values()])
        sites, values, types, wheres = [], [], set(), []
        for s in stages:
            site, value, gtype, where = _one_site(s, name, *texts[s], found[s])
            sites.append(site)
            values.append(value)
            types.add(gtype)
            wheres.append(where)
        if len(types) > 1:
            raise ValueError(
                f"{' and '.join(wheres)}: {name} is declared {' and '.join(sorted(types))}; one "
                "constant of both stages (GL links the uniforms of one name) has one type"
            )
        gtype = types.pop()
        default = _start_of(name, values, wheres, gtype, lo, hi, start)
        out[name] = UserConstant(name, gtype, default, lo, hi, tuple(sites))
    return out


def _start_of(name, values, wheres, gtype, lo, hi, start) -> tuple:
    """The start value of a constant from its declarations' initializers ``values`` (None for
    a uniform without one) or the declaration's ``start``; ValueError for a range that is
    empty, a START beside an initializer, none for uniforms without one, or initializers of
    the two stages that differ, or a start value outside the range."""
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ValueError(f"{wheres[0]}: the range [{lo}, {hi}] of {name} is empty")
    given = [(v, w) for v, w in zip(values, wheres) if v is not None]
    if given and start:
        raise ValueError(
            f"{given[0][1]}: {name} has an initializer, its start value; give no START in its "
            "declaration (or remove the initializer)"
        )
    if not given and not start:
        raise ValueError(
            f"{wheres[0]}: the uniform {name} has no initializer (the engine sets it); give its "
            f"start value: `// @study constant {name} {lo:g} {hi:g} START`"
        )
    if len({v for v, _ in given}) > 1:
        raise ValueError(
            f"{given[0][1]} and {given[1][1]}: {name} starts at {given[0][0]} in one stage and "
            f"{given[1][0]} in the other; one constant of both stages (GL links the uniforms of "
            "one name) has one start value: make the initializers equal or rename one"
        )
    default = given[0][0] if given else start_value(start[0], gtype, wheres[0])
    if not all(lo <= v <= hi for v in default):
        shown = f"{default[0]:g}" if len(set(default)) == 1 else str(default)
        raise ValueError(
            f"{wheres[0]}: {name} = {shown} lies outside its range [{lo}, {hi}]; widen the "
            "range or change the value"
        )
    return default


def _included_constant(name, m, stage, texts, lo, hi, start) -> UserConstant:
    """The constant of a uniform an ``#include`` d file of ``stage`` declares: never written
    back (the file is the engine's), its start value from the declaration."""
    where = f"{texts.get(stage, texts['fragment'])[1]} (an #include)"
    default = _start_of(name, [None], [where], m["type"], lo, hi, start)
    return UserConstant(name, m["type"], default, lo, hi, (Site(stage, (-1, -1), True),))


def written_text(source: str, constants, values: dict, stage: str, initializers: bool,
                 uniform_initializers: bool = True) -> str:  # fmt: skip
    """``source`` (the file of ``stage``) with ``values`` (name -> float | tuple) in place of
    the initializers of ``constants`` declared there; every other byte kept. A uniform without
    initializer gets one where ``initializers`` (its dialect allows one), else is left as it
    is; one an ``#include`` declares is never written. ``uniform_initializers`` False: a
    uniform's initializer is removed (the material sets the value)."""
    sites = [(c, c.site(stage)) for c in constants]
    sites = sorted(((c, s) for c, s in sites if s is not None), key=lambda cs: cs[1].span[0])
    out, pos = [], 0
    for c, s in sites:
        if s.bare and (not initializers or s.span[0] < 0):
            continue
        if s.assign and not uniform_initializers:
            out += [source[pos : s.assign[0]]]
            pos = s.assign[1]
            continue
        v = values[c.name]
        comps = v if isinstance(v, (tuple, list)) else (v,)
        text = literal(comps[0]) if c.type == "float" else (
            f"{c.type}({', '.join(literal(x) for x in comps)})")  # fmt: skip
        out += [source[pos : s.span[0]], f" = {text}" if s.bare else text]
        pos = s.span[1]
    out.append(source[pos:])
    return "".join(out)


def without_initializers(text: str, names) -> str:
    """``text`` with the initializer of each uniform of ``names`` declared on one line removed
    (``uniform float Shininess = 800.0;`` -> ``uniform float Shininess;``); every other byte
    kept."""
    names = set(names)
    if not names:
        return text

    def bare(m: re.Match) -> str:
        if m["name"] not in names or not m["head"].lstrip().startswith("uniform"):
            return m[0]
        return m["head"][: m["head"].index(m["name"]) + len(m["name"])] + m["tail"]

    return DECL.sub(bare, text)


def initialized_uniforms(texts: dict, given, label: str) -> dict:
    """The uniforms declared on one line with an initializer made of literals in the texts
    ``texts`` (stage -> text or None), except those named in ``given``: name -> (stage, the
    initializer's components). One not made of literals is left out (it stays as written)."""
    found = {}
    for stage, text in texts.items():
        for name, m in declared(text or "")[0].items():
            if name in given or name in found or not m["head"].lstrip().startswith("uniform"):
                continue
            try:
                found[name] = (stage, parse_value(m["value"], m["type"], label))
            except ValueError:
                continue
    return found


def split_bindings(bindings: dict, fragment: str, vertex: str, label: str) -> tuple[dict, dict]:
    """A declaration's ``bindings`` (name -> input) split by the stage that reads each name:
    (those the fragment shader's text ``fragment`` reads, those only the vertex shader's
    ``vertex`` reads); ValueError for a name neither reads. Comments do not count."""
    frag, vert = re.sub(r"//.*", "", fragment), re.sub(r"//.*", "", vertex or "")
    ours, theirs = {}, {}
    for name, target in bindings.items():
        pattern = rf"\b{re.escape(name)}\b"
        if re.search(pattern, frag):
            ours[name] = target
        elif re.search(pattern, vert):
            theirs[name] = target
        else:
            raise ValueError(
                f"{label}: bind {name}: neither this shader nor its vertex shader reads {name}; "
                "remove the line or correct the name"
            )
    return ours, theirs
