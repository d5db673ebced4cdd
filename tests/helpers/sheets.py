"""Reading a short binding sheet (``BINDINGS.md``) as a newcomer wiring the shader would: the
values the fit used, parsed from its text alone (``study.export.textures.scene_lines``'s
wording), into the form of ``textures.json``'s scene record."""

from __future__ import annotations

import re

NUM = r"-?[\d.]+(?:e[-+]?\d+)?"


def _vec(text: str) -> list[float]:
    return [float(x) for x in re.findall(NUM, text)]


def _after(text: str, pattern: str) -> re.Match:
    m = re.search(pattern, text)
    if m is None:
        raise AssertionError(f"the sheet has no line matching {pattern!r}")
    return m


def sheet_values(text: str) -> tuple[dict, float]:
    """(the scene record the short sheet ``text`` states, the normal map's tile) with the
    sheet's printed precision: ``lightpos``, ``lightcolor``, ``wave_offsets``,
    ``wave_velocities``, ``top_down`` (``extent`` [x0, z0, x1, z1], ``size``,
    ``no_geometry``, ``tex_matrix0`` rows). AssertionError names a value the sheet lacks."""
    vec = rf"\(({NUM}(?:, {NUM})*)\)"
    light = _after(text, rf"`lightpos` = {vec} .*?`lightcolor` = {vec}")
    waves = re.findall(rf"`wave(\d)` = {vec} \+ t \* {vec}", text)
    if len(waves) != 4:
        raise AssertionError(f"the sheet gives {len(waves)} waves, not 4")
    box = _after(text, rf"over x in \[({NUM}), ({NUM})\], z in \[({NUM}), ({NUM})\], (\d+) x")
    none = _after(text, rf"holds world y, ({NUM}) where nothing is below")
    rows = _after(text, rf"`uTextureMatrix0` \(rows\) = ((?:{vec} ?){{4}})")
    tile = _after(text, rf"\(tile ({NUM})\)")
    x0, x1, z0, z1 = (float(box.group(k)) for k in (1, 2, 3, 4))
    scene = {
        "lightpos": _vec(light.group(1)),
        "lightcolor": _vec(light.group(2)),
        "wave_offsets": [_vec(o) for _, o, _ in sorted(waves)],
        "wave_velocities": [_vec(v) for _, _, v in sorted(waves)],
        "top_down": {
            "extent": [x0, z0, x1, z1],
            "size": int(box.group(5)),
            "no_geometry": float(none.group(1)),
            "tex_matrix0": [_vec(r) for r in re.findall(vec, rows.group(1))],
        },
    }
    return scene, float(tile.group(1))
