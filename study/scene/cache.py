"""Where references and shader inputs are cached, the versions their keys include, and the
cached ``.npz`` files of the inputs some shaders read beyond the study's."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from .._io import disk_full, file_lock

SCENE_VERSION = 2


def cache_dir() -> Path:
    """``$STUDY_CACHE`` or ``./.cache`` (relative to the working directory)."""
    return Path(os.environ.get("STUDY_CACHE", ".cache")).resolve()


def versions() -> dict:
    """The Mitsuba and Dr.Jit versions (a cache key includes them: a new renderer renders anew)."""
    import drjit
    import mitsuba

    return {"mitsuba": mitsuba.__version__, "drjit": drjit.__version__}


def _read_fields(path: Path, names, what: str, log) -> dict | None:
    if not path.exists():
        return None
    try:
        with np.load(path) as z:
            fields = {k: z[k] for k in names}
        log(f"{what}: cached {path}")
        return fields
    except (OSError, ValueError, KeyError) as exc:
        log(f"{what}: unreadable cache file {path} ({exc}); rebuilding")
    return None


def cached_fields(path: Path, names, build, what: str, log=print) -> dict:
    """The arrays ``names`` of ``path`` (an ``.npz`` file named by its key) when it holds them,
    else ``build()`` (a dict name -> array) written there atomically; one process builds while
    others wanting the same file wait on its lock (``<path>.lock``). ``what`` names the inputs
    in the log lines (``<what>: cached <path>`` / ``<what>: built and cached at <path>``)."""
    path = Path(path)
    fields = _read_fields(path, names, what, log)
    if fields is not None:
        return fields
    with file_lock(path.with_suffix(".lock"), what, log):
        fields = _read_fields(path, names, what, lambda m: None)  # built meanwhile?
        if fields is not None:
            log(f"{what}: cached {path}")
            return fields
        fields = build()
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz.tmp")
        os.close(fd)
        try:
            with disk_full(path.parent), open(tmp, "wb") as f:
                np.savez_compressed(f, **fields)
            os.replace(tmp, path)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    log(f"{what}: built and cached at {path}")
    return fields
