"""Scalar names of the shader's constants: ``bumptex_mult``, ``water_color[2]``, ...

The experiment's ``fit.parameters`` names whole constants; colours expand to their RGB
components (alpha is not fitted: the shader's output alpha is not compared).
"""
from __future__ import annotations

from shaders_port import CONSTANT_SPECS, Constants


def expand_parameters(names: list[str]) -> list[str]:
    """['water_color', 'bumptex_mult'] -> ['water_color[0]', 'water_color[1]', 'water_color[2]', 'bumptex_mult']."""
    out = []
    for n in names:
        if n not in CONSTANT_SPECS:
            raise ValueError(f"unknown constant {n!r}; known: {sorted(CONSTANT_SPECS)}")
        if CONSTANT_SPECS[n][1].endswith("vec4"):
            out += [f"{n}[{i}]" for i in range(3)]
        elif CONSTANT_SPECS[n][1].endswith("int"):
            raise ValueError(f"{n} is an integer loop cap: it belongs to the speed/accuracy study, not the fit")
        else:
            out.append(n)
    return out


def split_name(name: str) -> tuple[str, int | None]:
    """'water_color[2]' -> ('water_color', 2); 'bumptex_mult' -> ('bumptex_mult', None)."""
    if name.endswith("]") and "[" in name:
        base, idx = name[:-1].split("[", 1)
        return base, int(idx)
    return name, None


def get_value(c: Constants, name: str) -> float:
    base, idx = split_name(name)
    v = getattr(c, base)
    return float(v[idx] if idx is not None else v)


def with_values(c: Constants, values: dict) -> Constants:
    """``c`` with scalar names set to ``values`` (floats, or Dr.Jit scalars for AD)."""
    changes: dict = {}
    for name, v in values.items():
        base, idx = split_name(name)
        if idx is None:
            changes[base] = v
        else:
            comps = list(changes.get(base, getattr(c, base)))
            comps[idx] = v
            changes[base] = tuple(comps)
    return c.replace(**changes)


def bounds(name: str) -> tuple[float, float]:
    """Valid range of a scalar name (the range of its constant)."""
    return CONSTANT_SPECS[split_name(name)[0]][3]
