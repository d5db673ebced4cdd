"""Tidy result tables of sweeps: one row per job, every input and every measured figure a column,
stored as Parquet (pyarrow), written atomically.

Rows are flat dicts. Nested job inputs and results are flattened with dotted names
(``{"scene": {"experiment": "a.toml"}}`` -> ``scene.experiment``); lists of numbers
(non-finite entries as nulls) or of strings stay lists (Parquet list columns); anything else
that is not a scalar is stored as its JSON text. Every row carries ``key`` (the job's
identity, :func:`job_key`), ``status`` (``ok`` or ``error``), ``error`` (the exception's type
and message, clipped), ``seconds`` (wall time of the job in its worker) and ``worker``. The
experiment file of a job's scene (``job.scene.experiment``) is recorded relative to the
repository where it lies inside it, so that a committed table names no folder of the machine
that ran it.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
from pathlib import Path

from .._io import disk_full, repo_relative

# what a row's results mean; every row records it (``schema``, 1 where absent). A sweep sets
# aside the rows of another version (``set_aside``) and measures their jobs again. 2: every fit
# pixel shaded at the footprint of ``fit.target_resolution``; 3: the adaptive search's screen
# shades one sample a pixel; 4: ``fit.loss``'s default is FLIP from the squared error's solution
SCHEMA_VERSION = 4
ERROR_CHARS = 2000


def job_key(fn_name: str, job: dict) -> str:
    """Identity of a job: a hash of the job function's qualified name and the canonical JSON of
    its inputs. Equal keys mean the same computation (the render cache keys the scene data)."""
    text = json.dumps(
        {"fn": fn_name, "job": job, "v": SCHEMA_VERSION},
        sort_keys=True,
        default=str,
        allow_nan=False,
    )
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def flatten(d: dict, prefix: str = "") -> dict:
    """``{"a": {"b": 1}, "c": [1, 2]}`` -> ``{"a.b": 1, "c": [1, 2]}`` with column-friendly
    values."""
    out = {}
    for k, v in d.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, name + "."))
        else:
            out[name] = _cell(v)
    return out


def job_columns(job: dict) -> dict:
    """The ``job.*`` columns of a job's row: its inputs flattened, the experiment file of its
    scene relative to the repository where it lies inside it (``study._io.repo_relative``)."""
    cols = flatten({"job": job})
    if isinstance(cols.get("job.scene.experiment"), str):
        cols["job.scene.experiment"] = repo_relative(cols["job.scene.experiment"])
    return cols


def _cell(v):
    if v is None or isinstance(v, (bool, str)):
        return v
    if isinstance(v, (bytes, bytearray)):  # a packed array (e.g. the screen's maps)
        return bytes(v)
    if isinstance(v, int):
        return int(v)
    if isinstance(v, float) or type(v).__module__ == "numpy" and hasattr(v, "item"):
        x = v.item() if hasattr(v, "item") else v
        if isinstance(x, bool):
            return x
        if isinstance(x, int):
            return x
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(v, (list, tuple)):
        items = [_cell(x) for x in v]
        numbers = [x for x in items if x is not None]
        if numbers and all(isinstance(x, (int, float)) and type(x) is not bool for x in numbers):
            return [None if x is None else float(x) for x in items]  # non-finite -> null
        if all(isinstance(x, str) for x in items):
            return list(items)
    return json.dumps(v, sort_keys=True, default=str)


def clip_error(exc: BaseException) -> str:
    """``Type: message`` clipped to a readable length."""
    text = f"{type(exc).__name__}: {exc}"
    return text if len(text) <= ERROR_CHARS else text[:ERROR_CHARS] + " ... (clipped)"


def write_table(path: Path, rows: list[dict]) -> Path:
    """Write ``rows`` as Parquet at ``path`` atomically (temporary file, then rename)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    columns: dict[str, None] = {}
    for r in rows:
        columns.update(dict.fromkeys(r))
    table = pa.Table.from_pylist([{c: r.get(c) for c in columns} for r in rows])
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        with disk_full(path.parent):
            pq.write_table(table, tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def set_aside(path: Path, rows: list[dict]) -> tuple[list[dict], Path | None]:
    """(the rows of ``rows`` of this :data:`SCHEMA_VERSION`, the file the others went to or
    None): rows of another version are appended to ``<name>.schema<v>.parquet`` beside the
    table (nothing is lost), so that no result of an earlier fit is read as a current one."""
    current = [r for r in rows if r.get("schema", 1) == SCHEMA_VERSION]
    others = [r for r in rows if r.get("schema", 1) != SCHEMA_VERSION]
    if not others:
        return rows, None
    path = Path(path)
    versions = sorted({str(r.get("schema", 1)) for r in others})
    aside = path.with_name(f"{path.stem}.schema{'-'.join(versions)}{path.suffix}")
    write_table(aside, read_table(aside) + others)
    write_table(path, current)
    return current, aside


def read_table(path: Path) -> list[dict]:
    """Rows of a table written by :func:`write_table`; [] if the file does not exist. A file that
    is not a readable Parquet table raises ValueError naming it (it is never silently replaced:
    move it away to start the sweep afresh)."""
    import pyarrow.parquet as pq

    path = Path(path)
    if not path.exists():
        return []
    try:
        return pq.read_table(path).to_pylist()
    except Exception as exc:  # pyarrow raises several types for a damaged file
        raise ValueError(
            f"{path} is not a readable Parquet table ({exc}); move it away to start "
            "this sweep afresh"
        ) from exc
