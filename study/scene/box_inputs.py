"""The local cube map of ``reflection = box`` (Lagarde and Zanuttini's box-projected cube map,
``shaders_port.ports.box``), from the experiment's Mitsuba scene without the water.

* ``box_min``, ``box_max``: the box of the pool's walls, ``(-hx, floor bottom, -hz)`` to
  ``(hx, pool.wall_height, hz)`` world units (``hx, hz = pool.half_extent``); its top is the
  walls' top.
* ``box_capture``: where the cube map is captured, the pool's centre at the walls' top,
  ``(0, pool.wall_height, 0)``. From there the upper half of the cube sees only the sky (the
  walls' tops are edge-on) and the lower half the walls' inner faces (and the dry floor), so
  a reflected ray that leaves the box through a wall, looked up towards its hit point, reads
  that point of the wall, and one that leaves through the top, looked up along itself, reads
  the sky: both exact for the pool's walls up to the texel size. A user's mesh above the water
  is captured too but projected onto the box (approximate).
* ``box_cubemap``: (6, F, F, 3) float32 linear RGB, ``F = BOX_CUBE_SIZE``, faces and ``y`` flip
  as the sky cube map (the texel of direction ``d`` holds the scene in direction
  ``d * (1, -1, 1)``): the rays from the capture point through the texel centres into the scene
  without the water (the reference's sky and sun, its path length), path traced at
  ``BOX_SPP`` where they hit geometry; a texel whose ray hits nothing is the sky cube map's
  (``user_scene.shader_cubemap``: no sun disc, the sun is the shader's highlight).

Noise: a texel's standard error is estimated from its samples. The shader reads only the
walls between the water and their top (:func:`wall_band`, a few percent of the texels); these
are traced at ``BOX_BAND_SPP``, the rest of the dry scene at ``BOX_SPP``, and the RMS standard
error of the band over its mean radiance is logged. Walls in shade are lit by the sky alone,
which the sun-dominated sampling of the environment finds slowly, hence the many samples on so
few texels; the cube is used as traced, not denoised (the band is a few texels high: a
denoiser would blur its edges). The walls are lit as in the scene without the water; the
reference lights them with the water in the pool (its floor's bounce reaches them through
the water), a little darker (docs/variants.md).

Cost: ``6 F^2`` rays, those that hit geometry (the lower half of the cube) path traced;
cached under ``<cache>/inputs/box_<key>.npz``, the key hashing the scene without the water
(``Experiment.dry_scene_hash``: not the camera, so every view shares it), the Mitsuba variant,
the size, the samples and ``BOX_INPUTS_VERSION``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np

from shaders_port import ShaderInputs
from shaders_port.inputs import BOX_INPUTS

from .._backend import jit_input
from ..config.experiment import Experiment
from .cache import SCENE_VERSION, cache_dir, cached_fields, versions
from .geometry import cubemap_directions
from .mitsuba_scene import build_geometry, floor_bottom
from .user_scene import reference_sky, shader_cubemap

BOX_INPUTS_VERSION = 1  # bump whenever the construction below changes
BOX_CUBE_SIZE = 128  # texels per face edge
BOX_SPP = 16  # path-traced samples per texel that sees geometry
BOX_BAND_SPP = 1024  # per texel of the walls above the water (the texels the shader reads)


def box_probe(exp: Experiment) -> dict:
    """``box_min``, ``box_max``, ``box_capture``: (3,) float32 each, world units (module doc)."""
    hx, hz = exp.pool.half_extent
    top = exp.pool.wall_height
    return {
        "box_min": np.array([-hx, floor_bottom(exp), -hz], np.float32),
        "box_max": np.array([hx, top, hz], np.float32),
        "box_capture": np.array([0.0, top, 0.0], np.float32),
    }


def _dry_scene(mi, exp: Experiment):
    return mi.load_dict(
        {
            "type": "scene",
            **build_geometry(mi, exp, water=False),
            "sky": {"type": "envmap", "bitmap": mi.Bitmap(reference_sky(exp))},
            "integrator": {"type": "path", "max_depth": exp.reference.max_depth},
        }
    )


def _trace(mi, scene, origins: np.ndarray, dirs: np.ndarray, spp: int, seed: int):
    """Path-traced radiance along rays (N, 3) float64: ``(mean (N, 3), standard error (N, 3))``
    from ``spp`` independent samples per ray, the sampler seeded ``seed``, ``seed + 1``, ..."""

    def vec(cls, a):
        return cls(*(jit_input(mi.Float, a[:, k]) for k in range(3)))

    n = len(dirs)
    ray = mi.RayDifferential3f(mi.Ray3f(vec(mi.Point3f, origins), vec(mi.Vector3f, dirs)))
    integrator, sampler = scene.integrator(), mi.load_dict({"type": "independent"})
    acc, acc2 = np.zeros((n, 3)), np.zeros((n, 3))
    for s in range(spp):
        sampler.seed((seed + s) % 2**32, n)
        spec, _, _ = integrator.sample(scene, sampler, ray)
        x = np.stack([np.array(spec[k], dtype=np.float64) for k in range(3)], -1)
        acc += x
        acc2 += x * x
    mean = acc / spp
    return mean, np.sqrt(np.maximum(acc2 / spp - mean**2, 0.0) / max(spp - 1, 1))


def wall_band(exp: Experiment, dirs: np.ndarray, size: int) -> np.ndarray:
    """(N,) bool: the directions (N, 3) from the capture point that a lookup of the shader can
    reach, up to a bilinear footprint: those that meet the box's walls between the water plane
    (less 1.5 texels of height there) and the walls' top."""
    p = box_probe(exp)
    lo, hi, c = (p[k].astype(np.float64) for k in ("box_min", "box_max", "box_capture"))
    plane = np.where(dirs > 0, hi, lo)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.abs(plane - c) / np.abs(dirs)
    t = np.min(t[:, [0, 2]], -1)
    y = c[1] + t * dirs[:, 1]
    margin = 1.5 * t * 2.0 / size  # a texel spans about 2 / size radians near the horizon
    return (y < hi[1]) & (y >= -margin)


def capture_cube(exp: Experiment, size: int, spp: int, band_spp: int):
    """``(box_cubemap (6, size, size, 3) float32 linear RGB, info)`` seen from
    ``box_probe(exp)['box_capture']`` (module doc): texels whose ray hits geometry traced at
    ``spp`` samples, those the shader reads (:func:`wall_band`) at ``band_spp``. ``info``:
    ``traced`` and ``band`` (the fractions of texels), ``noise`` (the RMS standard error of the
    band's texels over their mean radiance)."""
    import mitsuba as mi

    scene = _dry_scene(mi, exp)
    dirs = (cubemap_directions(size) * np.array([1.0, -1.0, 1.0])).reshape(-1, 3)
    o = np.broadcast_to(box_probe(exp)["box_capture"].astype(np.float64), dirs.shape)
    pts = [jit_input(mi.Float, a[:, k]) for a in (o, dirs) for k in range(3)]
    ray = mi.Ray3f(mi.Point3f(*pts[:3]), mi.Vector3f(*pts[3:]))
    hit = np.array(scene.ray_intersect(ray).is_valid()).astype(bool)
    band = hit & wall_band(exp, dirs, size)
    rest = hit & ~band
    cube = shader_cubemap(exp, size).reshape(-1, 3).astype(np.float64)
    seed = exp.reference.seed * 1_000_003 + 500_009  # apart from the other renders' seeds
    if rest.any():
        cube[rest] = _trace(mi, scene, o[rest], dirs[rest], spp, seed)[0]
    noise = 0.0
    if band.any():
        cube[band], se = _trace(mi, scene, o[band], dirs[band], band_spp, seed + spp)
        level = float(cube[band].mean())
        noise = float(np.sqrt((se**2).mean()) / level) if level > 0 else 0.0
    n = len(dirs)
    info = {"traced": float(hit.sum() / n), "band": float(band.sum() / n), "noise": noise}
    return cube.reshape(6, size, size, 3).astype(np.float32), info


def build_box_inputs(exp: Experiment, log=print) -> dict:
    """The four ``box_*`` fields of ``ShaderInputs`` (module doc)."""
    cube, info = capture_cube(exp, BOX_CUBE_SIZE, BOX_SPP, BOX_BAND_SPP)
    log(
        f"local cube map: {BOX_CUBE_SIZE}^2 texels per face, {info['traced']:.0%} traced at "
        f"{BOX_SPP} spp, the walls above the water ({info['band']:.1%}) at {BOX_BAND_SPP} spp, "
        f"their noise {info['noise']:.2e} (RMS standard error over the mean)"
    )
    return {"box_cubemap": cube, **box_probe(exp)}


def with_box_inputs(
    exp: Experiment, inputs: ShaderInputs, variant: str, cache=None, log=print
) -> ShaderInputs:
    """``inputs`` with the local cube map and its box, from ``<cache>/inputs/box_<key>.npz``
    when present, else built and written there (module doc: the key)."""
    key = hashlib.sha256(
        json.dumps(
            {
                "dry_scene": exp.dry_scene_hash(),
                "variant": variant,
                "scene_version": SCENE_VERSION,
                "box_version": BOX_INPUTS_VERSION,
                "size": BOX_CUBE_SIZE,
                "spp": [BOX_SPP, BOX_BAND_SPP],
                "versions": versions(),
            },
            sort_keys=True,
        ).encode()
    ).hexdigest()[:32]
    path = (cache or cache_dir()) / "inputs" / f"box_{key}.npz"
    fields = cached_fields(
        path, BOX_INPUTS, lambda: build_box_inputs(exp, log), "local cube map", log
    )
    return dataclasses.replace(inputs, **fields)
