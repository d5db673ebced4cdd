"""The Mitsuba 3 scene of an experiment: physically modelled water in a tiled pool.

* Pool floor: a triangle mesh of ``floor_height`` with a diffuse tile texture.
* Walls: four diffuse boxes around the pool rising ``pool.wall_height`` above the water.
* Ledge (``floor.ledge``, optional): a diffuse box under water spanning the pool in z; the floor
  under it is hidden from the top-down textures the shader raycasts (depth complexity 2).
* Water: one closed triangle mesh (a smooth dielectric, ``water.ior`` inside, 1.0
  outside) bounding a homogeneous medium (``water.sigma_t``, ``water.albedo``). Its top is
  the wave surface ``H(x, z)`` displaced for real, with analytic vertex normals; its
  sides and bottom close the volume just inside the walls and below the floor, so the floor
  lies inside the medium. The waves are geometry, not a normal-mapped flat BSDF, because
  a normal map on a dielectric bounding a medium breaks reciprocity and does not move
  the interface; the displaced mesh refracts exactly where the real surface is.
* Mesh above the water: the user's OBJ/PLY (``mesh.file``, see ``study.config.files``), diffuse.
* Floor from files: ``floor.heightmap`` and ``floor.albedo_image`` (see ``study.config.files``).
* Sky and sun: one lat-long ``envmap`` (gradient sky, ground, sun disc; or the user's HDR
  map, ``user_scene.reference_sky``). The sun is an
  area of the environment, not a delta light: a delta light never reaches the floor
  through a smooth dielectric. Its caustics are sampled by BSDF sampling only; the
  reference noise is measured, not assumed (see ``_reference``).
* Integrator: ``volpath`` when the water absorbs or scatters, else ``path``.

Nothing here sets the Mitsuba variant; call ``study._backend.init_backend`` first.
"""

from __future__ import annotations

import math

import numpy as np

from shaders_port import perspective_view_proj

from ..config.experiment import Experiment
from ..config.floor import albedo_over_pool, floor_height, heightmap_floor
from .geometry import Waves, sun_direction
from .shader_waves import ShaderWaves, shader_waves
from .user_scene import mesh_bounds, mesh_shape, reference_sky

WATER_INSET = 1e-3  # the water volume stays this far inside the walls (no coincident faces)
LEDGE_GAP = 0.02  # the ends of an under-water ledge stay this far from the walls (and the
# water volume's sides), so no faces intersect


def study_waves(exp: Experiment) -> Waves:
    """The study's height field of ``exp`` (``geometry.Waves``): its normal map is the shader's
    ``normalMap`` whatever makes the reference's surface."""
    w = exp.section("waves")
    return Waves(
        w["amplitude"], w["normal_tile"], w["components"], w["seed"], w["offsets"], w["slope_scale"]
    )


def waves_of(exp: Experiment) -> Waves | ShaderWaves:
    """The reference's water surface: the study's waves, or with ``waves.source = "shader"``
    the surface of the shader's normals (``shader_waves``); both answer
    ``height_and_gradient(x, z)``."""
    if exp.waves.source == "shader":
        return shader_waves(exp)
    return study_waves(exp)


def floor_of(exp: Experiment, x, z) -> np.ndarray:
    f = exp.section("floor")
    if f["shape"] == "heightmap":
        return heightmap_floor(exp.values, x, z)
    return floor_height(
        f["shape"], f["depth"], f["relief"], f["steps"], f["seed"], exp.pool.half_extent, x, z
    )


def sky_params(exp: Experiment, with_sun: bool = True) -> dict:
    p = dict(zenith=exp.sky.zenith, horizon=exp.sky.horizon, ground=exp.sky.ground)
    if with_sun:
        p.update(
            sun_dir=sun_direction(exp.sun.elevation, exp.sun.azimuth),
            sun_radius_deg=exp.sun.radius,
            sun_radiance=exp.sun.radiance,
        )
    return p


def camera_view_proj(exp: Experiment, width: int, height: int) -> np.ndarray:
    c = exp.section("camera")
    return perspective_view_proj(
        c["position"], c["target"], fov_y_deg=c["fov_y"], aspect=width / height
    )


def floor_bottom(exp: Experiment) -> float:
    hx, hz = exp.pool.half_extent
    x, z = np.meshgrid(np.linspace(-hx, hx, 129), np.linspace(-hz, hz, 129))
    return float(floor_of(exp, x, z).min()) - 0.1


def _mesh(mi, name, positions, faces, normals=None, uv=None, outward=None, **props_in):
    """A Mitsuba mesh from (V, 3) positions and (F, 3) faces; faces whose geometric normal
    points against ``outward`` (a (F, 3) array or a callable of centroids) are flipped."""
    positions = np.asarray(positions, np.float32)
    faces = _oriented(positions, faces, outward)
    props = mi.Properties()
    for k, v in props_in.items():
        props[k] = v
    m = mi.Mesh(
        name,
        len(positions),
        len(faces),
        props=props,
        has_vertex_normals=normals is not None,
        has_vertex_texcoords=uv is not None,
    )
    params = mi.traverse(m)
    params["vertex_positions"] = positions.ravel()
    params["faces"] = faces.ravel()
    if normals is not None:
        params["vertex_normals"] = np.asarray(normals, np.float32).ravel()
    if uv is not None:
        params["vertex_texcoords"] = np.asarray(uv, np.float32).ravel()
    params.update()
    return m


def _oriented(positions: np.ndarray, faces, outward) -> np.ndarray:
    """(F, 3) uint32 ``faces`` of the float32 ``positions``, those whose geometric normal points
    against ``outward`` (a (F, 3) array or a callable of centroids; None: none) flipped."""
    faces = np.asarray(faces, np.uint32).copy()
    if outward is not None:
        p = positions[faces]
        n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        want = outward(p.mean(1)) if callable(outward) else outward
        flip = (n * want).sum(-1) < 0
        faces[flip] = faces[flip][:, [0, 2, 1]]
    return faces


def _grid_faces(nx: int, nz: int) -> np.ndarray:
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(nz - 1), indexing="ij")
    v00 = (j * nx + i).ravel()
    v10, v01, v11 = v00 + 1, v00 + nx, v00 + nx + 1
    return np.concatenate([np.stack([v00, v01, v10], 1), np.stack([v10, v01, v11], 1)])


def tile_texture(exp: Experiment, px_per_tile: int = 32) -> np.ndarray:
    """(N, N, 3) float32 albedo of the floor over [-hx, hx] x [-hz, hz] (row = z, column = x):
    the tiles, or ``floor.albedo_image`` resampled."""
    f = exp.section("floor")
    if f["albedo_image"]:
        return albedo_over_pool(exp.values)
    hx, hz = exp.pool.half_extent
    nx = max(8, int(round(2 * hx / f["tile_size"] * px_per_tile)))
    nz = max(8, int(round(2 * hz / f["tile_size"] * px_per_tile)))
    nx, nz = min(nx, 2048), min(nz, 2048)
    x = -hx + (np.arange(nx) + 0.5) / nx * 2 * hx
    z = -hz + (np.arange(nz) + 0.5) / nz * 2 * hz
    X, Z = np.meshgrid(x, z)
    ix, iz = np.floor(X / f["tile_size"]), np.floor(Z / f["tile_size"])
    dark = ((ix + iz) % 2 == 1)[..., None]
    col = np.where(dark, np.asarray(f["tile_albedo2"]), np.asarray(f["tile_albedo"]))
    fx, fz = X / f["tile_size"] - ix, Z / f["tile_size"] - iz
    grout = ((np.minimum(fx, 1 - fx) < 0.04) | (np.minimum(fz, 1 - fz) < 0.04))[..., None]
    return np.where(grout, 0.5 * col, col).astype(np.float32)


def build_geometry(
    mi,
    exp: Experiment,
    water: bool = True,
    medium=None,
    mesh: bool = True,
    water_bsdf: dict | None = None,
) -> dict:
    """Shapes of the scene as a dict for ``mi.load_dict`` (no sensor, emitter or integrator).
    ``medium``: the water's medium object (default: a new one from :func:`water_medium`);
    ``mesh``: include the user's mesh above the water (``mesh.file``), if any; ``water_bsdf``:
    extra properties of the water's dielectric (see :func:`water_mesh`)."""
    hx, hz = exp.pool.half_extent
    res = exp.reference.water_mesh
    yb = floor_bottom(exp)
    out = {}
    # ---- floor
    nfx, nfz = res, res
    x, z = np.meshgrid(np.linspace(-hx, hx, nfx), np.linspace(-hz, hz, nfz))
    y = floor_of(exp, x, z)
    pos = np.stack([x, y, z], -1).reshape(-1, 3)
    uv = np.stack([(x + hx) / (2 * hx), (z + hz) / (2 * hz)], -1).reshape(-1, 2)
    tex = mi.load_dict(
        {
            "type": "bitmap",
            "bitmap": mi.Bitmap(tile_texture(exp)),
            "raw": True,
            "filter_type": "bilinear",
            "wrap_mode": "clamp",
        }
    )
    out["floor"] = _mesh(
        mi,
        "floor",
        pos,
        _grid_faces(nfx, nfz),
        uv=uv,
        outward=np.array([0, 1, 0]),
        bsdf=mi.load_dict({"type": "diffuse", "reflectance": tex}),
    )
    # ---- walls
    w, top = exp.pool.wall_width, exp.pool.wall_height
    wall_bsdf = {
        "type": "diffuse",
        "reflectance": {"type": "rgb", "value": exp.pool.wall_albedo},
    }
    boxes = {
        "wall_px": ((hx, hx + w), (-hz - w, hz + w)),
        "wall_nx": ((-hx - w, -hx), (-hz - w, hz + w)),
        "wall_pz": ((-hx, hx), (hz, hz + w)),
        "wall_nz": ((-hx, hx), (-hz - w, -hz)),
    }
    T = mi.ScalarTransform4f
    for name, ((x0, x1), (z0, z1)) in boxes.items():
        out[name] = {
            "type": "cube",
            "bsdf": wall_bsdf,
            "to_world": T().translate([(x0 + x1) / 2, (yb + top) / 2, (z0 + z1) / 2])
            @ T().scale([(x1 - x0) / 2, (top - yb) / 2, (z1 - z0) / 2]),
        }
    x_min, x_max, top, thick = exp.floor.ledge
    if thick > 0.0:  # an under-water slab across the pool in z (see floor.ledge)
        zl = hz - LEDGE_GAP
        out["ledge"] = {
            "type": "cube",
            "bsdf": wall_bsdf,
            "to_world": T().translate([(x_min + x_max) / 2, top - thick / 2, 0.0])
            @ T().scale([(x_max - x_min) / 2, thick / 2, zl]),
        }
    if mesh and exp.mesh.file:
        mesh_bounds(mi, exp)  # loadable and above the water
        out["mesh"] = mesh_shape(mi, exp)
    if water:
        out["water"] = water_mesh(
            mi, exp, yb, medium if medium is not None else water_medium(mi, exp), water_bsdf
        )
    return out


def water_medium(mi, exp: Experiment):
    """The homogeneous medium inside the water, or None for clear water."""
    if not has_medium(exp):
        return None
    # sigma_t enters as an RGB in [0, 1] times a scalar scale (Mitsuba's RGB volume
    # values are reflectance-like and must lie in [0, 1])
    scale = max(exp.water.sigma_t)
    return mi.load_dict(
        {
            "type": "homogeneous",
            "scale": scale,
            "sigma_t": {"type": "rgb", "value": [v / scale for v in exp.water.sigma_t]},
            "albedo": {"type": "rgb", "value": exp.water.albedo},
        }
    )


def water_mesh(mi, exp: Experiment, y_bottom: float, medium=None, bsdf: dict | None = None):
    """The closed water volume: displaced top, vertical sides, flat bottom. ``bsdf``: extra
    properties of its ``dielectric`` (e.g. ``specular_transmittance = 0`` keeps the reflected
    light only, ``specular_reflectance = 0`` the transmitted: the terms of the shader's Fresnel
    combine, ``benchmarks/bench_grazing.py``)."""
    pos, faces, nor, outward = _water_arrays(exp, y_bottom)
    props = {
        "bsdf": mi.load_dict(
            {"type": "dielectric", "int_ior": exp.water.ior, "ext_ior": 1.0, **(bsdf or {})}
        )
    }
    if medium is not None:
        props["interior"] = medium
    return _mesh(mi, "water", pos, faces, normals=nor, outward=outward, **props)


def _water_arrays(exp: Experiment, y_bottom: float):
    """(positions (V, 3), faces (F, 3), vertex normals (V, 3), outward normals (F, 3)) of the
    water volume of :func:`water_mesh`, float64 NumPy, faces not yet oriented."""
    hx, hz = exp.pool.half_extent
    hx, hz = hx - WATER_INSET, hz - WATER_INSET
    n = exp.reference.water_mesh
    waves = waves_of(exp)
    x, z = np.meshgrid(np.linspace(-hx, hx, n), np.linspace(-hz, hz, n))
    h, gx, gz = waves.height_and_gradient(x, z)
    nrm = np.stack([-gx, np.ones_like(gx), -gz], -1)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    pos = [np.stack([x, h, z], -1).reshape(-1, 3)]
    nor = [nrm.reshape(-1, 3)]
    faces = [_grid_faces(n, n)]
    base = n * n
    # boundary loop of the top grid (vertex indices, counter-clockwise seen from above)
    idx = np.arange(n * n).reshape(n, n)
    ring = np.concatenate([idx[0, :-1], idx[:-1, -1], idx[-1, :0:-1], idx[:0:-1, 0]])
    p0 = pos[0][ring]
    p1 = np.roll(p0, -1, axis=0)
    m = len(ring)
    mid = 0.5 * (p0 + p1)
    on_x = np.abs(mid[:, 0]) >= hx - 1e-6
    side_n = np.stack(
        [
            np.where(on_x, np.sign(mid[:, 0]), 0.0),
            np.zeros(m),
            np.where(on_x, 0.0, np.sign(mid[:, 2])),
        ],
        -1,
    )
    # each side quad has its own 4 vertices (flat shading): p0, p1 on top, then at the bottom
    q = np.stack([p0, p1, p1, p0], 1)
    q[:, 2:, 1] = y_bottom
    pos.append(q.reshape(-1, 3))
    nor.append(np.repeat(side_n, 4, axis=0))
    v = base + 4 * np.arange(m)
    faces.append(np.concatenate([np.stack([v, v + 1, v + 2], 1), np.stack([v, v + 2, v + 3], 1)]))
    # bottom: a fan around the centre
    ring_b = np.stack([p0[:, 0], np.full(m, y_bottom), p0[:, 2]], -1)
    b0 = base + 4 * m
    pos += [ring_b, np.array([[0.0, y_bottom, 0.0]])]
    nor += [np.tile([0.0, -1.0, 0.0], (m + 1, 1))]
    k = np.arange(m)
    faces.append(np.stack([b0 + k, b0 + (k + 1) % m, np.full(m, b0 + m)], 1))
    pos, nor, faces = np.concatenate(pos), np.concatenate(nor), np.concatenate(faces)
    nt = (n - 1) * (n - 1) * 2
    outward = np.concatenate(
        [np.tile([0.0, 1.0, 0.0], (nt, 1)), side_n, side_n, np.tile([0.0, -1.0, 0.0], (m, 1))]
    )
    return pos, faces, nor, outward


def set_waves(scene, exp: Experiment) -> None:
    """Move the water surface of ``scene`` (a scene of :func:`build_scene` or of the top-down
    renders, built for an experiment that differs from ``exp`` at most in ``waves.offsets``, a
    frame of the same animation) to the waves of ``exp``: the vertex positions, normals and faces
    :func:`water_mesh` builds for ``exp`` replace the shape ``water``'s, and the acceleration
    structure is rebuilt. The scene then renders exactly as one built for ``exp``
    (``tests/test_animation.py`` checks it bit for bit). The arrays are set directly, without
    making a mesh (with its dielectric) to take them from."""
    import mitsuba as mi

    key = exp.scene_hash()
    if key not in _MOVED:  # a frame's scenes (reference, lighting) move to the same arrays
        pos, faces, nor, outward = _water_arrays(exp, floor_bottom(exp))
        pos = np.asarray(pos, np.float32)
        _MOVED.clear()
        _MOVED[key] = (
            pos.ravel(),
            np.asarray(nor, np.float32).ravel(),
            _oriented(pos, faces, outward).ravel(),
        )
    params = mi.traverse(scene)
    for name, value in zip(("vertex_positions", "vertex_normals", "faces"), _MOVED[key]):
        params[f"water.{name}"] = value
    params.update()


_MOVED: dict = {}  # scene hash -> the water arrays set_waves set last (one frame's)


def has_medium(exp: Experiment) -> bool:
    return any(v > 0 for v in exp.water.sigma_t)


def sampler_spp(sampler: str, spp: int) -> int:
    """Samples per pixel Mitsuba's ``sampler`` takes when asked for ``spp`` (at least ``spp``;
    Mitsuba would round the same way and warn): ``stratified`` draws a square grid of strata,
    ``multijitter`` an ``a x b`` grid with ``b = floor(sqrt(spp))`` and ``a = ceil(spp / b)``,
    ``independent`` any count. ``tests/test_reference.py`` checks this against the pinned
    Mitsuba's own ``sample_count()``."""
    spp = max(1, int(spp))
    if sampler == "stratified":
        return math.ceil(math.sqrt(spp)) ** 2
    if sampler == "multijitter":
        b = math.isqrt(spp)
        return -(-spp // b) * b
    return spp


def dimension_correlation(
    mi, sampler: str, spp: int = 36, n_pixels: int = 4096, dims: int = 12
) -> tuple[float, float]:
    """Mean correlation of sample dimension d with d+1 of Mitsuba's ``sampler`` over ``dims``
    1-D draws of ``n_pixels`` x ``spp`` samples (seed 0), and its standard error from the spread
    of the ``dims - 1`` pairs. A path tracer assumes independent dimensions: the ``stratified``
    sampler's consecutive-seed permutations correlate them (about -0.01 at 36 spp)."""
    s = mi.load_dict({"type": sampler, "sample_count": spp})
    s.seed(0, n_pixels * spp)
    u = np.array([np.array(s.next_1d()) for _ in range(dims)])
    c = np.corrcoef(u)
    pairs = np.array([c[i, i + 1] for i in range(dims - 1)])
    return float(pairs.mean()), float(pairs.std(ddof=1) / np.sqrt(len(pairs)))


def build_scene(
    exp: Experiment,
    width: int | None = None,
    height: int | None = None,
    seed: int = 0,
    *,
    water_bsdf: dict | None = None,
    rows: tuple[int, int] | None = None,
):
    """The reference scene (perspective camera, box pixel filter, ``reference.sampler``) as a
    loaded ``mi.Scene`` (render it with :func:`study.scene.reference.pass_spp` samples per pass).
    ``water_bsdf``: extra properties of the water's dielectric (:func:`water_mesh`); ``rows``:
    render only image rows ``[r0, r1)`` (a film crop; row 0 at the top)."""
    import mitsuba as mi

    width = width or exp.resolution[0]
    height = height or exp.resolution[1]
    c = exp.section("camera")
    d = {"type": "scene", **build_geometry(mi, exp, water=True, water_bsdf=water_bsdf)}

    d["sky"] = {"type": "envmap", "bitmap": mi.Bitmap(reference_sky(exp))}
    d["sensor"] = {
        "type": "perspective",
        "fov": c["fov_y"],
        "fov_axis": "y",
        "to_world": mi.ScalarTransform4f().look_at(
            origin=c["position"], target=c["target"], up=[0, 1, 0]
        ),
        "sampler": {"type": exp.reference.sampler, "seed": seed},
        "film": {
            "type": "hdrfilm",
            "width": width,
            "height": height,
            "pixel_format": "rgb",
            "rfilter": {"type": "box"},
            **(
                {
                    "crop_offset_x": 0,
                    "crop_offset_y": rows[0],
                    "crop_width": width,
                    "crop_height": rows[1] - rows[0],
                }
                if rows is not None
                else {}
            ),
        },
    }
    d["integrator"] = {
        "type": "volpath" if has_medium(exp) else "path",
        "max_depth": exp.reference.max_depth,
    }
    return mi.load_dict(d)
