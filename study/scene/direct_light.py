"""The floor's *direct* light through the waves, ray traced without a path tracer's noise
(``reference.lighting_direct = "traced"``, the default).

The floor's lighting path traced from the floor (:mod:`.lighting`) is noisy where it matters: a
path reaches the sun only when a direction sampled at the floor happens to refract through the
waves into the sun's disc (a smooth dielectric blocks light sampling), so the sun's caustics
arrive as fireflies, and the sky's light is estimated with a random channel's free-flight
distances through the water. A denoiser then takes the caustics' and the sky's ripples for
noise and smooths them, and the fitted bump scale follows the smoothed ripples.

So the light that reaches the floor *directly* -- paths floor -> one refraction at the water's
top -> the environment, unscattered -- is computed here, and only the rest (light that bounced:
back down off the water's underside, off the walls, between floor and walls) is path traced:

* **The split is exact.** That direct term is the part of the path-traced lighting rendered with
  ``max_depth = 3`` (floor, water's top, environment). With the same sampler seed and the same
  envmap that render draws the same random numbers as the full one and follows its paths sample
  for sample, so ``full - direct`` is the full estimate with exactly its direct contributions
  removed (:func:`.lighting.render_lighting`; a negative texel, which a render that strayed would
  leave, stops the build).
* **The sun, traced from the sun** (:func:`sun_direct`, light tracing): photons in the cone of the
  sun's disc (uniform in solid angle, their radiance from the very envmap the path tracer sees,
  Mitsuba's ``envmap.eval``), from points uniform on a horizontal plane just above the highest
  crest (the pool's rectangle, grown so that every ray that can reach the water crosses it),
  traced from above the walls (walls and the user's mesh cast their shadows); at the water's top,
  Fresnel transmission of the power ``1 - F`` and refraction about the shading normal (as
  Mitsuba's ``dielectric``); then down with the water's transmittance ``exp(-sigma_t d)`` to the
  first surface. A photon carries ``L |d_y| Omega A / N`` through the plane and adds
  ``Phi rho |n_y| / (pi A_texel)`` to its texel where it lands on a surface the camera sees from
  above: every sample lands where the waves focus the light, so the caustics are sharpest where
  they are brightest.
* **The sky, gathered at the floor** (:func:`sky_direct`): per texel, jittered points seen from the
  under-water camera and cosine-weighted directions at each (strata permuted per texel), up
  through one refraction to the sky without the sun, with the water's transmittance evaluated,
  not sampled; the radiance gains ``ior^2`` entering the water (Mitsuba's ``dielectric`` in
  radiance mode). Per texel its noise is 6-9 % before denoising against the path tracer's 27-34 %
  at 32 spp (30-40 times less variance for the time, ``benchmarks/bench_direct_light.py``), so the
  denoiser that follows has little to take for noise.

``tests/test_direct_light.py`` checks both against Mitsuba's own ``max_depth = 3`` estimate of
the same term, texel block by texel block.

Texture arrays are in GL order (row = t, z increasing; column = s, x increasing), float32, linear
RGB radiance of the floor seen from above (texel mean over its horizontal area).
"""
from __future__ import annotations

import numpy as np

from .experiment import Experiment

CONE_MARGIN_TEXELS = 2.0   # the cone around the sun's texels, grown by this many map texels
                           # (the envmap interpolates bilinearly: its disc is one texel wider)
PLANE_ABOVE_CREST = 0.01   # the photons' plane above the highest point of the water's top (m)
N_BATCHES = 4              # independent photon batches (noise estimate from their spread)


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
    """(N, 3) unit directions uniform in solid angle in the cone (axis, angle) from uniforms u, v."""
    cos_t = 1.0 - u * (1.0 - np.cos(angle))
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t ** 2))
    phi = 2.0 * np.pi * v
    a = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(axis, a)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(axis, t1)
    return (np.outer(sin_t * np.cos(phi), t1) + np.outer(sin_t * np.sin(phi), t2)
            + np.outer(cos_t, axis))


def _shape(scene, name: str):
    for s in scene.shapes():
        if s.id() == name:
            return s
    raise RuntimeError(f"the scene has no shape {name!r}")


def _vec(mi, a: np.ndarray):
    return [mi.Float(np.ascontiguousarray(a[:, k], np.float32)) for k in range(3)]


def _splat(mi, ok, p, value, extent, size: int) -> tuple[np.ndarray, int]:
    """Sum of the (N, 3) ``value`` of the lanes ``ok`` into the (size, size, 3) texels of their
    points ``p`` over ``extent``, GL order (one kernel evaluates the whole batch), and how many
    lanes were ``ok``."""
    import drjit as dr
    dr.eval(ok, p, value)
    ok_np = np.array(ok, bool)
    x0, z0, x1, z1 = extent
    col = np.clip(((np.array(p.x)[ok_np] - x0) / (x1 - x0) * size).astype(int), 0, size - 1)
    row = np.clip(((np.array(p.z)[ok_np] - z0) / (z1 - z0) * size).astype(int), 0, size - 1)
    idx = row * size + col
    out = np.stack([np.bincount(idx, weights=np.array(value[k])[ok_np].astype(np.float64), minlength=size * size)
                    for k in range(3)], -1)
    return out.reshape(size, size, 3), int(ok_np.sum())


def sun_direct(mi, scene, exp: Experiment, sun: np.ndarray, extent, size: int, n_photons: int,
               seed: int, y_cam: float, cone=None) -> tuple[np.ndarray, int]:
    """Light-traced radiance of the direct sunlight on the surfaces the under-water camera at
    ``y_cam`` sees (the floor, a ledge), (size, size, 3) float32 over the texture ``extent``
    (x0, z0, x1, z1), GL order, linear RGB, from ``n_photons`` photons of the (H, 2H, 3) ``sun``
    map; and the number of photons that landed. ``scene``: the geometry with the water (its shape
    ``water``). Scalars enter the kernels as opaque values: another photon count or scene compiles
    nothing new. ``cone``: :func:`sun_cone` of ``sun``, if known."""
    import drjit as dr

    F = mi.Float
    water = _shape(scene, "water")
    emitter = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(np.ascontiguousarray(sun, np.float32))})
    axis, angle = sun_cone(sun) if cone is None else cone
    if axis[1] <= 0.0:               # the sun is below the horizon: no direct light through the water
        return np.zeros((size, size, 3), np.float32), 0
    y_plane = float(water.bbox().max.y) + PLANE_ABOVE_CREST
    y_start = float(scene.bbox().max.y) + 1.0
    # the plane's rectangle: the pool, grown by how far a sun ray moves sideways between the
    # plane and the camera (which is below the lowest wave trough)
    cos_low = max(np.cos(np.arccos(min(1.0, axis[1])) + angle), 1e-3)
    reach = (y_plane - y_cam) * np.sqrt(max(0.0, 1.0 - cos_low ** 2)) / cos_low
    hx, hz = exp["pool.half_extent"]
    rx0, rx1, rz0, rz1 = -hx - reach, hx + reach, -hz - reach, hz + reach
    area = (rx1 - rx0) * (rz1 - rz0)
    omega = 2.0 * np.pi * (1.0 - np.cos(angle))

    rng = np.random.default_rng(seed)
    side = max(1, int(np.sqrt(n_photons)))        # jittered strata over the rectangle
    n = side * side
    j, i = np.divmod(np.arange(n), side)
    plane = np.stack([rx0 + (i + rng.random(n)) / side * (rx1 - rx0), np.full(n, y_plane),
                      rz0 + (j + rng.random(n)) / side * (rz1 - rz0)], -1)
    dirs = -_cone_directions(axis, angle, rng.random(n), rng.random(n))      # travelling down
    o = plane - dirs * ((y_start - y_plane) / -dirs[:, 1])[:, None]

    d = mi.Vector3f(*_vec(mi, dirs))
    si_e = dr.zeros(mi.SurfaceInteraction3f, n)
    si_e.wi = d                                   # the envmap looks up -wi: towards the sun
    power = emitter.eval(si_e) * F(np.abs(dirs[:, 1]).astype(np.float32)) * dr.opaque(F, omega * area / n)

    si = scene.ray_intersect(mi.Ray3f(mi.Point3f(*_vec(mi, o)), d))
    ok = si.is_valid() & (si.shape == mi.ShapePtr(water)) & (mi.Frame3f.cos_theta(si.wi) > 0)
    r, cos_t, _, eta_ti = mi.fresnel(mi.Frame3f.cos_theta(si.wi), dr.opaque(F, exp["water.ior"]))
    power = power * (1.0 - r)
    si2 = scene.ray_intersect(si.spawn_ray(si.to_world(mi.refract(si.wi, cos_t, eta_ti))), ok)
    ok &= si2.is_valid() & (si2.shape != mi.ShapePtr(water))
    # where the camera sees it: nothing between the landing point and the camera above it
    up = si2.spawn_ray(mi.Vector3f(0.0, 1.0, 0.0))
    up.maxt = dr.opaque(F, y_cam) - si2.p.y
    ok &= (up.maxt > 0) & ~scene.ray_test(up, ok)
    sigma = mi.Color3f(*[dr.opaque(F, float(v)) for v in exp["water.sigma_t"]])
    albedo = si2.bsdf().eval_diffuse_reflectance(si2, ok)
    x0, z0, x1, z1 = extent
    value = (power * dr.exp(-sigma * si2.t) * albedo * dr.abs(si2.n.y)
             * dr.opaque(F, size * size / (np.pi * (x1 - x0) * (z1 - z0))))
    out, landed = _splat(mi, ok, si2.p, value, extent, size)
    if not np.all(np.isfinite(out)):
        raise RuntimeError(f"the light-traced sunlight of {exp['name']!r} has non-finite texels")
    return out.astype(np.float32), landed


def sky_direct(mi, scene, exp: Experiment, sky: np.ndarray, extent, size: int, n_dirs: int, seed: int,
               y_cam: float) -> np.ndarray:
    """Direct skylight ``E / pi`` (size, size, 3) float32 (the texel's lighting: multiply by its
    albedo for its radiance) on the surfaces the under-water camera at ``y_cam`` sees, over
    ``extent``, GL order, linear RGB: per texel ``n_dirs`` (a square number) jittered points and
    as many cosine-weighted directions, stratified, up through one refraction at the water's top to
    the (H, 2H, 3) ``sky`` map, with the water's transmittance; zero where the ray meets anything
    else on the way (that light bounced, and is path traced)."""
    import drjit as dr

    F = mi.Float
    water = _shape(scene, "water")
    emitter = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(np.ascontiguousarray(sky, np.float32))})
    side = int(round(np.sqrt(n_dirs)))
    if side * side != n_dirs:
        raise ValueError(f"reference.sky_directions = {n_dirs}: use a square number (16, 25, 36, ...)")
    rng = np.random.default_rng(seed)
    x0, z0, x1, z1 = extent
    n = size * size * n_dirs
    row, col = np.divmod(np.repeat(np.arange(size * size), n_dirs), size)
    k = np.tile(np.arange(n_dirs), size * size)
    px = x0 + (col + (k % side + rng.random(n)) / side) / size * (x1 - x0)
    pz = z0 + (row + (k // side + rng.random(n)) / side) / size * (z1 - z0)
    kd = rng.permuted(np.tile(np.arange(n_dirs), (size * size, 1)), axis=1).ravel()
    u, v = (kd % side + rng.random(n)) / side, (kd // side + rng.random(n)) / side
    del row, col, k, kd

    o = mi.Point3f(F(px.astype(np.float32)), F(np.full(n, y_cam, np.float32)), F(pz.astype(np.float32)))
    si = scene.ray_intersect(mi.Ray3f(o, mi.Vector3f(0.0, -1.0, 0.0)))
    ok = si.is_valid() & (si.shape != mi.ShapePtr(water))
    wo_local = mi.warp.square_to_cosine_hemisphere(mi.Point2f(F(u.astype(np.float32)), F(v.astype(np.float32))))
    frame = mi.Frame3f(dr.select(si.n.y < 0, -si.n, si.n))
    si2 = scene.ray_intersect(si.spawn_ray(frame.to_world(wo_local)), ok)
    ok &= si2.is_valid() & (si2.shape == mi.ShapePtr(water)) & (mi.Frame3f.cos_theta(si2.wi) < 0)
    r, cos_t, _, eta_ti = mi.fresnel(mi.Frame3f.cos_theta(si2.wi), dr.opaque(F, exp["water.ior"]))
    ok &= cos_t != 0                              # total internal reflection: no skylight this way
    wo = si2.to_world(mi.refract(si2.wi, cos_t, eta_ti))
    ok &= ~scene.ray_test(si2.spawn_ray(wo), ok)
    sigma = mi.Color3f(*[dr.opaque(F, float(v)) for v in exp["water.sigma_t"]])
    si_e = dr.zeros(mi.SurfaceInteraction3f, n)
    si_e.wi = -wo
    value = dr.select(ok, dr.exp(-sigma * si2.t) * (1.0 - r) * dr.square(eta_ti) * emitter.eval(si_e, ok), 0.0)
    dr.eval(value)
    out = np.stack([np.array(value[c]) for c in range(3)], -1).reshape(size * size, n_dirs, 3).mean(1)
    if not np.all(np.isfinite(out)):
        raise RuntimeError(f"the traced skylight of {exp['name']!r} has non-finite texels")
    return out.reshape(size, size, 3).astype(np.float32)


def traced_direct(exp: Experiment, extent, size: int, seed: int, y_cam: float, albedo: np.ndarray,
                  inside: np.ndarray, scene) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """The direct sky- and sunlight's radiance on the texture's (size, size) texels over
    ``extent`` (GL order, linear RGB), zero outside the (size, size) bool ``inside``: (mean,
    its two independent halves (2, size, size, 3), per-texel standard error, a dict for the
    texture's info), float32. The sky from ``reference.sky_directions`` directions per texel and
    half, times the texel ``albedo`` (size, size, 3), its mean denoised (``reference.lighting_denoise``)
    and matched to the raw mean over the pool; the sun from ``reference.sun_photons`` photons per
    texel in ``N_BATCHES`` batches, raw (halves: batches 0-1 and 2-3). ``scene``: a Mitsuba scene
    of the experiment's geometry with the water (the lighting render's, :func:`.lighting.lighting_scene`)."""
    import mitsuba as mi

    from .lighting import denoise_gain, denoise_radiance
    from .user_scene import reference_sky_parts

    sky, sun = reference_sky_parts(exp)
    mask = inside[..., None]
    nd = exp["reference.sky_directions"]
    sky_h = np.stack([sky_direct(mi, scene, exp, sky, extent, size, nd, 2 * seed + h, y_cam) for h in range(2)])
    sky_h = np.where(mask, sky_h * albedo, 0.0)
    sky_raw = sky_h.mean(0)
    sky_se = np.abs(sky_h[0] - sky_h[1]) / 2.0
    info = {"direct": "traced", "sky_directions": 2 * nd}
    sky_mean = sky_raw
    if exp["reference.lighting_denoise"] != "none" and inside.any():
        sky_mean = np.where(mask, denoise_radiance(sky_raw, np.maximum(albedo, 1e-3)), 0.0)
        gain, gain_se = denoise_gain(sky_mean[inside], sky_raw[inside], sky_se[inside])
        info["sky_denoise_gain"], info["sky_denoise_gain_se"] = gain, gain_se
        if exp["reference.lighting_denoise"] == "oidn":
            sky_mean = sky_mean / np.asarray(gain, np.float32)

    sun_mean, sun_h, sun_se = np.zeros_like(sky_raw), np.zeros_like(sky_h), np.zeros_like(sky_raw)
    if sun.max() > 0.0:
        per_batch = exp["reference.sun_photons"] * size * size // N_BATCHES
        batches, landed, cone = [], 0, sun_cone(sun)
        for b in range(N_BATCHES):
            img, m = sun_direct(mi, scene, exp, sun, extent, size, per_batch, seed * N_BATCHES + b, y_cam, cone)
            batches.append(np.where(mask, img, 0.0))
            landed += m
        batches = np.stack(batches)
        half = N_BATCHES // 2
        sun_mean = batches.mean(0)
        sun_h = np.stack([batches[:half].mean(0), batches[half:].mean(0)])
        sun_se = np.sqrt(batches.var(0, ddof=1) / N_BATCHES)
        info.update(sun_photons=per_batch * N_BATCHES, sun_photons_landed=landed)
    se = np.sqrt(sky_se ** 2 + sun_se ** 2)
    return ((sky_mean + sun_mean).astype(np.float32), (sky_h + sun_h).astype(np.float32),
            se.astype(np.float32), info)
