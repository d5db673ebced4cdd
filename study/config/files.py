"""The user's own scene files: floor heightmap, floor albedo image, HDR sky, a mesh above the water.

Every file key of the experiment (``FILE_KEYS``) names a file; ``""`` means none (the
built-in floor shape, tiles, gradient sky, no mesh). This module reads and validates them
and is the one place that knows their formats; the scene modules ask it for arrays.

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
  is the map's brightest region (:func:`find_sun`): the reference keeps the map as it is,
  the shader gets the region as its light and the map with the region filled in as its
  cube map. With ``sun.source = "explicit"`` the ``sun.*`` disc is added to the map.
* ``mesh.file``: an OBJ or PLY mesh loaded by Mitsuba's ``obj`` / ``ply`` shape plugins,
  placed by ``mesh.scale``, then ``mesh.rotation`` (degrees about +y, from +x towards +z),
  then ``mesh.position``; diffuse with ``mesh.albedo`` or the image ``mesh.texture``
  (needs texture coordinates). It must lie entirely above the water.

Errors are :class:`~study.config.experiment.ExperimentError` naming the key and the file.
"""

from __future__ import annotations

import functools
import hashlib
import math
from pathlib import Path

import numpy as np

from .errors import ExperimentError

FILE_KEYS = ("floor.heightmap", "floor.albedo_image", "sky.envmap", "mesh.file", "mesh.texture")
IMAGE_EXT = (".exr", ".png", ".jpg", ".jpeg")
MESH_EXT = (".obj", ".ply")
MAX_TEXELS = 4096 * 4096
SUN_THRESHOLD = 0.1  # the sun region: texels brighter than this fraction of the brightest one
SUN_CONTRAST = 20.0  # ... whose brightest texel is this many times the median, or no sun


def _error(key: str, path, msg: str):
    return ExperimentError(f"{key}: {msg} (file {path})")


def clip_text(text: str, limit: int = 80) -> str:
    """``text`` cut to ``limit`` characters with the number of characters left out."""
    text = str(text)
    return (
        text if len(text) <= limit else f"{text[:limit]}... ({len(text) - limit} more characters)"
    )


def clip_path(path, limit: int = 240) -> str:
    """A path cut to its last ``limit`` characters (the file's name stays whole), marked."""
    text = str(path)
    return text if len(text) <= limit else f"...{text[-limit:]}"


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


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


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
    # turn about +y: u -> u + rotation / 360 (periodic linear interpolation along u)
    shift = (values["sky.rotation"] / 360.0) * w
    src = (np.arange(w) - shift) % w
    i0 = np.floor(src).astype(int)
    f = (src - i0)[None, :, None]
    rgb = (1 - f) * rgb[:, i0] + f * rgb[:, (i0 + 1) % w]
    return (rgb * values["sky.scale"]).astype(np.float32)


# ---- lat-long geometry ----------------------------------------------------------------------


def latlong_directions(h: int) -> tuple[np.ndarray, np.ndarray]:
    """(h, 2h, 3) unit directions of the texel centres of a lat-long map (Mitsuba's envmap
    convention) and (h, 2h) their solid angles (steradians)."""
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(2 * h) + 0.5) / (2 * h)
    th, ph = np.meshgrid(v * np.pi, u * 2 * np.pi, indexing="ij")
    d = np.stack([np.sin(th) * np.sin(ph), np.cos(th), -np.sin(th) * np.cos(ph)], -1)
    edges = np.arange(h + 1) / h * np.pi
    band = (np.cos(edges[:-1]) - np.cos(edges[1:])) * (2 * np.pi / (2 * h))
    return d, np.repeat(band[:, None], 2 * h, 1)


def latlong_lookup(img: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Bilinear lookup of a lat-long image (H, 2H, C) in unit directions d (..., 3)."""
    h, w = img.shape[:2]
    u = (np.arctan2(d[..., 0], -d[..., 2]) / (2 * np.pi)) % 1.0
    v = np.arccos(np.clip(d[..., 1], -1, 1)) / np.pi
    x, y = u * w - 0.5, np.clip(v * h - 0.5, 0, h - 1)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    y1 = np.minimum(y0 + 1, h - 1)
    x0w, x1w = x0 % w, (x0 + 1) % w
    return (1 - fy) * ((1 - fx) * img[y0, x0w] + fx * img[y0, x1w]) + fy * (
        (1 - fx) * img[y1, x0w] + fx * img[y1, x1w]
    )


def find_sun(img: np.ndarray) -> dict:
    """The brightest region of a lat-long radiance map (H, 2H, 3): the texels brighter than
    ``SUN_THRESHOLD`` x the brightest one and connected to it (wrapping in u). Returns
    ``direction`` (3,) (radiance-weighted mean), ``solid_angle`` (sr), ``radiance`` (3,)
    (mean over the region, linear RGB), ``radius_deg`` (of the disc of that solid angle),
    ``mask`` (H, 2H) bool. Raises ValueError when no texel stands out (the brightest is less
    than ``SUN_CONTRAST`` x the median)."""
    from scipy import ndimage

    h, w = img.shape[:2]
    lum = img @ np.array([0.2126, 0.7152, 0.0722])
    peak = float(lum.max())
    med = float(np.median(lum))
    if peak <= 0 or peak < SUN_CONTRAST * med:
        raise ValueError(
            f"no sun in the map: its brightest texel is {peak / max(med, 1e-30):.3g} x the "
            f"median (at least {SUN_CONTRAST:g} x needed)"
        )
    r, c = np.unravel_index(int(np.argmax(lum)), lum.shape)
    shift = w // 2 - c  # centre the peak so the region does not wrap
    rolled = np.roll(lum, shift, axis=1)
    labels, _ = ndimage.label(rolled >= SUN_THRESHOLD * peak)
    mask = np.roll(labels == labels[r, w // 2], -shift, axis=1)
    d, omega = latlong_directions(h)
    wgt = omega[mask] * lum[mask]
    direction = (d[mask] * wgt[:, None]).sum(0)
    direction /= np.linalg.norm(direction)
    solid = float(omega[mask].sum())
    radiance = (img[mask] * omega[mask][:, None]).sum(0) / solid
    radius = math.degrees(math.acos(max(-1.0, 1 - solid / (2 * np.pi))))
    return {
        "direction": direction,
        "solid_angle": solid,
        "radiance": radiance,
        "radius_deg": radius,
        "mask": mask,
    }


def fill_region(img: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``img`` with the texels of ``mask`` (grown by one texel) set to the mean of the ring of
    texels around them: the sky without its sun."""
    from scipy import ndimage

    grown = ndimage.binary_dilation(mask, iterations=1)
    ring = ndimage.binary_dilation(grown, iterations=2) & ~grown
    out = img.copy()
    out[grown] = img[ring].mean(0) if ring.any() else 0.0
    return out


# ---- world rectangles -----------------------------------------------------------------------


def floor_extent(values: dict) -> tuple[float, float, float, float]:
    """(x0, z0, x1, z1) covered by the floor images (``floor.extent``, or the pool's rectangle)."""
    e = values["floor.extent"]
    if e == "pool":
        hx, hz = values["pool.half_extent"]
        return (-hx, -hz, hx, hz)
    return tuple(float(v) for v in e)


def sample_rect(img: np.ndarray, extent, x, z) -> np.ndarray:
    """Bilinear lookup (clamped) of an image (H, W, C) covering ``extent`` at world (x, z)."""
    x0, z0, x1, z1 = extent
    h, w = img.shape[:2]
    fx = np.clip((np.asarray(x, np.float64) - x0) / (x1 - x0) * w - 0.5, 0, w - 1)
    fz = np.clip((np.asarray(z, np.float64) - z0) / (z1 - z0) * h - 0.5, 0, h - 1)
    i0, j0 = np.floor(fx).astype(int), np.floor(fz).astype(int)
    i1, j1 = np.minimum(i0 + 1, w - 1), np.minimum(j0 + 1, h - 1)
    ax, az = (fx - i0)[..., None], (fz - j0)[..., None]
    return (1 - az) * ((1 - ax) * img[j0, i0] + ax * img[j0, i1]) + az * (
        (1 - ax) * img[j1, i0] + ax * img[j1, i1]
    )


def heightmap_floor(values: dict, x, z) -> np.ndarray:
    """World y of a heightmap floor at (x, z)."""
    hm = heightmap(values)[..., None]
    return (
        -values["floor.depth"]
        + values["floor.height_scale"] * sample_rect(hm, floor_extent(values), x, z)[..., 0]
    )


def albedo_over_pool(values: dict, max_size: int = 2048) -> np.ndarray:
    """(N, M, 3) float32 floor albedo over the pool rectangle (row = z, column = x), resampled
    from ``floor.albedo_image`` at (at most) its own texel density."""
    img = albedo_image(values)
    x0, z0, x1, z1 = floor_extent(values)
    hx, hz = values["pool.half_extent"]
    nx = int(np.clip(round(img.shape[1] * 2 * hx / (x1 - x0)), 8, max_size))
    nz = int(np.clip(round(img.shape[0] * 2 * hz / (z1 - z0)), 8, max_size))
    x = -hx + (np.arange(nx) + 0.5) / nx * 2 * hx
    z = -hz + (np.arange(nz) + 0.5) / nz * 2 * hz
    X, Z = np.meshgrid(x, z)
    return sample_rect(img, (x0, z0, x1, z1), X, Z).astype(np.float32)


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
