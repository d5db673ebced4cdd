"""The top-down refraction texture as *lighting x known floor albedo* (``reference.texture_method
= "lighting"``).

The floor is diffuse and its albedo is known exactly (the tile bitmap), so its radiance seen
from above is ``albedo(x) * E(x) / pi``: the albedo carries the sharp detail (tile edges, grout)
and the lighting ``E / pi`` is smooth except for the sun's caustics, which the sun's disc
(``sun.radius``) already blurs on the floor. So the lighting is path traced at
``reference.lighting_size`` texels over the pool (fewer texels than the texture: each gets
``(texture_size / lighting_size)^2`` times the samples for the same cost), and multiplied
back by the albedo at the texture's full resolution.

Same physics as ``reference.texture_method = "colour"``: the same scene, integrator
(``path``/``volpath``, ``reference.max_depth``), orthographic camera and absorption
correction; Mitsuba's ``aov`` integrator returns, from the very same samples, the radiance and
the albedo of the first surface hit, and the lighting of a texel is their ratio (the
albedo-weighted mean of ``E / pi`` over the texel). What changes is the *resolution* of the
lighting: caustic detail finer than one lighting texel is averaged (bilinear interpolation
between lighting texel centres); the benchmark measures what that does to the fitted
constants (``benchmarks/bench_new_scene.py``).

Outside the pool (the walls' tops, used where the shader's rays leave the pool) the dry scene
is rendered in colour at ``reference.wall_spp`` (at least ``ALBEDO_SPP``, multi-jittered; the
same render gives the albedo): the walls are lit directly by the sky and the sun, with light
sampling, and jittered strata average the albedo over each texel. At the default 16 spp the
texels still carry noise, which the shader sees where its rays leave the pool, and noise in its
inputs biases the fit; so with ``reference.wall_denoise = "oidn"`` (the default) the dry colour
is denoised (guided by its albedo, :func:`denoise_dry`) and its mean outside the pool matched to
the raw mean there.

Noise is measured, not assumed: the lighting is the mean of ``N_SEEDS`` renders with
independent seeds, and the RMS standard error of the resulting colour over the pool texels
(linear RGB) is returned with the texture.

With ``reference.lighting_denoise = "oidn"`` (or ``"oidn_unmatched"``) the mean radiance is
denoised by Intel Open Image Denoise (``pyoidn``, the ``RT`` filter in HDR mode, guided by the
floor albedo from the same samples, which is noise-free under the orthographic camera) before
the division by the albedo.
A denoiser trades variance for a bias of its own (it blurs what it takes for noise, caustics
first); ``benchmarks/bench_denoise.py`` measures what it does to the fitted constants. The
standard error returned is then that of the *input* to the denoiser. Its bias in brightness is
measured on every build (:func:`denoise_gain`: the composed texture's mean over the pool against
the raw mean of the same samples, which is unbiased) and, with ``"oidn"``,
divided out per colour channel over the pool: the path tracer's brightness, the denoiser's
detail (``"oidn_unmatched"`` keeps the denoiser's brightness).

Under water (``reference.lighting_direct = "traced"``, the default) the floor's *direct* light
through the waves -- where the sun's caustics and the sky's ripples are, and the path tracer's
fireflies -- is ray traced at the texture's texels by :mod:`.direct_light`, and only the light
that bounced comes from this render (``reference.bounce_spp``): each pass minus the same pass
rendered with ``max_depth = 3`` (same seed, same paths), then denoised as above. With
``reference.sun_bounces = "photons"`` the sun's bounced light is light traced too, and this
render is lit by the sky without the sun.

The four passes also give the texture's two *halves* (passes 0-1 and 2-3, raw even when the
mean is denoised: a denoiser's bias would survive the decorrelation), independent estimates of
the same lighting, whose product of residuals the fit's decorrelated loss uses
(``fit.input_noise = "decorrelate"``, ``study.fit.decorrelated``) to cancel the texture's noise
instead of being biased by it.

Texture arrays are in GL order (row = t, z increasing; column = s, x increasing), float32,
linear RGB.
"""

from __future__ import annotations

import numpy as np

from ..config.errors import ExperimentError
from ..config.experiment import Experiment
from .denoise import denoise_gain, denoise_radiance
from .direct_light import traced_direct
from .animation import shared_part
from .mitsuba_scene import build_geometry, has_medium, sampler_spp, set_waves, water_medium
from .topdown import (
    MAX_OPTICAL_DEPTH,
    camera_ray_optical_depth,
    ortho_sensor,
    to_gl_order,
    top_down_world_y,
    underwater_camera_height,
)
from .user_scene import dry_camera_height, reference_sky, reference_sky_parts

N_SEEDS = 4  # independent lighting renders (noise estimate from their spread)
ALBEDO_SPP = 16  # least samples per texel of the dry render that also gives the albedo
DRY_SAMPLER = "multijitter"  # its sampler (strata without the stratified sampler's correlations)


def pool_extent(exp: Experiment) -> tuple[float, float, float, float]:
    """World rectangle (x0, z0, x1, z1) of the pool floor (the lighting render's extent)."""
    hx, hz = exp.pool.half_extent
    return (-hx, -hz, hx, hz)


def _top_down_scene(mi, exp: Experiment, *, water: bool, integrator: dict, sky=None, medium=None):
    """(scene, the water's medium) lit by ``sky`` ((H, 2H, 3) lat-long; default: the reference's
    envmap); ``medium``: reuse this medium object (default: a new one)."""
    if medium is None:
        medium = water_medium(mi, exp) if water else None
    d = {
        "type": "scene",
        **build_geometry(mi, exp, water=water, medium=medium),
        "sky": {"type": "envmap", "bitmap": mi.Bitmap(reference_sky(exp) if sky is None else sky)},
        "integrator": integrator,
    }
    return mi.load_dict(d), medium


def lighting_scene(exp: Experiment, water: bool, sky_only: bool = False):
    """(scene, the water's medium) of the lighting render: its geometry, the reference's envmap
    (``sky_only``: without the sun, :func:`.user_scene.reference_sky_parts`) and the ``aov``
    integrator giving radiance and the first hit's albedo."""
    import mitsuba as mi

    sky = None
    if sky_only:
        sky = reference_sky_parts(exp)[0]
    return _top_down_scene(mi, exp, water=water, integrator=_albedo_aov(exp, water), sky=sky)


def _transport(exp: Experiment, water: bool) -> dict:
    return {
        "type": "volpath" if water and has_medium(exp) else "path",
        "max_depth": exp.reference.max_depth,
    }


def _albedo_aov(exp: Experiment, water: bool, max_depth: int | None = None) -> dict:
    """The top-down renders' integrator: radiance (:func:`_transport`, paths cut at ``max_depth``
    if given) and the first hit's albedo, as 6 channels."""
    transport = _transport(exp, water)
    if max_depth is not None:
        transport["max_depth"] = max_depth
    return {"type": "aov", "aovs": "alb:albedo", "transport": transport}


def texel_centres(extent, size: int) -> tuple[np.ndarray, np.ndarray]:
    """(X, Z) world coordinates (size, size) of the texel centres of ``extent`` in GL order."""
    x0, z0, x1, z1 = extent
    c = (np.arange(size) + 0.5) / size
    return np.meshgrid(x0 + c * (x1 - x0), z0 + c * (z1 - z0))


def interpolate(lighting: np.ndarray, extent, X: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of a GL-order (n, n, C) grid over ``extent`` at world points
    (X, Z) (any shape), clamped to the outermost texel centres."""
    x0, z0, x1, z1 = extent
    n_z, n_x = lighting.shape[:2]
    u = np.clip((X - x0) / (x1 - x0) * n_x - 0.5, 0.0, n_x - 1.0)
    v = np.clip((Z - z0) / (z1 - z0) * n_z - 0.5, 0.0, n_z - 1.0)
    i0, j0 = (
        np.minimum(np.floor(u).astype(int), n_x - 2),
        np.minimum(np.floor(v).astype(int), n_z - 2),
    )
    fu, fv = (u - i0)[..., None], (v - j0)[..., None]
    a, b = lighting[j0, i0], lighting[j0, i0 + 1]
    c, d = lighting[j0 + 1, i0], lighting[j0 + 1, i0 + 1]
    return ((1 - fv) * ((1 - fu) * a + fu * b) + fv * ((1 - fu) * c + fu * d)).astype(np.float32)


def render_lighting(
    exp: Experiment,
    size: int,
    spp: int,
    seed: int,
    *,
    water: bool,
    y_cam: float,
    progress=None,
    without_direct: bool = False,
    scene=None,
    world_y=None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lighting ``radiance / albedo`` (size, size, 3) over the pool (GL order), corrected for the
    absorption of the camera's own vertical ray as ``top_down_colour`` does, and its per-texel
    standard error, from ``N_SEEDS`` renders of ``ceil(spp / N_SEEDS)`` spp each (denoised first
    when ``reference.lighting_denoise = "oidn"``; the standard error is the denoiser's input's);
    and the two *halves* (2, size, size, 3): the raw (never denoised) means of passes 0-1 and of
    passes 2-3, independent estimates of the same lighting (``fit.input_noise = "decorrelate"``).

    ``without_direct``: leave the direct light through the water's top out (it is ray traced,
    :mod:`.direct_light`): each pass is rendered again with ``max_depth = 3``, the same envmap and
    the same seed, which follows the full pass's paths sample for sample, and is subtracted.
    ``scene``: (scene, medium) from :func:`lighting_scene` (default: built here); ``world_y``:
    :func:`~.topdown.top_down_world_y` over the pool at ``size`` (default: cast here)."""
    import mitsuba as mi

    extent = pool_extent(exp)
    scene, medium = scene if scene is not None else lighting_scene(exp, water)
    direct = None
    if without_direct:
        direct = mi.load_dict(_albedo_aov(exp, water, max_depth=3))
    per_pass = max(1, -(-spp // N_SEEDS))
    sensor = ortho_sensor(mi, extent, size, per_pass, seed, y_cam=y_cam, medium=medium)
    passes, radiances, albedos = [], [], []
    for k in range(N_SEEDS):
        img = np.array(
            mi.render(scene, sensor=sensor, spp=per_pass, seed=seed * N_SEEDS + k), np.float32
        )
        img = to_gl_order(mi, sensor, img, extent)
        radiance, albedo = img[..., :3], img[..., 3:6]
        if direct is not None:
            d3 = np.array(
                mi.render(
                    scene, sensor=sensor, integrator=direct, spp=per_pass, seed=seed * N_SEEDS + k
                ),
                np.float32,
            )
            radiance = radiance - to_gl_order(mi, sensor, d3, extent)[..., :3]
            _check_lockstep(radiance, img[..., :3], exp)
            radiance = np.maximum(radiance, 0.0)
        if np.any(albedo <= 0.0):
            raise ExperimentError(
                "the lighting render found texels of zero floor albedo (floor.tile_albedo, "
                'floor.albedo_image); use reference.texture_method = "colour" for such '
                "a floor"
            )
        passes.append(radiance / albedo)
        radiances.append(radiance)
        albedos.append(albedo)
        if progress:
            progress(k + 1, N_SEEDS)
    passes = np.stack(passes)
    lighting = passes.mean(0)
    halves = np.stack([passes[: N_SEEDS // 2].mean(0), passes[N_SEEDS // 2 :].mean(0)])
    stderr = np.sqrt(passes.var(0, ddof=1) / N_SEEDS)
    if exp.reference.lighting_denoise != "none":
        albedo = np.mean(albedos, axis=0)
        lighting = denoise_radiance(np.mean(radiances, axis=0), albedo) / albedo
    if water:
        if world_y is None:
            world_y = top_down_world_y(exp, extent, size)

        optical = camera_ray_optical_depth(exp, y_cam, world_y)
        if optical.max() > MAX_OPTICAL_DEPTH:
            raise ExperimentError(
                f"water.sigma_t: the floor's light through the water is lost (optical depth "
                f"{optical.max():.3g} above the floor, more than {MAX_OPTICAL_DEPTH:g}); the "
                "lighting texture cannot recover it: use reference.texture_method = "
                '"colour" (the dry floor stands in there) or less absorption'
            )
        gain = np.exp(optical)
        lighting, stderr, halves = lighting * gain, stderr * gain, halves * gain
    if not np.all(np.isfinite(lighting)):
        raise RuntimeError(f"the lighting render of {exp.name!r} has non-finite texels")
    return lighting.astype(np.float32), stderr.astype(np.float32), halves.astype(np.float32)


def _check_lockstep(rest: np.ndarray, full: np.ndarray, exp: Experiment) -> None:
    """The full pass minus its direct pass must be non-negative up to float rounding: a negative
    texel means the two renders did not follow the same paths (a sampler or integrator that draws
    its random numbers differently), and the subtraction would be wrong."""
    floor = -1e-4 * max(float(full.max()), 1e-6)
    if rest.min() < floor:
        raise RuntimeError(
            f"the lighting render of {exp.name!r}: the direct pass is brighter than the full "
            f"pass in some texels (min {rest.min():.3g}): the two renders did not follow the same "
            'paths; use reference.lighting_direct = "path"'
        )


def dry_spp(spp: int) -> int:
    """Samples per texel of the dry render for ``reference.wall_spp = spp``: at least
    ``ALBEDO_SPP``, rounded up to the multi-jittered sampler's grid."""
    return sampler_spp(DRY_SAMPLER, max(spp, ALBEDO_SPP))


def render_dry(
    exp: Experiment, extent, size: int, spp: int, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """(colour, albedo), each (size, size, 3) GL order: the dry scene (no water) seen from above,
    path traced at :func:`dry_spp` multi-jittered spp, and the texel-mean albedo of the first
    surface hit, from the same samples (one scene, one render)."""
    import mitsuba as mi

    spp = dry_spp(spp)
    scene, _ = _top_down_scene(mi, exp, water=False, integrator=_albedo_aov(exp, False))
    sensor = ortho_sensor(
        mi, extent, size, spp, seed, y_cam=dry_camera_height(mi, exp, extent), sampler=DRY_SAMPLER
    )
    img = to_gl_order(
        mi,
        sensor,
        np.array(mi.render(scene, sensor=sensor, spp=spp, seed=seed), np.float32),
        extent,
    )
    return img[..., :3], img[..., 3:6]


def denoise_dry(
    dry: np.ndarray, albedo: np.ndarray, outside: np.ndarray
) -> tuple[np.ndarray, dict]:
    """The (n, n, 3) linear-RGB dry render denoised by Open Image Denoise guided by its albedo
    (``reference.wall_denoise = "oidn"``), its mean over the (n, n) bool ``outside`` texels (the
    only ones the texture takes from it) matched per colour channel to the raw mean there; and a
    dict with that ratio (denoised / raw, before the match). At 16 spp its texels' noise is 5-8 %,
    and noise in the shader's inputs biases the fit (docs/fast-references.md)."""
    den = denoise_radiance(dry, np.maximum(albedo, 1e-3))
    ratio, _ = denoise_gain(
        den[outside], dry[outside], np.zeros_like(dry[outside])
    )  # no per-texel SE here
    g = np.asarray(ratio, np.float32)
    return (den / np.where(g > 0.0, g, 1.0)).astype(np.float32), {"wall_denoise_gain": ratio}


def _match_denoiser(exp, colour, colour_halves, se, inside, n_light: int, info: dict):
    """The denoiser's brightness against the raw mean of its own samples, as the shader sees it
    (albedo-weighted, on the texture; the lighting grid's texels taken as independent), recorded
    in ``info``; with ``oidn`` the colour divided by it (the path tracer's brightness, the
    denoiser's detail). Returns the colour, (size, size, 3) linear RGB."""
    gain, gain_se = denoise_gain(
        colour[inside],
        colour_halves.mean(0)[inside],
        se[inside],
        n_independent=n_light**2 * float(inside.mean()),
    )
    info["denoise_gain"], info["denoise_gain_se"] = gain, gain_se
    if exp.reference.lighting_denoise == "oidn":
        g = np.asarray(gain, np.float32)
        colour = np.where(inside[..., None], colour / np.where(g > 0.0, g, 1.0), colour)
        info["denoise_matched"] = True
    return colour


def _pool_world_y(exp: Experiment, size: int, shared) -> np.ndarray:
    """World y of the first hit from above on the lighting grid (``size`` texels over the pool),
    built once for an animation's frames (it does not move with the waves)."""
    return shared_part(
        shared, exp, "pool_world_y", lambda: top_down_world_y(exp, pool_extent(exp), size)
    )


def lighting_colour(
    exp: Experiment, extent, size: int, seed: int = 0, world_y=None, progress=None, shared=None
) -> tuple[np.ndarray, dict, np.ndarray]:
    """(size, size, 3) float32 linear RGB top-down colour over ``extent`` (GL order) by
    lighting x albedo inside the pool and the dry colour render outside; a dict with the
    measured noise (``noise``: RMS standard error of the colour over the pool texels) and the
    settings used; and the colour's two independent halves (2, size, size, 3) float32, each from
    half of the lighting passes (the dry render outside the pool is shared by both).
    ``shared``: a :class:`~.animation.FrameShared` of an animation's frames, which then share the
    lighting scene (its water moved to each frame's waves), the dry render with its albedo and
    the lighting grid's world y."""
    wet = exp.reference.refraction_lighting == "underwater"
    y_cam = underwater_camera_height(exp) if wet else 100.0
    n_light = min(exp.reference.lighting_size, size)  # never finer than the texture
    # traced: under water, paths long enough to hold the direct term, and water that only absorbs
    # (in scattering water the max_depth-3 pass also holds light scattered on the camera's own ray)
    traced = (
        wet
        and exp.reference.lighting_direct == "traced"
        and exp.reference.max_depth >= 3
        and max(exp.water.albedo) == 0.0
    )
    spp = exp.reference.bounce_spp if traced else exp.reference.texture_spp
    # sun_bounces: all the sun's light traced from the sun, so the path tracer sees the sky alone
    sun_bounces = traced and exp.reference.sun_bounces == "photons"
    if shared is None:
        scene = lighting_scene(exp, wet, sky_only=sun_bounces)
    else:
        scene = shared.scene(
            exp,
            "lighting_scene",
            lambda: lighting_scene(exp, wet, sky_only=sun_bounces),
            lambda sc, e: set_waves(sc[0], e),
        )
    lighting, lighting_se, halves = render_lighting(
        exp,
        n_light,
        spp,
        seed,
        water=wet,
        y_cam=y_cam,
        progress=progress,
        without_direct=traced,
        scene=scene,
        world_y=_pool_world_y(exp, n_light, shared) if wet else None,
    )
    if world_y is None:
        world_y = top_down_world_y(exp, extent, size)
    X, Z = texel_centres(extent, size)
    hx, hz = exp.pool.half_extent
    inside = (np.abs(X) < hx) & (np.abs(Z) < hz) & (world_y < y_cam)
    pool = pool_extent(exp)

    def dry_render():
        dry, albedo = render_dry(exp, extent, size, exp.reference.wall_spp, seed)
        wall_info = {}
        if exp.reference.wall_denoise == "oidn" and not inside.all():
            dry, wall_info = denoise_dry(dry, albedo, ~inside)
        return dry, albedo, wall_info

    dry, albedo, wall_info = shared_part(shared, exp, "dry_render", dry_render)

    def compose(light):  # lighting x albedo inside the pool, the dry render outside
        return np.where(inside[..., None], interpolate(light, pool, X, Z) * albedo, dry)

    colour, colour_halves = compose(lighting), np.stack([compose(h) for h in halves])
    se = interpolate(lighting_se, pool, X, Z) * albedo
    noise = float(np.sqrt(np.mean(se[inside] ** 2))) if inside.any() else 0.0
    info = {
        "method": "lighting",
        "lighting_size": n_light,
        "spp": spp,
        "wall_spp": dry_spp(exp.reference.wall_spp),
        "noise": noise,
        "n_seeds": N_SEEDS,
        "denoise": exp.reference.lighting_denoise,
        "direct": "traced" if traced else "path",
        **wall_info,
    }
    if exp.reference.lighting_denoise != "none" and inside.any():
        colour = _match_denoiser(exp, colour, colour_halves, se, inside, n_light, info)
    if traced:  # the direct sky- and sunlight, ray traced on the texture's texels
        args = (exp, extent, size, seed, y_cam, albedo, inside)
        d_mean, d_halves, d_se, d_info = traced_direct(
            *args, scene=scene[0], sun_bounces=sun_bounces, shared=shared
        )
        colour, colour_halves = colour + d_mean, colour_halves + d_halves
        if inside.any():
            info["noise"] = float(np.sqrt(np.mean(se[inside] ** 2 + d_se[inside] ** 2)))
        info.update(d_info)
    return colour.astype(np.float32), info, colour_halves.astype(np.float32)
