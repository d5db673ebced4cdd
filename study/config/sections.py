"""The typed view of an experiment: one frozen dataclass per section of the schema.

Generated from ``SCHEMA`` (``study.config.schema``), so a key added there is a field here:
``exp.water.sigma_t`` reads ``water.sigma_t``, ``exp.fit.shader`` reads ``fit.shader``; the
top-level keys (``name``, ``description``, ``resolution``, ``variant``) are attributes of the
experiment itself. Each field's type follows its ``Field.kind`` (``float``, ``int``, ``str``,
``bool``, lists for vectors and lists; ``None`` where a key is unset), and its docstring line is
the key's own documentation. The values are the validated ones, read when the section is asked
for (an experiment whose values change, such as an animation's frame, is never read stale).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from .schema import SCHEMA

__all__ = ["SECTIONS", "TOP_LEVEL", "section_of"]

_TYPES = {"float": float, "int": int, "str": str, "bool": bool}


def _make(section: str, keys: list[str]) -> type:
    fields = []
    doc = [f"The ``[{section}]`` table of an experiment (``study.config.schema``):", ""]
    for key in keys:
        f = SCHEMA[key]
        name = key.split(".", 1)[1]
        fields.append((name, _TYPES.get(f.kind, Any) | None))
        doc.append(f"{name}: {f.doc}")
    cls = dataclasses.make_dataclass(
        "".join(p.title() for p in section.split("_")) + "Section",
        fields,
        frozen=True,
        namespace={"__module__": __name__},
    )
    cls.__doc__ = "\n".join(doc)
    return cls


def _sections() -> dict[str, type]:
    keys: dict[str, list[str]] = {}
    for key in SCHEMA:
        if "." in key:
            keys.setdefault(key.split(".", 1)[0], []).append(key)
    return {section: _make(section, ks) for section, ks in keys.items()}


#: section name -> its frozen dataclass
SECTIONS: dict[str, type] = _sections()
#: the keys without a section: attributes of the experiment itself
TOP_LEVEL: tuple[str, ...] = tuple(k for k in SCHEMA if "." not in k)


def section_of(values: dict, section: str):
    """The frozen dataclass of ``section`` holding its keys' ``values`` (dotted key -> value)."""
    cls = SECTIONS[section]
    p = section + "."
    return cls(**{k[len(p) :]: v for k, v in values.items() if k.startswith(p)})
