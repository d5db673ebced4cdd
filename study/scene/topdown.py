"""The orthographic top-down camera of the shader's textures: its sensor, the conversion of its
renders to GL texel order, the first hit from above (world y), the top-down renders, the
under-water camera's height and its own ray's absorption, and the reflection textures of the
user's mesh. Texel (row, column) = (t, s): z and x increasing, over a world rectangle
``extent = (x0, z0, x1, z1)``."""

from __future__ import annotations

import numpy as np

from .._backend import jit_input
from .._progress import render_in_passes
from ..config.experiment import Experiment
from .mitsuba_scene import build_geometry, floor_of, has_medium, water_medium
from .shader_waves import wave_extremes
from .user_scene import reference_sky, reflection_extent

NO_GEOMETRY = -1e3  # world y of a texel with nothing below it (the shaders' sentinel)
MAX_OPTICAL_DEPTH = 40.0  # exp(40) = 2e17: beyond it the under-water render holds no floor light
ORTHO_NEAR_CLIP = 1e-2  # the top-down camera's rays start this far below it (Mitsuba's near clip)


def texture_extent(exp: Experiment) -> tuple[float, float, float, float]:
    """World rectangle (x0, z0, x1, z1) covered by the top-down textures: the pool and its walls."""
    hx, hz = exp.pool.half_extent
    b = exp.pool.wall_width
    return (-hx - b, -hz - b, hx + b, hz + b)


def ortho_sensor(
    mi,
    extent,
    size: int,
    spp: int,
    seed: int,
    y_cam: float = 100.0,
    medium=None,
    sampler: str = "independent",
):
    """Mitsuba orthographic sensor looking straight down from ``y_cam`` over ``extent``, a
    ``size`` x ``size`` linear-RGB film with a box filter, ``spp`` samples of ``sampler`` seeded
    with ``seed``, inside ``medium`` if given (the under-water camera)."""
    x0, z0, x1, z1 = extent
    cx, cz = (x0 + x1) / 2, (z0 + z1) / 2
    T = mi.ScalarTransform4f
    d = {
        "type": "orthographic",
        "to_world": T().look_at(origin=[cx, y_cam, cz], target=[cx, y_cam - 1.0, cz], up=[0, 0, 1])
        @ T().scale([(x1 - x0) / 2, (z1 - z0) / 2, 1.0]),
        "near_clip": ORTHO_NEAR_CLIP,
        "sampler": {"type": sampler, "seed": seed},
        "film": {
            "type": "hdrfilm",
            "width": size,
            "height": size,
            "pixel_format": "rgb",
            "rfilter": {"type": "box"},
        },
    }
    if medium is not None:
        d["medium"] = medium
    return mi.load_dict(d)


def camera_ray_top(y_cam: float) -> float:
    """Height where the rays of a top-down camera at ``y_cam`` start (its near clip plane): the
    under-water camera's own ray through the water runs from there to the floor."""
    return y_cam - ORTHO_NEAR_CLIP


def camera_ray_optical_depth(exp: Experiment, y_cam: float, world_y: np.ndarray) -> np.ndarray:
    """(..., 3) optical depth ``sigma_t (y_top - world_y)`` of the under-water camera's own vertical
    ray, from where it starts (:func:`camera_ray_top`) down to the surface at ``world_y`` (...);
    ``exp`` of it divides that ray's absorption out of a top-down render."""
    sigma = np.asarray(exp.water.sigma_t, np.float64)
    return sigma * np.maximum(camera_ray_top(y_cam) - world_y, 0.0)[..., None]


def to_gl_order(mi, sensor, img: np.ndarray, extent) -> np.ndarray:
    """Reorder an orthographic render so that row = t (z increasing), column = s (x increasing),
    checking the sensor's own pixel-to-world map instead of assuming it."""
    h, w = img.shape[:2]
    probe = [(0.5 / w, 0.5 / h), ((w - 0.5) / w, 0.5 / h), (0.5 / w, (h - 0.5) / h)]
    o = []
    for u, v in probe:
        ray, _ = sensor.sample_ray(0.0, 0.0, mi.Point2f(u, v), mi.Point2f(0.5, 0.5))
        o.append(np.array(ray.o).ravel())
    dcol, drow = o[1] - o[0], o[2] - o[0]
    if abs(dcol[1]) > 1e-6 or abs(drow[1]) > 1e-6:
        raise RuntimeError("orthographic sensor is not looking straight down")
    if abs(dcol[0]) > abs(dcol[2]):  # columns run along x
        if dcol[0] < 0:
            img = img[:, ::-1]
        if drow[2] < 0:
            img = img[::-1]
    else:  # columns run along z: transpose
        img = np.swapaxes(img, 0, 1)
        if dcol[2] < 0:
            img = img[::-1]
        if drow[0] < 0:
            img = img[:, ::-1]
    return np.ascontiguousarray(img)


def top_down_world_y(exp: Experiment, extent, size: int, mesh: bool = False) -> np.ndarray:
    """(size, size) float32 world y of the first hit from above at texel centres (GL order);
    the user's mesh above the water is left out unless ``mesh``."""
    import mitsuba as mi

    scene = mi.load_dict({"type": "scene", **build_geometry(mi, exp, water=False, mesh=mesh)})
    x0, z0, x1, z1 = extent
    c = (np.arange(size) + 0.5) / size
    X, Z = np.meshgrid(x0 + c * (x1 - x0), z0 + c * (z1 - z0))
    n = X.size

    def cast(dx: float, dz: float):
        o = mi.Point3f(
            jit_input(mi.Float, (X.ravel() + dx).astype(np.float32)),
            jit_input(mi.Float, np.full(n, 100.0)),
            jit_input(mi.Float, (Z.ravel() + dz).astype(np.float32)),
        )
        si = scene.ray_intersect(mi.Ray3f(o, mi.Vector3f(0.0, -1.0, 0.0)))
        return np.array(si.is_valid()), np.array(si.p.y, dtype=np.float32)

    # A ray exactly on a shared triangle edge can slip through (the intersector is not
    # watertight in float32): such texels are cast again a hair (1e-4 units) off-centre.
    valid, y = cast(0.0, 0.0)
    valid2, y2 = cast(1e-4, 0.7e-4)
    y = np.where(valid, y, np.where(valid2, y2, NO_GEOMETRY))
    return y.astype(np.float32).reshape(size, size)


def render_top_down(
    mi,
    exp: Experiment,
    extent,
    size: int,
    spp: int,
    seed: int,
    *,
    water: bool,
    y_cam: float = 100.0,
    progress=None,
) -> np.ndarray:
    medium = water_medium(mi, exp) if water else None
    d = {
        "type": "scene",
        **build_geometry(mi, exp, water=water, medium=medium),
        "sky": {"type": "envmap", "bitmap": mi.Bitmap(reference_sky(exp))},
        "integrator": {
            "type": "volpath" if water and has_medium(exp) else "path",
            "max_depth": exp.reference.max_depth,
        },
    }
    scene = mi.load_dict(d)
    sensor = ortho_sensor(mi, extent, size, spp, seed, y_cam=y_cam, medium=medium)

    img = render_in_passes(mi, scene, sensor, spp, seed, progress)
    return to_gl_order(mi, sensor, img, extent)


def underwater_camera_height(exp: Experiment) -> float:
    """Height of the under-water orthographic camera: below the lowest wave trough, above the
    floor."""
    y_cam = wave_extremes(exp)[0] - 0.02
    hx, hz = exp.pool.half_extent
    x, z = np.meshgrid(np.linspace(-hx, hx, 129), np.linspace(-hz, hz, 129))
    top = float(floor_of(exp, x, z).max())
    if top >= y_cam - 0.01:
        raise ValueError(
            f"the floor rises to y = {top:.3f}, above the wave troughs (y = {y_cam + 0.02:.3f}): "
            "make floor.depth larger or floor.relief / the waves smaller, or set "
            'reference.refraction_lighting = "dry"'
        )
    return y_cam


def mesh_reflection_textures(exp: Experiment, extent, size: int, progress=None):
    """The reflection textures with the user's mesh: ``(refl_world_y (size, size) float32,
    refl_texture (size, size, 3) float32, extent)`` over :func:`reflection_extent`. As for
    the walls, the geometry above the water is taken as a height field: world y of the first
    hit from above (walls and mesh) where it is above the water (else the sentinel
    ``NO_GEOMETRY``), coloured by the dry top-down render (sun and sky, mesh included)."""
    import mitsuba as mi

    ext = reflection_extent(mi, exp, extent)
    world_y = top_down_world_y(exp, ext, size, mesh=True)
    colour = render_top_down(
        mi,
        exp,
        ext,
        size,
        exp.reference.texture_spp,
        exp.reference.seed,
        water=False,
        progress=progress,
    )
    above = world_y > 0.0
    refl_y = np.where(above, world_y, NO_GEOMETRY).astype(np.float32)
    refl_col = np.where(above[..., None], colour, 0.0).astype(np.float32)
    return refl_y, refl_col, ext
