"""Rewrite the committed result files under ``docs/results`` so that they name no folder of the
machine that made them: each absolute path becomes the path the writers now record.

* A file of the repository (an experiment, a shader, an ``#include`` folder; the checkout that
  ran it could sit anywhere, ``/work/main`` or ``/tmp/main_trade``): relative to the repository
  (``experiments/views.toml``), as ``study._io.repo_relative`` records it. Found by the longest
  tail of the path that names a file or folder of this checkout.
* A ``normal_map`` of a shader's declaration: relative to the shader's folder, as the shader's
  reader (``UserShader``) resolves it.
* A reference in a render cache (``.../references/<key>.exr``): in the default cache,
  ``.cache/references/<key>.exr`` (the key names it; the cache's folder was the machine's).
* A tradeoff's export folder (``.../shaders/<name>``): relative to the run's output folder,
  ``shaders/<name>``, as the tradeoff's other exports are recorded.

JSON files (every string value), the Markdown reports beside them (the same paths in their
text) and Parquet tables (string columns; the table's metadata kept) are rewritten in place;
a path that matches none of the rules is listed and left. Run from anywhere:
``python scripts/relative_result_paths.py [--check]`` (``--check``: list what would change and
exit 1 if anything would).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "docs" / "results"
# an absolute path in a string: up to a quote, whitespace, a bracket or a backquote
ABSOLUTE = re.compile(r"(?<![\w.~])/(?:work|tmp|home|root|Users|mnt|var|private)/[^\s\"'`,)\]|]*")
CACHED = re.compile(r"/references/([0-9a-f]{16,64}\.exr)$")
EXPORT = re.compile(r"/(shaders/[\w.-]+)$")


def in_repo(path: str) -> str | None:
    """The repository-relative path of ``path``'s longest tail (of two parts or more) that
    names a file or folder of this checkout."""
    parts = Path(path).parts[1:]
    for i in range(len(parts) - 1):
        tail = Path(*parts[i:])
        if (REPO / tail).exists():
            return tail.as_posix()
    return None


def relative(path: str, shader: str | None = None, key: str = "") -> str | None:
    """The path ``path`` becomes, or None when no rule matches. ``shader``: the (rewritten)
    ``shader_file`` of the record, for a declaration's ``normal_map`` (``key``)."""
    mine = in_repo(path)
    if mine is not None:
        if key == "normal_map" and shader:
            return Path(os.path.relpath(REPO / mine, (REPO / shader).parent)).as_posix()
        return mine
    m = CACHED.search(path)
    if m:
        return f".cache/references/{m[1]}"
    m = EXPORT.search(path)
    if m:
        return m[1]
    return None


def _pairs(o, pairs: dict, left: list, shader: str | None = None, key: str = "") -> None:
    """(old string -> new string) of every string value of a JSON document that holds a path."""
    if isinstance(o, dict):
        sh = o.get("shader_file")
        if isinstance(sh, str):
            shader = relative(sh) if sh.startswith("/") else sh
        for k, v in o.items():
            _pairs(v, pairs, left, shader, k)
    elif isinstance(o, list):
        for v in o:
            _pairs(v, pairs, left, shader, key)
    elif isinstance(o, str):
        new = _text(o, left, shader, key)
        if new != o:
            pairs[o] = new


def _text(s: str, left: list, shader: str | None = None, key: str = "") -> str:
    def sub(m):
        new = relative(m[0], shader, key)
        if new is None:
            left.append(m[0])
            return m[0]
        return new

    return ABSOLUTE.sub(sub, s)


def rewrite(path: Path, left: list) -> bytes | None:
    """The new contents of ``path``, or None when it holds no path to rewrite."""
    if path.suffix == ".json":  # the strings replaced in the text: its layout kept
        text = path.read_text()
        pairs: dict = {}
        _pairs(json.loads(text), pairs, left)
        new = text
        for old, value in pairs.items():
            new = new.replace(json.dumps(old)[1:-1], json.dumps(value)[1:-1])
        assert _pairs_done(new, pairs), path
        return None if new == text else new.encode()
    if path.suffix == ".md":
        text = path.read_text()
        new = _text(text, left)
        return None if new == text else new.encode()
    if path.suffix == ".parquet":
        return _parquet(path, left)
    return None


def _pairs_done(text: str, pairs: dict) -> bool:
    """Whether ``text`` parses to the document with every string of ``pairs`` replaced."""
    left: list = []
    again: dict = {}
    _pairs(json.loads(text), again, left)
    return not again


def _parquet(path: Path, left: list) -> bytes | None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    changed = False
    cols = []
    for name in table.column_names:
        col = table.column(name)
        if pa.types.is_string(col.type) or pa.types.is_large_string(col.type):
            values = col.to_pylist()
            new = [v if v is None else _text(v, left) for v in values]
            if new != values:
                changed = True
                col = pa.chunked_array([pa.array(new, type=col.type)])
        cols.append(col)
    if not changed:
        return None
    out = pa.Table.from_arrays(cols, schema=table.schema)
    sink = pa.BufferOutputStream()
    pq.write_table(out, sink)
    return sink.getvalue().to_pybytes()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="list what would change; write nothing")
    args = ap.parse_args(argv)
    changed, left = [], []
    for path in sorted(RESULTS.rglob("*")):
        if path.suffix not in (".json", ".md", ".parquet") or not path.is_file():
            continue
        new = rewrite(path, left)
        if new is None:
            continue
        changed.append(path.relative_to(REPO).as_posix())
        if not args.check:
            tmp = path.with_name(path.name + ".tmp")
            tmp.write_bytes(new)
            tmp.replace(path)
    for c in changed:
        print(("would rewrite " if args.check else "rewrote ") + c)
    for p in sorted(set(left)):
        print(f"left as it is (no rule): {p}", file=sys.stderr)
    return 1 if args.check and changed else 0


if __name__ == "__main__":
    sys.exit(main())
