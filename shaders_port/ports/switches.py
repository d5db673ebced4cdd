"""The variant switches: how a port reads the GLSL ``#define`` names a variant is compiled with.

A shader variant is a name, a shader file and its preprocessor names
(``shaders_port.variants.Variant``). Each port module holds one table ``DEFINES`` mapping every
name its GLSL file understands to the port options that take the same code path, e.g.
``{"BEER_ATTENUATION": {"attenuation": "beer"}}``. :func:`decode` turns a variant's names into
the port's options; it is the only place a port's options are made from names, so the GLSL,
the port and the registry cannot disagree on what a name means.
"""

from __future__ import annotations


def decode(shader: str, table: dict, defines) -> dict:
    """The port options of ``shader`` compiled with ``defines`` (a tuple of preprocessor names).

    ``table``: the port's ``DEFINES`` (name -> {option: value}). Returns {option: value} for the
    options the names set (the others keep the port's defaults). Raises ValueError naming the
    name when the port does not implement it, or naming both names when two set one option to
    different values (e.g. ``GGX_SPECULAR`` with ``NO_SPECULAR``: the GLSL would take the first
    ``#ifdef`` branch silently).
    """
    if isinstance(defines, str):
        raise TypeError(f"defines must be a tuple of names, got the string {defines!r}")
    options: dict = {}
    set_by: dict = {}
    for name in defines:
        if name not in table:
            raise ValueError(
                f"{shader}: the port does not implement #define {name}; it implements: "
                f"{', '.join(table) or 'none'}"
            )
        for option, value in table[name].items():
            if option in options and options[option] != value:
                raise ValueError(
                    f"{shader}: #define {set_by[option]} and #define {name} both choose "
                    f"{option} ({options[option]!r} and {value!r}); keep one of them"
                )
            options[option], set_by[option] = value, name
    return options
