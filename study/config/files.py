"""The user's own scene files: floor heightmap, floor albedo image, HDR sky, a mesh above the water.

Every file key of the experiment (``FILE_KEYS``) names a file; ``""`` means none (the
built-in floor shape, tiles, gradient sky, no mesh). This module reads and validates them
and is the one place that knows their formats; the scene modules ask it for arrays. The maths
on those arrays is :mod:`~.image_maths`'s; the floor the heightmap and albedo image describe
is :mod:`~.floor`'s.

Files and conventions (world units, ``+y`` up, water plane at ``y = 0``):

* ``floor.heightmap``: a single-channel EXR (float texels, any channel name) or a 16-bit
  greyscale PNG (texels / 65535). It covers the world rectangle ``floor.extent``
  ``[x0, z0, x1, z1]``: columns run along x from x0 to x1, rows along z from z0 (row 0) to
  z1, texel centres at the cell centres, sampled bilinearly (clamped at the border). The
  floor is at ``y = -floor.depth + floor.height_scale * texel``.
* ``floor.albedo_image``: an sRGB PNG/JPEG (8-bit, decoded to linear) or a linear RGB EXR,
  albedo in [0, 1], over the same rectangle in the same orientation.
* ``sky.envmap``: a lat-long RGB EXR of radiance (linear), width = 2 x height, in
  Mitsuba's ``envmap`` convention (u = atan2(x, -z) / 2pi, v = acos(y) / pi, row 0 at the
  zenith), turned about +y by ``sky.rotation`` degrees (from +x towards +z, as
  ``sun.azimuth``) and multiplied by ``sky.scale``. With ``sun.source = "envmap"`` the sun
  is the map's brightest region (:func:`~.image_maths.find_sun`): the reference keeps the map
  as it is, the shader gets the region as its light and the map with the region filled in as
  its cube map. With ``sun.source = "explicit"`` the ``sun.*`` disc is added to the map.
* ``mesh.file``: an OBJ or PLY mesh loaded by Mitsuba's ``obj`` / ``ply`` shape plugins,
  placed by ``mesh.scale``, then ``mesh.rotation`` (degrees about +y, from +x towards +z),
  then ``mesh.position``; diffuse with ``mesh.albedo`` or the image ``mesh.texture``
  (needs texture coordinates). It must lie entirely above the water.

Errors are :class:`~study.config.errors.ExperimentError` naming the key and the file.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

import numpy as np

from .errors import ExperimentError, clip_path, clip_text
from .image_maths import find_sun, srgb_to_linear, turn_latlong

FILE_KEYS = ("floor.heightmap", "floor.albedo_image", "sky.envmap", "mesh.file", "mesh.texture")
IMAGE_EXT = (".exr", ".png", ".jpg", ".jpeg")
MESH_EXT = (".obj", ".ply")
MAX_TEXELS = 4096 * 4096


def _error(key: str, path, msg: str):
    return ExperimentError(f"{key}: {msg} (file {path})")


def resolve(key: str, value: str, base: Path | None) -> str:
    """Absolute path of a file key's value (relative to ``base``), or "" for none; checks it
    exists."""
    if value == "":
        return ""
    p = Path(value).expanduser()
    if not p.is_absolute():
        p = (base or Path.cwd()) / p
    ext = MESH_EXT if key == "mesh.file" else IMAGE_EXT
    if p.suffix.lower() not in ext:
        raise _error(key, clip_path(p), f"expected a {', '.join(ext)} file")
    try:
        p = p.resolve()
        found = p.is_file()
    except OSError as exc:  # e.g. a name longer than the file system allows
        raise _error(key, clip_path(p), f"not a usable path ({exc.strerror})") from None
    if not found:
        raise _error(key, clip_path(p), "no such file")
    return str(p)


def digest(path: str) -> str:
    """SHA-256 of a file's contents."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


# ---- images ---------------------------------------------------------------------------------


@functools.lru_cache(maxsize=16)
def _read_image(key: str, path: str, sha: str) -> np.ndarray:
    """(H, W, C) float32 texels of an EXR (as stored) or PNG/JPEG (8-bit / 255, 16-bit / 65535,
    still sRGB-encoded); ``sha`` keys the cache on the contents."""
    suffix = Path(path).suffix.lower()
    try:
        if suffix == ".exr":
            import OpenEXR

            with OpenEXR.File(path) as f:
                ch = {k: np.array(v.pixels, dtype=np.float32) for k, v in f.channels().items()}
            if len(ch) == 1:
                img = next(iter(ch.values()))
            elif "RGB" in ch or "RGBA" in ch:
                img = ch.get("RGB", ch.get("RGBA"))
            else:
                raise _error(
                    key,
                    path,
                    f"unexpected EXR channels {clip_text(sorted(ch))}; write one channel, or RGB",
                )
        else:
            from PIL import Image

            with Image.open(path) as im:
                im.load()
                mode = im.mode
                if mode in ("I;16", "I;16B", "I;16L"):
                    img = np.array(im, dtype=np.uint16).astype(np.float32) / 65535.0
                elif mode in ("L", "RGB", "RGBA", "LA"):
                    img = np.array(im, dtype=np.uint8).astype(np.float32) / 255.0
                elif mode == "P":
                    img = np.array(im.convert("RGB"), dtype=np.uint8).astype(np.float32) / 255.0
                else:
                    raise _error(key, path, f"unsupported image mode {mode!r}")
                if mode in ("I;16", "I;16B", "I;16L"):
                    img = img[..., None]
                elif mode == "L":
                    img = img[..., None]
                img = img.reshape(img.shape[0], img.shape[1], -1)
    except Exception as exc:
        if isinstance(exc, ExperimentError):
            raise
        raise _error(key, path, f"not a readable image ({clip_text(exc)})") from exc
    img = np.asarray(img, np.float32)
    if img.ndim == 2:
        img = img[..., None]
    if img.shape[0] < 2 or img.shape[1] < 2 or img.shape[0] * img.shape[1] > MAX_TEXELS:
        raise _error(
            key,
            path,
            f"image of {img.shape[1]}x{img.shape[0]} texels; expected 2x2 to {MAX_TEXELS} texels",
        )
    if not np.all(np.isfinite(img)):
        raise _error(key, path, f"{int((~np.isfinite(img)).sum())} texels are NaN or infinite")
    return img


def _is_8bit_png(path: str) -> bool:
    if Path(path).suffix.lower() != ".png":
        return False
    from PIL import Image

    with Image.open(path) as im:
        return im.mode in ("L", "LA", "RGB", "RGBA", "P")


def heightmap(values: dict) -> np.ndarray:
    """(H, W) float64 heightmap texels of ``floor.heightmap`` (unscaled)."""
    key, path = "floor.heightmap", values["floor.heightmap"]
    img = _read_image(key, path, digest(path))
    if img.shape[2] != 1:
        raise _error(key, path, f"expected one channel (a height), got {img.shape[2]}")
    if _is_8bit_png(path):
        raise _error(
            key, path, "an 8-bit PNG has 256 height levels (terraces); write a 16-bit PNG or an EXR"
        )
    return img[..., 0].astype(np.float64)


def albedo_image(values: dict, key: str = "floor.albedo_image") -> np.ndarray:
    """(H, W, 3) float32 linear albedo in [0, 1] of an image key (PNG/JPEG sRGB, EXR linear)."""
    path = values[key]
    img = _read_image(key, path, digest(path))
    if img.shape[2] not in (1, 3, 4):
        raise _error(key, path, f"expected 1, 3 or 4 channels, got {img.shape[2]}")
    rgb = np.repeat(img, 3, 2) if img.shape[2] == 1 else img[..., :3]
    if Path(path).suffix.lower() != ".exr":
        rgb = srgb_to_linear(rgb.astype(np.float64))
    lo, hi = float(rgb.min()), float(rgb.max())
    if lo < 0 or hi > 1:
        raise _error(
            key, path, f"albedo texels span [{lo:.4g}, {hi:.4g}]; an albedo lies in [0, 1]"
        )
    return np.asarray(rgb, np.float32)


def envmap_file(values: dict) -> np.ndarray:
    """(H, 2H, 3) float32 radiance of ``sky.envmap``, turned by ``sky.rotation``, times
    ``sky.scale``."""
    key, path = "sky.envmap", values["sky.envmap"]
    if Path(path).suffix.lower() != ".exr":
        raise _error(key, path, "an HDR sky must be an EXR file (linear radiance)")
    img = _read_image(key, path, digest(path))
    if img.shape[2] not in (3, 4):
        raise _error(key, path, f"expected RGB, got {img.shape[2]} channel(s)")
    h, w = img.shape[:2]
    if w != 2 * h:
        raise _error(key, path, f"a lat-long map is twice as wide as high; got {w}x{h}")
    rgb = img[..., :3].astype(np.float64)
    if rgb.min() < 0:
        raise _error(key, path, f"{int((rgb < 0).sum())} texels are negative; radiance is >= 0")
    rgb = turn_latlong(rgb, values["sky.rotation"])
    return (rgb * values["sky.scale"]).astype(np.float32)


def floor_extent(values: dict) -> tuple[float, float, float, float]:
    """(x0, z0, x1, z1) covered by the floor images (``floor.extent``, or the pool's rectangle)."""
    e = values["floor.extent"]
    if e == "pool":
        hx, hz = values["pool.half_extent"]
        return (-hx, -hz, hx, hz)
    return tuple(float(v) for v in e)


# ---- validation -----------------------------------------------------------------------------


def _covers(key: str, path, extent, values) -> None:
    hx, hz = values["pool.half_extent"]
    x0, z0, x1, z1 = extent
    if not (x0 <= -hx and z0 <= -hz and x1 >= hx and z1 >= hz):
        raise _error(
            key,
            path,
            f"floor.extent {list(extent)} does not cover the water "
            f"[{-hx:g}, {-hz:g}, {hx:g}, {hz:g}]; widen floor.extent or shrink "
            "pool.half_extent",
        )


def check_files(values: dict) -> dict:
    """Validate every file key of a validated experiment's ``values`` (paths already resolved by
    :func:`resolve`) and the keys that go with them; return ``{key: sha256}`` of the files given."""
    has = {k: values[k] != "" for k in FILE_KEYS}
    if values["floor.shape"] == "heightmap" and not has["floor.heightmap"]:
        raise ExperimentError(
            'floor.shape = "heightmap" needs floor.heightmap (a single-channel EXR or 16-bit PNG)'
        )
    if has["floor.heightmap"] and values["floor.shape"] != "heightmap":
        raise ExperimentError(
            f"floor.heightmap is given ({values['floor.heightmap']}) but floor.shape is "
            f'{values["floor.shape"]!r}; set floor.shape = "heightmap" (or remove '
            "floor.heightmap)"
        )
    if values["sun.source"] == "envmap" and not has["sky.envmap"]:
        raise ExperimentError(
            'sun.source = "envmap" needs sky.envmap (the sun is taken from the map)'
        )
    if has["mesh.texture"] and not has["mesh.file"]:
        raise ExperimentError(f"mesh.texture is given ({values['mesh.texture']}) without mesh.file")
    e = values["floor.extent"]
    if e != "pool" and not (e[2] > e[0] and e[3] > e[1]):
        raise ExperimentError(
            f"floor.extent {e}: expected [x0, z0, x1, z1] with x1 > x0 and z1 > z0"
        )
    if has["floor.heightmap"]:
        heightmap(values)
        _covers("floor.heightmap", values["floor.heightmap"], floor_extent(values), values)
    if has["floor.albedo_image"]:
        albedo_image(values)
        _covers("floor.albedo_image", values["floor.albedo_image"], floor_extent(values), values)
    if has["sky.envmap"]:
        sky = envmap_file(values)
        if values["sun.source"] == "envmap":
            try:
                find_sun(sky)
            except ValueError as exc:
                raise _error(
                    "sky.envmap",
                    values["sky.envmap"],
                    f'{exc}; give the sun explicitly (sun.source = "explicit")',
                ) from exc
        elif max(values["sun.radiance"]) > 0:
            texel = 180.0 / sky.shape[0]
            if values["sun.radius"] < texel:
                raise ExperimentError(
                    f"sun.radius = {values['sun.radius']:g} degrees is below one texel "
                    f"({texel:.3g} degrees) of sky.envmap {values['sky.envmap']}; make the "
                    "sun larger or the map finer"
                )
    if has["mesh.texture"]:
        albedo_image(values, "mesh.texture")
    if has["mesh.file"]:
        path = values["mesh.file"]
        try:
            with open(path, "rb") as f:
                head = f.read(4096)
        except OSError as exc:
            raise _error("mesh.file", path, f"not readable ({exc})") from exc
        if path.lower().endswith(".ply") and not head.startswith(b"ply"):
            raise _error("mesh.file", path, "not a PLY file (it does not start with 'ply')")
        if not head.strip():
            raise _error("mesh.file", path, "the file is empty")
    return {k: digest(values[k]) for k in FILE_KEYS if has[k]}
