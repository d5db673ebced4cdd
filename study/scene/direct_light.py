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
* **The sun, traced from the sun** (:mod:`.sun_photons`, light tracing): its photons land where the
  waves focus the light, so the caustics are sharpest where they are brightest. With
  ``reference.sun_bounces = "photons"`` the photons walk on after their first
  landing, so *all* the sun's light is traced from the sun, and the path tracer renders the
  bounced light of the sky alone (an envmap without the sun: no fireflies left to denoise).
* **The sky, gathered at the floor** (:func:`sky_direct`): per texel, jittered points seen from the
  under-water camera and cosine-weighted directions at each (strata permuted per texel), up
  through one refraction to the sky without the sun, with the water's transmittance evaluated,
  not sampled; the radiance gains ``ior^2`` entering the water (Mitsuba's ``dielectric`` in
  radiance mode). Its noise per texel is far below the path tracer's for the time
  (``benchmarks/bench_direct_light.py``), so the denoiser that follows has little to take for
  noise.

``tests/test_direct_light.py`` checks each against Mitsuba's own estimate of the same term, texel
block by texel block.

Texture arrays are in GL order (row = t, z increasing; column = s, x increasing), float32, linear
RGB radiance of the floor seen from above (texel mean over its horizontal area).
"""

from __future__ import annotations

import numpy as np

from .._backend import jit_input
from ..config.experiment import Experiment
from .denoise import denoise_gain, denoise_radiance
from .animation import shared_part
from .sun_photons import N_BATCHES, shape_named, sun_direct, sun_walk
from .user_scene import reference_sky_parts


def sky_samples(mi, extent, size: int, n_dirs: int, seed: int, y_cam: float):
    """The sample pattern of :func:`sky_direct`: (points (size^2 n_dirs) ``mi.Point3f`` at height
    ``y_cam``, n_dirs jittered strata per texel of ``extent``; their ``mi.Point2f`` uniforms for
    the directions, strata permuted per texel), texel-major, from ``seed``. It depends on nothing
    that moves with the waves: an animation's frames draw it once."""
    F = mi.Float
    side = int(round(np.sqrt(n_dirs)))
    if side * side != n_dirs:
        raise ValueError(
            f"reference.sky_directions = {n_dirs}: use a square number (16, 25, 36, ...)"
        )
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
    o = mi.Point3f(jit_input(F, px), jit_input(F, np.full(n, y_cam)), jit_input(F, pz))
    uv = mi.Point2f(jit_input(F, u), jit_input(F, v))
    import drjit as dr

    dr.eval(o, uv)
    return o, uv


def sky_direct(
    mi,
    scene,
    exp: Experiment,
    sky: np.ndarray,
    extent,
    size: int,
    n_dirs: int,
    seed: int,
    y_cam: float,
    samples=None,
) -> np.ndarray:
    """Direct skylight ``E / pi`` (size, size, 3) float32 (the texel's lighting: multiply by its
    albedo for its radiance) on the surfaces the under-water camera at ``y_cam`` sees, over
    ``extent``, GL order, linear RGB: per texel ``n_dirs`` (a square number) jittered points and
    as many cosine-weighted directions, stratified, up through one refraction at the water's top to
    the (H, 2H, 3) ``sky`` map, with the water's transmittance; zero where the ray meets anything
    else on the way (that light bounced, and is path traced). ``samples``: the pattern of
    :func:`sky_samples` for these arguments (default: drawn here)."""
    import drjit as dr

    F = mi.Float
    water = shape_named(scene, "water")
    o, uv = samples if samples is not None else sky_samples(mi, extent, size, n_dirs, seed, y_cam)
    emitter = mi.load_dict(
        {"type": "envmap", "bitmap": mi.Bitmap(np.ascontiguousarray(sky, np.float32))}
    )
    n = size * size * n_dirs
    si = scene.ray_intersect(mi.Ray3f(o, mi.Vector3f(0.0, -1.0, 0.0)))
    ok = si.is_valid() & (si.shape != mi.ShapePtr(water))
    wo_local = mi.warp.square_to_cosine_hemisphere(uv)
    frame = mi.Frame3f(dr.select(si.n.y < 0, -si.n, si.n))
    si2 = scene.ray_intersect(si.spawn_ray(frame.to_world(wo_local)), ok)
    ok &= si2.is_valid() & (si2.shape == mi.ShapePtr(water)) & (mi.Frame3f.cos_theta(si2.wi) < 0)
    r, cos_t, _, eta_ti = mi.fresnel(mi.Frame3f.cos_theta(si2.wi), dr.opaque(F, exp.water.ior))
    ok &= cos_t != 0  # total internal reflection: no skylight this way
    wo = si2.to_world(mi.refract(si2.wi, cos_t, eta_ti))
    ok &= ~scene.ray_test(si2.spawn_ray(wo), ok)
    sigma = mi.Color3f(*[dr.opaque(F, float(v)) for v in exp.water.sigma_t])
    si_e = dr.zeros(mi.SurfaceInteraction3f, n)
    si_e.wi = -wo
    value = dr.select(
        ok, dr.exp(-sigma * si2.t) * (1.0 - r) * dr.square(eta_ti) * emitter.eval(si_e, ok), 0.0
    )
    dr.eval(value)
    out = (
        np.stack([np.array(value[c]) for c in range(3)], -1).reshape(size * size, n_dirs, 3).mean(1)
    )
    if not np.all(np.isfinite(out)):
        raise RuntimeError(f"the traced skylight of {exp.name!r} has non-finite texels")
    return out.reshape(size, size, 3).astype(np.float32)


def traced_direct(
    exp: Experiment,
    extent,
    size: int,
    seed: int,
    y_cam: float,
    albedo: np.ndarray,
    inside: np.ndarray,
    scene,
    sun_bounces: bool = False,
    shared=None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """The direct sky- and sunlight's radiance (with ``sun_bounces``, all the sunlight's,
    :func:`.sun_photons.sun_walk`) on the texture's (size, size) texels over
    ``extent`` (GL order, linear RGB), zero outside the (size, size) bool ``inside``: (mean,
    its two independent halves (2, size, size, 3), per-texel standard error, a dict for the
    texture's info), float32. The sky from ``reference.sky_directions`` directions per texel and
    half, times the texel ``albedo`` (size, size, 3), its mean denoised
    (``reference.lighting_denoise``) and matched to the raw mean over the pool; the sun from
    ``reference.sun_photons`` photons per texel in ``N_BATCHES`` batches, raw (halves: batches 0-1
    and 2-3). ``scene``: a Mitsuba scene of the experiment's geometry with the water (the
    lighting render's, :func:`.lighting.lighting_scene`); ``shared``: a
    :class:`~.animation.FrameShared` of an animation's frames, which then share the skylight's
    sample patterns (:func:`sky_samples`)."""
    import mitsuba as mi

    sky, sun = reference_sky_parts(exp)
    mask = inside[..., None]
    nd = exp.reference.sky_directions

    def half(h: int) -> np.ndarray:
        samples = shared_part(
            shared,
            exp,
            f"sky_samples{h}",
            lambda: sky_samples(mi, extent, size, nd, 2 * seed + h, y_cam),
        )
        return sky_direct(mi, scene, exp, sky, extent, size, nd, 2 * seed + h, y_cam, samples)

    sky_h = np.stack([half(h) for h in range(2)])
    sky_h = np.where(mask, sky_h * albedo, 0.0)
    sky_raw = sky_h.mean(0)
    sky_se = np.abs(sky_h[0] - sky_h[1]) / 2.0
    info = {"direct": "traced", "sky_directions": 2 * nd}
    sky_mean = sky_raw
    if exp.reference.lighting_denoise != "none" and inside.any():
        sky_mean = np.where(mask, denoise_radiance(sky_raw, np.maximum(albedo, 1e-3)), 0.0)
        gain, gain_se = denoise_gain(sky_mean[inside], sky_raw[inside], sky_se[inside])
        info["sky_denoise_gain"], info["sky_denoise_gain_se"] = gain, gain_se
        if exp.reference.lighting_denoise == "oidn":
            sky_mean = sky_mean / np.asarray(gain, np.float32)

    sun_mean, sun_h, sun_se = np.zeros_like(sky_raw), np.zeros_like(sky_h), np.zeros_like(sky_raw)
    if sun.max() > 0.0:
        per_batch = exp.reference.sun_photons * size * size // N_BATCHES
        trace = sun_walk if sun_bounces else sun_direct
        batches, landed = trace(
            mi,
            scene,
            exp,
            sun,
            extent,
            size,
            per_batch,
            [seed * N_BATCHES + b for b in range(N_BATCHES)],
            y_cam,
        )
        batches = np.where(mask, batches, 0.0)
        half = N_BATCHES // 2
        sun_mean = batches.mean(0)
        sun_h = np.stack([batches[:half].mean(0), batches[half:].mean(0)])
        sun_se = np.sqrt(batches.var(0, ddof=1) / N_BATCHES)
        info.update(
            sun_photons=per_batch * N_BATCHES,
            sun_photons_landed=landed,
            sun_bounces="photons" if sun_bounces else "path",
        )
    se = np.sqrt(sky_se**2 + sun_se**2)
    return (
        (sky_mean + sun_mean).astype(np.float32),
        (sky_h + sun_h).astype(np.float32),
        se.astype(np.float32),
        info,
    )
