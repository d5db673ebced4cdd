"""The sun's light on the floor traced from the sun (light tracing): its direct light through the
waves (:func:`sun_direct`) and, with ``reference.sun_bounces = "photons"``, every bounce after it
too (:func:`sun_walk`).

**Why from the sun.** A path traced from the floor reaches the sun only when a direction it samples
happens to refract out through the waves into the sun's disc (a smooth dielectric blocks light
sampling): the sun's caustics arrive as fireflies. The same holds for the sun's light that bounced
-- off the sunlit walls onto the floor at their feet, off the floor and back down from the
water's underside (total internal reflection holds 44 % of the floor's cosine-weighted light
under water): at the texture's 16 spp a few texels catch a firefly, the denoiser takes them for
noise, and the pool-wide brightness match spreads what it removed over the whole pool, so the
light at the feet of the sunlit walls comes out too dark in red and the rest of the floor
slightly too bright. Photons from the sun land where the light goes, every one. The fitted
constants hardly notice (docs/fast-references.md), so the default stays ``"path"``.

**The photons.** Uniform in solid angle in the cone of the sun's disc (:func:`sun_cone`; their
radiance from the very envmap the path tracer sees, Mitsuba's ``envmap.eval``), from points
uniform (jittered) on a horizontal plane just above the highest crest (the pool's rectangle,
grown so that every ray that can reach the water crosses it), started above everything (walls
and the user's mesh cast their shadows). A photon carries the power ``L |d_y| Omega A / N``
through the plane.

* :func:`sun_direct`: at the water's top, Fresnel transmission of the power ``1 - F`` and
  refraction about the shading normal (as Mitsuba's ``dielectric``); then down with the water's
  transmittance ``exp(-sigma_t d)`` to the first surface.
* :func:`sun_walk`: the photon's walk, as Mitsuba's path tracer would see it backwards: at every
  surface Mitsuba's own BSDF sampled in importance mode (the water's dielectric from above or
  below: reflection or refraction by its Fresnel term; the diffuse walls, floor and mesh:
  cosine-weighted, the power times the albedo), the water's transmittance on every segment inside
  it, up to ``reference.max_depth`` (a landing after ``k`` surfaces is a path of depth ``k + 1``).

A photon of power ``Phi`` that lands on a diffuse surface the under-water camera sees from above
adds ``Phi rho |n_y| / (pi A_texel)`` to its texel (the texel-mean radiance over its horizontal
area). ``tests/test_direct_light.py`` checks both against Mitsuba's path tracer lit by the sun
alone, texel block by texel block.

Texture arrays are in GL order (row = t, z increasing; column = s, x increasing), float32, linear
RGB radiance of the floor seen from above.
"""

from __future__ import annotations

import numpy as np

from .._backend import jit_input
from ..config.experiment import Experiment

CONE_MARGIN_TEXELS = 2.0  # the cone around the sun's texels, grown by this many map texels
# (the envmap interpolates bilinearly: its disc is one texel wider)
PLANE_ABOVE_CREST = 0.01  # the photons' plane above the highest point of the water's top (m)
N_BATCHES = 4  # independent photon batches (noise estimate from their spread)


def sun_cone(sun: np.ndarray) -> tuple[np.ndarray, float]:
    """(unit axis (3,), half-angle in radians) of a cone holding every direction where the
    (H, 2H, 3) lat-long sun map (Mitsuba's envmap convention) is not zero, grown by
    :data:`CONE_MARGIN_TEXELS` map texels."""
    h = sun.shape[0]
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(2 * h) + 0.5) / (2 * h)
    th, ph = np.meshgrid(v * np.pi, u * 2 * np.pi, indexing="ij")
    d = np.stack([np.sin(th) * np.sin(ph), np.cos(th), -np.sin(th) * np.cos(ph)], -1)
    lum = sun.sum(-1)
    lit = lum > 0.0
    if not lit.any():
        raise ValueError("the sun map has no light")
    w = (lum * np.sin(th))[lit]
    axis = (d[lit] * w[:, None]).sum(0)
    axis /= np.linalg.norm(axis)
    cos_max = float(np.clip(d[lit] @ axis, -1.0, 1.0).min())
    return axis, float(np.arccos(cos_max) + CONE_MARGIN_TEXELS * np.pi / h)


def _cone_directions(axis: np.ndarray, angle: float, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(N, 3) unit directions uniform in solid angle in the cone (axis, angle) from
    uniforms u, v."""
    cos_t = 1.0 - u * (1.0 - np.cos(angle))
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t**2))
    phi = 2.0 * np.pi * v
    a = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(axis, a)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(axis, t1)
    return (
        np.outer(sin_t * np.cos(phi), t1)
        + np.outer(sin_t * np.sin(phi), t2)
        + np.outer(cos_t, axis)
    )


def shape_named(scene, name: str):
    for s in scene.shapes():
        if s.id() == name:
            return s
    raise RuntimeError(f"the scene has no shape {name!r}")


def _vec(mi, a: np.ndarray):
    return [jit_input(mi.Float, a[:, k]) for k in range(3)]


def _splat(
    mi, ok, p, value, extent, size: int, batch: np.ndarray, n_batches: int
) -> tuple[np.ndarray, int]:
    """Sum of the (N, 3) ``value`` of the lanes ``ok`` into the (n_batches, size, size, 3) texels
    of their ``batch`` (N,) and their points ``p`` over ``extent``, GL order (one kernel evaluates
    them all), and how many lanes were ``ok``."""
    import drjit as dr

    dr.eval(ok, p, value)
    ok_np = np.array(ok, bool)
    x0, z0, x1, z1 = extent
    col = np.clip(((np.array(p.x)[ok_np] - x0) / (x1 - x0) * size).astype(int), 0, size - 1)
    row = np.clip(((np.array(p.z)[ok_np] - z0) / (z1 - z0) * size).astype(int), 0, size - 1)
    idx = (batch[ok_np] * size + row) * size + col
    m = n_batches * size * size
    out = np.stack(
        [
            np.bincount(idx, weights=np.array(value[k])[ok_np].astype(np.float64), minlength=m)
            for k in range(3)
        ],
        -1,
    )
    return out.reshape(n_batches, size, size, 3), int(ok_np.sum())


def _emit(mi, scene, exp: Experiment, sun: np.ndarray, n_photons: int, seeds, y_cam: float):
    """The photons of the (H, 2H, 3) ``sun`` map in one batch per seed of ``seeds``, travelling
    down: (origins (B N, 3) above the whole scene, unit directions (B N, 3), float64 numpy; power
    (B N, 3) as Mitsuba's ``Color3f``, radiance x m^2 x sr; batch index (B N,) int), N the square
    number at most ``n_photons``; or None when the sun is below the horizon."""
    import drjit as dr

    F = mi.Float
    water = shape_named(scene, "water")
    axis, angle = sun_cone(sun)
    if axis[1] <= 0.0:  # the sun is below the horizon: no direct light through the water
        return None
    y_plane = float(water.bbox().max.y) + PLANE_ABOVE_CREST
    y_start = float(scene.bbox().max.y) + 1.0
    # the plane's rectangle: the pool, grown by how far a sun ray moves sideways between the
    # plane and the camera (which is below the lowest wave trough)
    cos_low = max(np.cos(np.arccos(min(1.0, axis[1])) + angle), 1e-3)
    reach = (y_plane - y_cam) * np.sqrt(max(0.0, 1.0 - cos_low**2)) / cos_low
    hx, hz = exp.pool.half_extent
    rx0, rx1, rz0, rz1 = -hx - reach, hx + reach, -hz - reach, hz + reach
    area = (rx1 - rx0) * (rz1 - rz0)
    omega = 2.0 * np.pi * (1.0 - np.cos(angle))

    side = max(1, int(np.sqrt(n_photons)))  # jittered strata over the rectangle
    n = side * side
    j, i = np.divmod(np.arange(n), side)
    origins, directions = [], []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        plane = np.stack(
            [
                rx0 + (i + rng.random(n)) / side * (rx1 - rx0),
                np.full(n, y_plane),
                rz0 + (j + rng.random(n)) / side * (rz1 - rz0),
            ],
            -1,
        )
        dirs = -_cone_directions(axis, angle, rng.random(n), rng.random(n))  # travelling down
        origins.append(plane - dirs * ((y_start - y_plane) / -dirs[:, 1])[:, None])
        directions.append(dirs)
    o, dirs = np.concatenate(origins), np.concatenate(directions)
    si_e = dr.zeros(mi.SurfaceInteraction3f, len(o))
    si_e.wi = mi.Vector3f(*_vec(mi, dirs))  # the envmap looks up -wi: towards the sun
    emitter = mi.load_dict(
        {"type": "envmap", "bitmap": mi.Bitmap(np.ascontiguousarray(sun, np.float32))}
    )
    power = emitter.eval(si_e) * jit_input(F, np.abs(dirs[:, 1])) * dr.opaque(F, omega * area / n)
    return o, dirs, power, np.repeat(np.arange(len(seeds)), n)


def _seen_from_above(mi, scene, si, ok, y_cam: float):
    """Lanes of ``ok`` whose surface point the under-water camera at ``y_cam`` sees: below it, and
    nothing between the point and the camera straight above."""
    import drjit as dr

    up = si.spawn_ray(mi.Vector3f(0.0, 1.0, 0.0))
    up.maxt = dr.opaque(mi.Float, y_cam) - si.p.y
    return ok & (up.maxt > 0) & ~scene.ray_test(up, ok)


def _texel_scale(mi, extent, size: int):
    """``1 / (pi A_texel)``: photon power x albedo x |n_y| to the texel-mean radiance."""
    import drjit as dr

    x0, z0, x1, z1 = extent
    return dr.opaque(mi.Float, size * size / (np.pi * (x1 - x0) * (z1 - z0)))


def sun_direct(
    mi,
    scene,
    exp: Experiment,
    sun: np.ndarray,
    extent,
    size: int,
    n_photons: int,
    seeds,
    y_cam: float,
) -> tuple[np.ndarray, int]:
    """Light-traced radiance of the direct sunlight on the surfaces the under-water camera at
    ``y_cam`` sees (the floor, a ledge), (B, size, size, 3) float32 over the texture ``extent``
    (x0, z0, x1, z1), GL order, linear RGB: one independent batch of ``n_photons`` photons of the
    (H, 2H, 3) ``sun`` map per seed of ``seeds`` (B of them, traced
    together: one kernel); and the number of photons that landed. ``scene``: the geometry with the
    water (its shape ``water``). Scalars enter the kernels as opaque values."""
    import drjit as dr

    F = mi.Float
    emitted = _emit(mi, scene, exp, sun, n_photons, seeds, y_cam)
    if emitted is None:
        return np.zeros((len(seeds), size, size, 3), np.float32), 0
    o, dirs, power, batch = emitted
    water = shape_named(scene, "water")
    si = scene.ray_intersect(mi.Ray3f(mi.Point3f(*_vec(mi, o)), mi.Vector3f(*_vec(mi, dirs))))
    ok = si.is_valid() & (si.shape == mi.ShapePtr(water)) & (mi.Frame3f.cos_theta(si.wi) > 0)
    r, cos_t, _, eta_ti = mi.fresnel(mi.Frame3f.cos_theta(si.wi), dr.opaque(F, exp.water.ior))
    power = power * (1.0 - r)
    si2 = scene.ray_intersect(si.spawn_ray(si.to_world(mi.refract(si.wi, cos_t, eta_ti))), ok)
    ok &= si2.is_valid() & (si2.shape != mi.ShapePtr(water))
    ok = _seen_from_above(mi, scene, si2, ok, y_cam)
    sigma = mi.Color3f(*[dr.opaque(F, float(v)) for v in exp.water.sigma_t])
    albedo = si2.bsdf().eval_diffuse_reflectance(si2, ok)
    value = (
        power * dr.exp(-sigma * si2.t) * albedo * dr.abs(si2.n.y) * _texel_scale(mi, extent, size)
    )
    out, landed = _splat(mi, ok, si2.p, value, extent, size, batch, len(seeds))
    if not np.all(np.isfinite(out)):
        raise RuntimeError(f"the light-traced sunlight of {exp.name!r} has non-finite texels")
    return out.astype(np.float32), landed


def sun_walk(
    mi,
    scene,
    exp: Experiment,
    sun: np.ndarray,
    extent,
    size: int,
    n_photons: int,
    seeds,
    y_cam: float,
) -> tuple[np.ndarray, int]:
    """Light-traced radiance of *all* the sun's light (direct and bounced, up to
    ``reference.max_depth``) on the surfaces the under-water camera at ``y_cam`` sees, (B, size,
    size, 3) float32 over ``extent``, GL order, linear RGB, one batch of ``n_photons`` photons per
    seed; and the number of landings splatted. Arguments as :func:`sun_direct`. One symbolic
    loop (one kernel), its landings scattered into the texels as they happen. Water that
    scatters (``water.albedo`` > 0) is not modelled here: the caller keeps it path traced."""
    import drjit as dr

    F, U = mi.Float, mi.UInt32
    emitted = _emit(mi, scene, exp, sun, n_photons, seeds, y_cam)
    if emitted is None:
        return np.zeros((len(seeds), size, size, 3), np.float32), 0
    o, d, power, batch = emitted
    n = len(o)
    water = mi.ShapePtr(shape_named(scene, "water"))
    sigma = mi.Color3f(*[dr.opaque(F, float(v)) for v in exp.water.sigma_t])
    scale = _texel_scale(mi, extent, size)
    x0, z0, x1, z1 = extent
    sx, sz = dr.opaque(F, size / (x1 - x0)), dr.opaque(F, size / (z1 - z0))
    ox, oz, n_side = dr.opaque(F, x0), dr.opaque(F, z0), dr.opaque(mi.Int32, size)
    max_surfaces = dr.opaque(
        U, exp.reference.max_depth - 1
    )  # the k-th surface: a path of depth k + 1
    ctx = mi.BSDFContext(mi.TransportMode.Importance)
    texels = dr.zeros(F, len(seeds) * size * size * 3)
    first = jit_input(U, batch * size * size, np.uint32)  # each batch's first texel
    rng = mi.PCG32(n, dr.opaque(mi.UInt64, seeds[0]), dr.arange(mi.UInt64, n))

    def cond(ray, p, inside, k, landed, active, rng):
        return active

    def body(ray, p, inside, k, landed, active, rng):
        si = scene.ray_intersect(ray, active)
        valid = active & si.is_valid()
        p = dr.select(inside, p * dr.exp(-sigma * si.t), p)
        is_water = si.shape == water
        seen = _seen_from_above(mi, scene, si, valid & ~is_water, y_cam)
        bsdf = si.bsdf()
        value = p * bsdf.eval_diffuse_reflectance(si, seen) * dr.abs(si.n.y) * scale
        col = dr.clip(mi.Int32((si.p.x - ox) * sx), 0, n_side - 1)
        row = dr.clip(mi.Int32((si.p.z - oz) * sz), 0, n_side - 1)
        idx = (first + U(row * n_side + col)) * 3
        for c in range(3):
            dr.scatter_reduce(dr.ReduceOp.Add, texels, value[c], idx + c, seen)
        landed = landed + dr.select(seen, 1, 0)
        bs, weight = bsdf.sample(
            ctx, si, rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32()), valid
        )
        wo = si.to_world(bs.wo)
        p = p * weight
        inside = dr.select(
            valid & is_water, dr.dot(wo, si.n) < 0.0, inside
        )  # in or out of the water
        ray = dr.select(valid, si.spawn_ray(wo), ray)
        k = k + 1
        active = valid & (dr.max(p) > 0.0) & (k < max_surfaces)
        return ray, p, inside, k, landed, active, rng

    ray = mi.Ray3f(mi.Point3f(*_vec(mi, o)), mi.Vector3f(*_vec(mi, d)))
    state = (
        ray,
        mi.Color3f(power),
        dr.zeros(mi.Bool, n),
        dr.zeros(U, n),
        dr.zeros(U, n),
        dr.full(mi.Bool, True, n),
        rng,
    )
    _, _, _, _, landed, _, _ = dr.while_loop(state, cond, body, label="sun_walk")
    dr.eval(texels, landed)
    out = np.array(texels, np.float64).reshape(len(seeds), size, size, 3)
    if not np.all(np.isfinite(out)):
        raise RuntimeError(f"the light-traced sunlight of {exp.name!r} has non-finite texels")
    return out.astype(np.float32), int(np.array(landed, np.int64).sum())
