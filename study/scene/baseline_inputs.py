"""The baseline shader's extra inputs (``water_baseline``, seeds 001-004), from the same scene.

A game feeding the baseline water renders two more views per frame; here both come from
the experiment's Mitsuba scene *without the water*, one path-traced ray per sample through
each pixel centre (no anti-aliasing, as a GL colour buffer without MSAA):

* ``scene_color`` / ``scene_depth``: the camera's own view (``view_proj``) at the output
  resolution. Depth is the GL window depth ``0.5 * z_ndc + 0.5`` of the first hit (exact ray
  cast; 1 where nothing is hit). Colour is the dry scene (sky, sun, walls, floor), except
  where the view sees the floor under the water: there the colour is the top-down
  ``refraction_texture`` looked up at the hit point (bilinear), the floor's own radiance
  lit as ``reference.refraction_lighting`` says -- the same radiance the raycast shaders
  read, which is exact for the diffuse floor and keeps the comparison about the shader;
* ``reflection_color``: the scene above the water seen by the mirrored camera of seed 004
  (``reflection_view_proj = mirrored_view_proj(view_proj)``), clipped at the water plane
  (seed 004's clip plane: each ray starts where it crosses y = 0; rays that never rise
  above the water see the sky, as a skybox drawn without clipping would show).

Sky seen directly (a ray that hits nothing) is the sky *without the sun disc*, as in the
raycast shaders' cube map: the sun is the shader's light and Phong highlight. Rows are in GL
order (row 0 = bottom of the screen). Linear RGB, float32.

Cost: two path-traced passes of ``width x height`` rays at ``BASELINE_SPP``;
cached under ``<cache>/inputs/baseline_<key>.npz`` keyed like the shader inputs.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np

from shaders_port import ShaderInputs
from shaders_port.inputs import mirrored_view_proj
from shaders_port.variants import get_variant

from .._backend import jit_input
from ..config.experiment import Experiment
from ..config.user_shader import is_user_shader, load_user_shader
from .box_inputs import with_box_inputs
from .cache import SCENE_VERSION, cache_dir, cached_fields, versions
from .geometry import envmap_image, sky_radiance
from .mitsuba_scene import build_geometry, sky_params
from .shader_inputs import INPUTS_VERSION

BASELINE_INPUTS_VERSION = 1  # bump whenever the construction below changes
# path-traced samples per pixel of the two views (only the dry walls and their shading are
# path traced: the floor under the water comes from the top-down texture); measured: see README
BASELINE_SPP = 32
BASELINE_FIELDS = ("scene_color", "scene_depth", "reflection_color", "reflection_view_proj")


def pixel_rays(view_proj: np.ndarray, width: int, height: int):
    """Rays through the pixel centres of a GL clip matrix: ``(origin (H, W, 3), unit direction
    (H, W, 3))`` float64, rows in GL order (row 0 = bottom); the origin is the camera."""
    inv = np.linalg.inv(np.asarray(view_proj, np.float64))
    S, T = np.meshgrid((np.arange(width) + 0.5) / width, (np.arange(height) + 0.5) / height)

    def unproject(zn):
        q = np.stack([2 * S - 1, 2 * T - 1, np.full_like(S, zn), np.ones_like(S)], -1) @ inv.T
        return q[..., :3] / q[..., 3:4]

    near, far = unproject(-1.0), unproject(1.0)
    d = far - near
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    # the eye: where all pixel rays meet (unproject of w = 0 in clip space)
    e = inv @ np.array([0.0, 0.0, -1.0, 0.0])
    eye = e[:3] / e[3]
    return np.broadcast_to(eye, d.shape).copy(), d


def _dry_scene(mi, exp: Experiment):
    d = {
        "type": "scene",
        **build_geometry(mi, exp, water=False),
        "sky": {"type": "envmap", "bitmap": mi.Bitmap(envmap_image(512, **sky_params(exp)))},
        "integrator": {"type": "path", "max_depth": exp.reference.max_depth},
    }
    return mi.load_dict(d)


def trace(mi, scene, origins: np.ndarray, dirs: np.ndarray, spp: int, seed: int):
    """Path-traced radiance along given rays:
    ``(radiance (N, 3), hit (N,) bool, hit point (N, 3))``. ``spp`` samples per ray (independent
    sampler), averaged."""
    n = len(origins)
    o = mi.Point3f(*(jit_input(mi.Float, origins[:, k]) for k in range(3)))
    d = mi.Vector3f(*(jit_input(mi.Float, dirs[:, k]) for k in range(3)))
    ray = mi.Ray3f(o, d)
    si = scene.ray_intersect(ray)
    hit = np.array(si.is_valid(), dtype=bool)
    p = np.stack([np.array(si.p[k], dtype=np.float64) for k in range(3)], -1)
    integrator = scene.integrator()
    sampler = mi.load_dict({"type": "independent"})
    acc = np.zeros((n, 3))
    for s in range(spp):
        sampler.seed(seed * 1_000_003 + s, n)
        spec, _, _ = integrator.sample(scene, sampler, mi.RayDifferential3f(ray))
        acc += np.stack([np.array(spec[k], dtype=np.float64) for k in range(3)], -1)
    return acc / spp, hit, p


def _bilinear(tex: np.ndarray, s: np.ndarray, t: np.ndarray) -> np.ndarray:
    """GL LINEAR + CLAMP_TO_EDGE lookup of an (H, W, C) texture at (s, t) (NumPy, float64)."""
    h, w = tex.shape[:2]
    u, v = s * w - 0.5, t * h - 0.5
    i0, j0 = np.floor(u).astype(int), np.floor(v).astype(int)
    a, b = (u - i0)[..., None], (v - j0)[..., None]
    i1, j1 = np.clip(i0 + 1, 0, w - 1), np.clip(j0 + 1, 0, h - 1)
    i0, j0 = np.clip(i0, 0, w - 1), np.clip(j0, 0, h - 1)
    return (
        (1 - a) * (1 - b) * tex[j0, i0]
        + a * (1 - b) * tex[j0, i1]
        + (1 - a) * b * tex[j1, i0]
        + a * b * tex[j1, i1]
    )


def camera_buffers(mi, exp: Experiment, inputs: ShaderInputs, width: int, height: int, spp: int):
    """``(scene_color (H, W, 3), scene_depth (H, W))`` of the camera's view without the water."""
    scene = _dry_scene(mi, exp)
    o, d = pixel_rays(inputs.view_proj, width, height)
    rad, hit, p = trace(mi, scene, o.reshape(-1, 3), d.reshape(-1, 3), spp, exp.reference.seed)
    vp = inputs.view_proj.astype(np.float64)
    clip = np.concatenate([p, np.ones_like(p[:, :1])], -1) @ vp.T
    depth = np.where(hit, 0.5 * clip[:, 2] / clip[:, 3] + 0.5, 1.0)
    sky = sky_radiance(d.reshape(-1, 3), **sky_params(exp, with_sun=False))
    colour = np.where(hit[:, None], rad, sky)
    # the floor under the water: the top-down texture's radiance of that point (what the raycast
    # shaders read), where the top-down view sees the same point
    st = np.concatenate([p, np.ones_like(p[:, :1])], -1) @ inputs.tex_matrix0.astype(np.float64).T
    wy = inputs.world_y
    hy, wx = wy.shape
    i = np.clip(np.floor(st[:, 0] * wx).astype(int), 0, wx - 1)
    j = np.clip(np.floor(st[:, 1] * hy).astype(int), 0, hy - 1)
    hx, hz = exp.pool.half_extent
    under = (
        hit
        & (p[:, 1] < 0.0)
        & (np.abs(p[:, 0]) < hx)
        & (np.abs(p[:, 2]) < hz)
        & (np.abs(wy[j, i] - p[:, 1]) < 0.05)
    )
    colour = np.where(
        under[:, None], _bilinear(inputs.refraction_texture, st[:, 0], st[:, 1]), colour
    )
    return (
        colour.reshape(height, width, 3).astype(np.float32),
        depth.reshape(height, width).astype(np.float32),
    )


def reflection_buffer(mi, exp: Experiment, rvp: np.ndarray, width: int, height: int, spp: int):
    """(H, W, 3) the scene above y = 0 seen by the mirrored camera ``rvp`` (clip plane y = 0)."""
    scene = _dry_scene(mi, exp)
    o, d = pixel_rays(rvp, width, height)
    o, d = o.reshape(-1, 3), d.reshape(-1, 3)
    up = d[:, 1] > 1e-6
    t = np.where(up, -o[:, 1] / np.where(up, d[:, 1], 1.0), 0.0)
    start = o + np.maximum(t, 0.0)[:, None] * d + np.array([0.0, 1e-4, 0.0])  # on the clip plane
    rad, hit, _ = trace(mi, scene, start, d, spp, exp.reference.seed + 1)
    sky = sky_radiance(d, **sky_params(exp, with_sun=False))
    colour = np.where((up & hit)[:, None], rad, sky)
    return colour.reshape(height, width, 3).astype(np.float32)


def build_baseline_inputs(exp: Experiment, inputs: ShaderInputs) -> dict:
    """The four optional ``ShaderInputs`` fields of the baseline shader at ``inputs``'
    resolution."""
    import mitsuba as mi

    w, h, spp = inputs.width, inputs.height, BASELINE_SPP
    colour, depth = camera_buffers(mi, exp, inputs, w, h, spp)
    rvp = mirrored_view_proj(inputs.view_proj)
    return {
        "scene_color": colour,
        "scene_depth": depth,
        "reflection_color": reflection_buffer(mi, exp, rvp, w, h, spp),
        "reflection_view_proj": rvp,
    }


def with_baseline_inputs(
    exp: Experiment, inputs: ShaderInputs, variant: str, cache=None, log=print
) -> ShaderInputs:
    """``inputs`` with the baseline buffers, from ``<cache>/inputs/baseline_<key>.npz`` when
    present, else built and written there atomically. The key hashes the experiment's
    shader-input values (``Experiment.inputs_hash``), the Mitsuba variant, the resolution,
    ``BASELINE_SPP``, ``BASELINE_INPUTS_VERSION`` and the package
    versions; the top-down texture they reuse is keyed by the same values."""
    key = hashlib.sha256(
        json.dumps(
            {
                "inputs": exp.inputs_hash(),
                "variant": variant,
                "scene_version": SCENE_VERSION,
                "inputs_version": INPUTS_VERSION,
                "baseline_version": BASELINE_INPUTS_VERSION,
                "spp": BASELINE_SPP,
                "size": [inputs.width, inputs.height],
                "versions": versions(),
            },
            sort_keys=True,
        ).encode()
    ).hexdigest()[:32]
    path = (cache or cache_dir()) / "inputs" / f"baseline_{key}.npz"
    fields = cached_fields(
        path, BASELINE_FIELDS, lambda: build_baseline_inputs(exp, inputs), "baseline inputs", log
    )
    return dataclasses.replace(inputs, **fields)


# the study's inputs a shader reads (``shaders_port.spirv.translated.STUDY_INPUTS``) that only the
# baseline's buffers hold
SCREEN_INPUTS = (
    "sceneColor",
    "sceneDepth",
    "reflection_sampler",
    "o2v_projection_reflection",
    "reflection_texture_matrix",
    "refraction_sampler",
    "depth_sampler",
)


def inputs_for_shader(
    exp: Experiment, inputs: ShaderInputs, shader: str, variant: str, cache=None, log=print
) -> ShaderInputs:
    """``inputs`` with whatever optional fields the shader ``shader`` reads: a variant's
    ``Variant.inputs`` (the screen-space buffers, of the baseline, the mirror and the
    screen-space reflection; the local cube map, ``box_inputs``), or, for
    a user's file (``*.frag``, with ``fit.declare``), the screen buffers when it reads one of
    :data:`SCREEN_INPUTS` (by name or through a binding); else ``inputs`` unchanged."""

    if is_user_shader(shader):
        reads = load_user_shader({**exp.values, "fit.shader": shader}).study_inputs()
        needs = any(n in reads for n in SCREEN_INPUTS)
    else:
        extra = get_variant(shader).inputs
        needs = any(f in BASELINE_FIELDS for f in extra)
        if "box_cubemap" in extra:
            inputs = with_box_inputs(exp, inputs, variant, cache=cache, log=log)
    if needs:
        return with_baseline_inputs(exp, inputs, variant, cache=cache, log=log)
    return inputs
