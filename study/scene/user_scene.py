"""Scene content from the user's files for the reference and the shader inputs.

The file formats and their validation are in :mod:`study.config.files`, the maths on lat-long
maps in :mod:`study.config.image_maths`; this module turns them into what the Mitsuba scene
and the shader inputs use:

* the sky: :func:`reference_sky` (the lat-long map the reference's ``envmap`` emits: the
  file's map, or the built-in gradient, with the explicit sun disc when there is one),
  :func:`shader_sky` (the shader's cube map: the same sky without the sun) and
  :func:`sun_of` (the shader's light: direction and radiance);
* the mesh above the water: :func:`mesh_shape` (a Mitsuba ``obj`` / ``ply`` shape dict),
  :func:`mesh_bounds` (its world bounding box, checked to lie above the water),
  :func:`dry_camera_height` (the height from which the top-down refraction texture is
  rendered so that the mesh does not hide the pool) and :func:`reflection_extent` (the
  world rectangle of the reflection textures, grown to cover the mesh).

Errors about files are ``ExperimentError`` naming the key and the file.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ..config.errors import ExperimentError, clip_text
from ..config.files import albedo_image, envmap_file
from ..config.image_maths import fill_region, find_sun, latlong_directions, latlong_lookup
from ..config.experiment import Experiment
from .geometry import cubemap_directions, envmap_image, sky_radiance, sun_direction
from .shader_waves import wave_extremes

SKY_HEIGHT = 512  # rows of the built-in gradient sky's lat-long map (0.35 degree texels)
CUBE_SUPERSAMPLE = 4  # lookups per cube-map texel side when resampling a sky file
MESH_CLEARANCE = 0.01  # the mesh stays this far above the highest wave crest (world units)


def has_file(exp: Experiment, key: str) -> bool:
    return exp[key] != ""


# ---- sky and sun ----------------------------------------------------------------------------


def _explicit_sun(exp: Experiment) -> dict:
    return dict(
        sun_dir=sun_direction(exp.sun.elevation, exp.sun.azimuth),
        sun_radius_deg=exp.sun.radius,
        sun_radiance=exp.sun.radiance,
    )


@functools.lru_cache(maxsize=4)
def _file_sky(path: str, sha: str, rotation: float, scale: float) -> tuple[np.ndarray, dict | None]:
    """(map, sun found in it or None) of a sky file (cached on its contents and placement)."""
    sky = envmap_file({"sky.envmap": path, "sky.rotation": rotation, "sky.scale": scale})
    try:
        sun = find_sun(sky)
    except ValueError:
        sun = None
    return sky, sun


def file_sky(exp: Experiment) -> tuple[np.ndarray, dict | None]:
    return _file_sky(
        exp.sky.envmap, exp.digests.get("sky.envmap", ""), exp.sky.rotation, exp.sky.scale
    )


def reference_sky(exp: Experiment) -> np.ndarray:
    """(H, 2H, 3) float32 lat-long radiance for the reference's ``envmap`` (sun included)."""
    if not has_file(exp, "sky.envmap"):
        p = dict(zenith=exp.sky.zenith, horizon=exp.sky.horizon, ground=exp.sky.ground)
        return envmap_image(SKY_HEIGHT, **p, **_explicit_sun(exp))
    sky, _ = file_sky(exp)
    if exp.sun.source == "explicit" and max(exp.sun.radiance) > 0:
        s = _explicit_sun(exp)
        d, _ = latlong_directions(sky.shape[0])
        inside = (d @ s["sun_dir"]) >= math.cos(math.radians(s["sun_radius_deg"]))
        sky = sky + inside[..., None] * np.asarray(s["sun_radiance"], np.float32)
    return np.asarray(sky, np.float32)


def reference_sky_parts(exp: Experiment) -> tuple[np.ndarray, np.ndarray]:
    """The reference's envmap (:func:`reference_sky`) as (sky without the sun, the sun), each
    (H, 2H, 3) float32 linear RGB, non-negative, adding up to it (to float rounding): the sun is
    where the map is brighter than the sky without it (the explicit sun's disc, or the sky file's
    sun region filled from its surroundings); zero everywhere when there is no sun."""
    ref = reference_sky(exp)
    if not has_file(exp, "sky.envmap"):
        p = dict(zenith=exp.sky.zenith, horizon=exp.sky.horizon, ground=exp.sky.ground)
        sky = envmap_image(SKY_HEIGHT, **p)
    else:
        sky, sun = file_sky(exp)
        if exp.sun.source == "envmap" and sun is not None:
            sky = fill_region(sky, sun["mask"])
    sun = np.maximum(ref - np.asarray(sky, np.float32), 0.0).astype(np.float32)
    return (ref - sun).astype(np.float32), sun


def shader_sky(exp: Experiment, d: np.ndarray) -> np.ndarray:
    """Sky radiance (..., 3) without the sun in unit directions d (..., 3) (the cube map's
    content)."""
    if not has_file(exp, "sky.envmap"):
        return sky_radiance(
            d, zenith=exp.sky.zenith, horizon=exp.sky.horizon, ground=exp.sky.ground
        )
    sky, sun = file_sky(exp)
    if exp.sun.source == "envmap":
        sky = fill_region(sky, sun["mask"])
    return latlong_lookup(sky, d)


def shader_cubemap(exp: Experiment, size: int) -> np.ndarray:
    """(6, size, size, 3) float32 cube map of the sky without the sun, stored y-flipped for the
    shader's ``* vec3(1, -1, 1)`` lookup. A sky file is averaged over CUBE_SUPERSAMPLE^2
    directions per texel (the map is usually finer than the cube map)."""
    if not has_file(exp, "sky.envmap"):
        d = cubemap_directions(size) * np.array([1.0, -1.0, 1.0])
        return shader_sky(exp, d).astype(np.float32)
    n = CUBE_SUPERSAMPLE
    fine = cubemap_directions(size * n) * np.array([1.0, -1.0, 1.0])
    rad = shader_sky(exp, fine)
    return rad.reshape(6, size, n, size, n, 3).mean((2, 4)).astype(np.float32)


def sun_of(exp: Experiment) -> tuple[np.ndarray, np.ndarray]:
    """(direction (3,), radiance (3,)) of the sun: explicit, or the sky file's brightest region."""
    if exp.sun.source == "envmap":
        _, sun = file_sky(exp)
        if sun is None:
            raise ExperimentError(
                f'sky.envmap: no sun found in {exp.sky.envmap}; set sun.source = "explicit"'
            )
        return np.asarray(sun["direction"]), np.asarray(sun["radiance"], np.float64)
    s = _explicit_sun(exp)
    return np.asarray(s["sun_dir"]), np.asarray(s["sun_radiance"], np.float64)


def sun_summary(exp: Experiment) -> dict:
    """JSON-able description of the sun the shader gets (for reports)."""
    d, rad = sun_of(exp)
    out = {
        "source": exp.sun.source,
        "direction": [float(v) for v in d],
        "elevation_deg": math.degrees(math.asin(max(-1.0, min(1.0, float(d[1]))))),
        "azimuth_deg": math.degrees(math.atan2(float(d[2]), float(d[0]))),
        "radiance": [float(v) for v in rad],
    }
    if exp.sun.source == "envmap":
        _, sun = file_sky(exp)
        out.update(solid_angle_sr=sun["solid_angle"], radius_deg=sun["radius_deg"])
    return out


# ---- mesh above the water -------------------------------------------------------------------


def mesh_shape(mi, exp: Experiment) -> dict:
    """The mesh as a Mitsuba shape dict (``obj`` or ``ply`` plugin), diffuse."""
    path = exp.mesh.file
    T = mi.ScalarTransform4f
    to_world = (
        T().translate(list(exp.mesh.position))
        @ T().rotate([0.0, 1.0, 0.0], -exp.mesh.rotation)  # Mitsuba turns +x towards -z
        @ T().scale(exp.mesh.scale)
    )
    if has_file(exp, "mesh.texture"):
        tex = {
            "type": "bitmap",
            "bitmap": mi.Bitmap(albedo_image(exp.values, "mesh.texture")),
            "raw": True,
            "filter_type": "bilinear",
        }
        bsdf = {"type": "diffuse", "reflectance": tex}
    else:
        bsdf = {
            "type": "diffuse",
            "reflectance": {"type": "rgb", "value": list(exp.mesh.albedo)},
        }
    return {
        "type": path.rsplit(".", 1)[1].lower(),
        "filename": path,
        "to_world": to_world,
        "bsdf": bsdf,
    }


def _load_mesh(mi, exp: Experiment):
    d = mesh_shape(mi, exp)
    try:
        return mi.load_dict(d)
    except Exception as exc:  # Mitsuba raises RuntimeError with its own message
        raise ExperimentError(
            f"mesh.file: Mitsuba cannot load it ({clip_text(exc, 300)}) (file {exp.mesh.file})"
        ) from exc


def mesh_bounds(mi, exp: Experiment) -> tuple[np.ndarray, np.ndarray]:
    """World bounding box (min (3,), max (3,)) of the placed mesh, checked: loadable, texture
    coordinates when ``mesh.texture`` is given, entirely above the water's highest crest."""
    key = (
        exp.mesh.file,
        exp.digests.get("mesh.file"),
        exp.digests.get("mesh.texture"),
        tuple(exp.mesh.position),
        exp.mesh.scale,
        exp.mesh.rotation,
        wave_extremes(exp),
    )
    if key in _BOUNDS:
        return _BOUNDS[key]
    shape = _load_mesh(mi, exp)
    if has_file(exp, "mesh.texture") and not shape.has_vertex_texcoords():
        raise ExperimentError(
            f"mesh.texture needs texture coordinates, and mesh.file {exp.mesh.file} "
            "has none; give mesh.albedo instead"
        )
    bb = shape.bbox()
    lo = np.array([bb.min.x, bb.min.y, bb.min.z], np.float64).ravel()
    hi = np.array([bb.max.x, bb.max.y, bb.max.z], np.float64).ravel()
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) or shape.face_count() == 0:
        raise ExperimentError(f"mesh.file: no faces or non-finite vertices (file {exp.mesh.file})")
    crest = wave_extremes(exp)[1] + MESH_CLEARANCE
    if lo[1] < crest:
        raise ExperimentError(
            f"mesh.file: the placed mesh reaches down to y = {lo[1]:.4g}, into the water "
            f"(it must stay above y = {crest:.4g}, the highest wave crest plus "
            f"{MESH_CLEARANCE}); raise mesh.position (file {exp.mesh.file})"
        )
    _BOUNDS[key] = (lo, hi)
    return lo, hi


_BOUNDS: dict = {}


def _overlaps(lo, hi, extent) -> bool:
    x0, z0, x1, z1 = extent
    return lo[0] < x1 and hi[0] > x0 and lo[2] < z1 and hi[2] > z0


def dry_camera_height(mi, exp: Experiment, extent) -> float:
    """Height of the orthographic camera of the dry top-down render: 100 (above everything),
    or, when the mesh spans the texture, just below the mesh (it must then clear the walls)."""
    if not has_file(exp, "mesh.file"):
        return 100.0
    lo, hi = mesh_bounds(mi, exp)
    if not _overlaps(lo, hi, extent):
        return 100.0
    top = exp.pool.wall_height
    y = lo[1] - 0.015  # the orthographic sensor's near clip is 0.01
    if y < top + 0.005:
        raise ExperimentError(
            f"mesh.file: over the pool and its walls the mesh must stay above the "
            f"wall tops (pool.wall_height = {top:g}) so that it does not hide them from "
            f"the top-down refraction texture; it reaches down to y = {lo[1]:.4g} "
            f"(file {exp.mesh.file})"
        )
    return float(y)


def reflection_extent(mi, exp: Experiment, extent) -> tuple[float, float, float, float]:
    """World rectangle of the reflection textures: ``extent`` grown to the mesh's footprint."""
    if not has_file(exp, "mesh.file"):
        return tuple(extent)
    lo, hi = mesh_bounds(mi, exp)
    x0, z0, x1, z1 = extent
    return (
        min(x0, float(lo[0])),
        min(z0, float(lo[2])),
        max(x1, float(hi[0])),
        max(z1, float(hi[2])),
    )


def check_scene(exp: Experiment) -> None:
    """Checks that need Mitsuba (the mesh); call after the backend is initialised."""
    if has_file(exp, "mesh.file"):
        import mitsuba as mi

        mesh_bounds(mi, exp)
