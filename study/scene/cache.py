"""Where references and shader inputs are cached, and the versions their keys include."""

from __future__ import annotations

import os
from pathlib import Path

SCENE_VERSION = 2


def cache_dir() -> Path:
    """``$STUDY_CACHE`` or ``./.cache`` (relative to the working directory)."""
    return Path(os.environ.get("STUDY_CACHE", ".cache")).resolve()


def versions() -> dict:
    """The Mitsuba and Dr.Jit versions (a cache key includes them: a new renderer renders anew)."""
    import drjit
    import mitsuba

    return {"mitsuba": mitsuba.__version__, "drjit": drjit.__version__}
