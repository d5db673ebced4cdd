"""Images and text on disk: OpenEXR files with provenance in the header, PNG previews, and atomic
JSON/text writers (a killed process never leaves a truncated file under the final name).

Images are float32 ``(height, width, 3)`` linear RGB, row 0 at the top. Extra layers
(e.g. the per-pixel standard error) are ``(height, width)`` or ``(height, width, 3)`` float32.
Provenance is a JSON dictionary stored as the string attribute ``study_provenance``. Writes are
atomic: the file is written under a temporary name in the same folder and renamed, so a killed
process never leaves a truncated file under the final name.

Paths a result file records are relative to the repository where they lie inside it
(:func:`repo_relative`), so that a committed result names no folder of the machine that made
it; :func:`repo_path` reads such a path back.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import socket
import tempfile
import time
from pathlib import Path

import numpy as np
import OpenEXR

PROVENANCE_KEY = "study_provenance"
# the repository: the folder that holds the ``study`` package
REPO_ROOT = Path(__file__).resolve().parents[1]


def repo_relative(path) -> str:
    """``path`` as a result file records it: relative to the repository (``experiments/a.toml``,
    ``/`` separated) when it lies inside it, else as given. A relative ``path`` is read against
    the working directory."""
    try:
        return Path(os.path.realpath(path)).relative_to(REPO_ROOT).as_posix()
    except ValueError:
        return str(path)


def repo_path(path) -> Path:
    """A path :func:`repo_relative` recorded, to open: a relative one is the repository's."""
    p = Path(path)
    return p if p.is_absolute() else REPO_ROOT / p


class DiskFullError(OSError):
    """A write ran out of space (``errno.ENOSPC`` / ``EDQUOT``); the message names the folder.
    The writers here write to a temporary file and rename it, so nothing half-written is left
    and the files already there stay valid."""


@contextlib.contextmanager
def disk_full(folder):
    """Turn running out of space while writing into ``folder`` into a :class:`DiskFullError`
    that names it (OpenEXR reports it as a ``RuntimeError``; Python as ``OSError``)."""
    try:
        yield
    except DiskFullError:
        raise
    except (OSError, RuntimeError) as exc:
        full = getattr(exc, "errno", None) in (
            errno.ENOSPC,
            errno.EDQUOT,
        ) or "No space left on device" in str(exc)
        if not full:
            raise
        raise DiskFullError(
            errno.ENOSPC,
            f"no space left on the device holding {folder}: nothing "
            "was written there; free space, or point --out / STUDY_CACHE at "
            "another disk",
        ) from exc


def write_exr(
    path,
    rgb: np.ndarray,
    provenance: dict | None = None,
    extra: dict[str, np.ndarray] | None = None,
) -> Path:
    """Write ``rgb`` (H, W, 3), or (H, W, 4) as the channels R, G, B, A, and optional extra
    (H, W) or (H, W, 3) layers atomically; return the path."""
    path = Path(path)
    rgb = np.ascontiguousarray(rgb, dtype=np.float32)
    if rgb.ndim != 3 or rgb.shape[2] not in (3, 4):
        raise ValueError(f"write_exr: expected an (H, W, 3) or (H, W, 4) image, got {rgb.shape}")
    channels = {"RGBA" if rgb.shape[2] == 4 else "RGB": rgb}
    for name, arr in (extra or {}).items():
        arr = np.ascontiguousarray(arr, dtype=np.float32)
        if arr.shape not in (rgb.shape[:2], rgb.shape):
            raise ValueError(
                f"write_exr: channel {name!r} has shape {arr.shape}, expected "
                f"{rgb.shape[:2]} or {rgb.shape}"
            )
        channels[name] = arr
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    if provenance is not None:
        header[PROVENANCE_KEY] = json.dumps(provenance, sort_keys=True)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=".exr.tmp")
    os.close(fd)
    try:
        with disk_full(path.parent):
            OpenEXR.File(header, channels).write(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def read_exr(path) -> tuple[np.ndarray, dict, dict[str, np.ndarray]]:
    """Read an EXR written by :func:`write_exr`: (rgb (H, W, 3) float32, or (H, W, 4) for an
    RGBA image, provenance, extra channels)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no EXR file at {path}")
    try:
        with OpenEXR.File(str(path)) as f:
            raw = f.header().get(PROVENANCE_KEY)  # read before the file closes
            channels = {k: np.array(v.pixels, dtype=np.float32) for k, v in f.channels().items()}
    except Exception as exc:  # OpenEXR raises plain exceptions on corrupt files
        raise ValueError(
            f"{path} is not a readable EXR file ({exc}); delete it and re-render"
        ) from exc
    if "RGB" not in channels and "RGBA" not in channels:
        raise ValueError(f"{path} has no RGB channel (channels: {sorted(channels)})")
    rgb = channels.pop("RGB") if "RGB" in channels else channels.pop("RGBA")
    provenance = json.loads(raw) if raw else {}
    return rgb, provenance, channels


def to_srgb(img: np.ndarray) -> np.ndarray:
    """Linear RGB -> sRGB-encoded values in [0, 1] (NaN shown as 0, clipped)."""
    x = np.clip(np.nan_to_num(np.asarray(img, np.float64), nan=0.0), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def write_png(path, rgb: np.ndarray, exposure: float = 1.0) -> Path:
    """Write a linear-RGB image as an sRGB-encoded 8-bit PNG preview (clipped)."""
    import matplotlib.image

    srgb = to_srgb(np.asarray(rgb, dtype=np.float64) * exposure)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    matplotlib.image.imsave(path, (srgb * 255 + 0.5).astype(np.uint8))
    return path


def write_json(path: Path, data: dict) -> None:
    """Write JSON atomically; refuses NaN/inf (they are not JSON)."""
    path = Path(path)
    write_text_atomic(path, json.dumps(data, indent=2, sort_keys=True, allow_nan=False) + "\n")


def write_text_atomic(path: Path, text: str) -> None:
    """Write text under a unique temporary name beside ``path``, then rename it into place."""
    path = Path(path)
    with disk_full(path.parent):
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with disk_full(path.parent), os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


@contextlib.contextmanager
def file_lock(path, what: str = "", log=None, timeout: float | None = None):
    """Hold an exclusive lock on ``path`` (created if missing) while the block runs.

    Processes that need the same cache entry (a sweep's workers, two shells) serialise on it:
    the first renders and writes, the others wait and then find the entry in the cache. The
    lock is an OS advisory lock (``fcntl.flock``) held by an open file descriptor, so the
    kernel releases it when its holder exits or is killed: a crashed holder never leaves a
    stale lock behind, and the lock file itself carries no state (its text, the holder's host
    and pid, is for people). ``timeout`` (seconds, None = wait as long as it takes) raises
    TimeoutError naming the lock file. ``log`` is told once if we have to wait.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        t0 = time.monotonic()
        told = False
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if log is not None and not told:
                    holder = path.read_text(errors="replace").strip() or "another process"
                    log(f"{what or path.name}: waiting for {holder} (lock {path})")
                    told = True
                if timeout is not None and time.monotonic() - t0 > timeout:
                    raise TimeoutError(
                        f"{path} stayed locked for more than {timeout:.0f} s; "
                        "the holder is still running (see the file's text)"
                    ) from None
                time.sleep(0.2)
        os.ftruncate(fd, 0)
        os.write(fd, f"host {socket.gethostname()} pid {os.getpid()}\n".encode())
        yield
    finally:
        os.close(fd)  # releases the lock
