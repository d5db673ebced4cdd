"""Path-traced reference images: rendering, measured noise, automatic spp, and the cache.

Noise is measured, never assumed: a reference is the mean of ``K`` renders with
independent sampler seeds, and the per-pixel standard error of that mean is estimated
from their spread (unbiased sample variance / K). The scalar noise figure is the RMS of the
standard error over the water pixels, in linear RGB.

Each pass samples with ``reference.sampler`` (``multijitter`` by default: Kensler's correlated
multi-jittered strata, less variance than the independent sampler's at equal samples); the
passes' seeds are independent, so their spread estimates the standard error of the mean for
any sampler. Mitsuba's ``stratified`` sampler reduces the variance as much but draws
consecutive dimensions from permutations with consecutive seeds, which correlates them, and
that biases volumetric path tracing: deep, chromatic water comes out too bright
(docs/fast-references.md, "Multi-jittered sampling").

Automatic spp renders a pilot (``K`` x ``PILOT_SPP``), estimates the per-sample variance on
the water pixels and picks the smallest power of two whose predicted noise is below
``reference.target_noise`` (capped at ``reference.max_spp``; the cap is reported).

Cache: ``<cache>/references/<key>.exr`` where the key hashes every experiment value that
affects the image, the spp policy, the variant, the versions of Mitsuba and Dr.Jit and
``SCENE_VERSION`` (bumped whenever the scene construction changes). The EXR header carries
the full provenance and the key is re-checked on load, so a stale or foreign file is never
reused. Files are written atomically.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._backend import jit_input
from .._io import file_lock, read_exr, write_exr
from ..config.experiment import Experiment
from .cache import SCENE_VERSION, cache_dir, versions
from .mitsuba_scene import build_scene, sampler_spp

N_SEEDS = 4
PILOT_SPP = 8


@dataclass
class Reference:
    """A reference image with its provenance.

    Attributes:
        image: (H, W, 3) float32 linear RGB, row 0 at the top.
        stderr: (H, W, 3) float32 per-pixel standard error of ``image``.
        provenance: dict (hash, spp, seeds, variant, versions, seconds, noise, ...).
        path: the cached EXR, if any.
        passes: (N_SEEDS, H, W, 3) float32 the independent passes ``image`` is the mean of, when
            kept (``keep_passes``: an animation's frames, whose frame-to-frame differences take
            their noise from them); None otherwise.
    """

    image: np.ndarray
    stderr: np.ndarray
    provenance: dict
    path: Path | None = None
    passes: np.ndarray | None = None

    @property
    def noise(self) -> float:
        return float(self.provenance["noise"])

    @property
    def spp(self) -> int:
        return int(self.provenance["spp"])


def reference_key(exp: Experiment, variant: str) -> str:
    data = {
        "scene": exp.scene_hash(),
        "variant": variant,
        "scene_version": SCENE_VERSION,
        "versions": versions(),
        "n_seeds": N_SEEDS,
    }
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:32]


def pass_spp(exp: Experiment, spp: int) -> int:
    """Samples per pixel of one of ``N_SEEDS`` passes that together take at least ``spp``,
    rounded up to a count ``reference.sampler`` can stratify (:func:`~.mitsuba_scene.sampler_spp`:
    128 spp are 4 passes of 35 for ``multijitter``, of 36 for ``stratified``)."""
    return sampler_spp(exp.reference.sampler, max(1, math.ceil(spp / N_SEEDS)))


def spp_text(provenance: dict) -> str:
    """The samples per pixel of a reference, with why they differ from those asked for when they
    do: ``"140 spp (128 asked, rounded up to 4 passes of 35 for the multijitter sampler)"``
    (``provenance``: a :class:`Reference`'s; one rendered before ``spp_asked`` was recorded gives
    ``"140 spp"``)."""
    spp, asked = int(provenance["spp"]), provenance.get("spp_asked")
    if asked is None or int(asked) == spp:
        return f"{spp} spp"
    return (
        f"{spp} spp ({int(asked)} asked, rounded up to {provenance['n_seeds']} passes of "
        f"{provenance['spp_per_pass']} for the {provenance['sampler']} sampler)"
    )


def render_passes(
    exp: Experiment, spp_per_pass: int, n_passes: int, seed0: int, progress=None, scene=None
) -> np.ndarray:
    """(n_passes, H, W, 3) float32 renders with independent seeds ``seed0 + i``
    (of ``scene``, default: ``build_scene(exp)``)."""
    import mitsuba as mi

    scene = scene if scene is not None else build_scene(exp)
    out = []
    for i in range(n_passes):
        img = mi.render(scene, spp=spp_per_pass, seed=seed0 + i)
        out.append(np.array(img, dtype=np.float32))
        if progress:
            progress(i + 1, n_passes)
    return np.stack(out)


_MASKS: dict = {}  # (scene hash, width, height) -> water mask, per process


def water_mask(exp: Experiment, width: int, height: int, scene=None) -> np.ndarray:
    """(H, W) bool, row 0 at the top: pixels whose centre's camera ray first hits the water
    surface in the reference scene (not a wall in front of it, not the sky). ``scene``: the
    reference scene at (width, height) if already built. Remembered per process (keyed on
    the scene hash and the size, so a changed scene is cast again)."""
    import drjit as dr
    import mitsuba as mi

    memo = (exp.scene_hash(), SCENE_VERSION, width, height)
    if memo in _MASKS:
        return _MASKS[memo].copy()
    if scene is None or tuple(scene.sensors()[0].film().crop_size()) != (width, height):
        scene = build_scene(exp, width, height)
    sensor = scene.sensors()[0]
    j, i = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    uv = mi.Point2f(
        jit_input(mi.Float, ((i.ravel() + 0.5) / width).astype(np.float32)),
        jit_input(mi.Float, ((j.ravel() + 0.5) / height).astype(np.float32)),
    )
    ray, _ = sensor.sample_ray(0.0, 0.0, uv, mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(ray)
    is_water = si.is_valid() & mi.has_flag(si.bsdf().flags(), mi.BSDFFlags.DeltaTransmission)
    mask = np.array(dr.select(is_water, 1, 0), dtype=bool).reshape(height, width)
    _MASKS[memo] = mask
    return mask.copy()


def noise_of(passes: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, float]:
    """Per-pixel standard error of the mean of ``passes`` and its RMS over ``mask``."""
    k = passes.shape[0]
    if k < 2:
        raise ValueError("noise estimation needs at least two independent passes")
    se = np.sqrt(passes.var(axis=0, ddof=1) / k).astype(np.float32)
    return se, float(np.sqrt(np.mean(se[mask] ** 2)))


def choose_spp(exp: Experiment, progress=None, scene=None) -> tuple[int, dict]:
    """Pick spp for ``reference.target_noise`` from a measured pilot; return (spp, info).
    ``scene``: the loaded scene of ``exp`` (default: built here)."""
    w, h = exp.resolution
    t0 = time.perf_counter()

    scene = build_scene(exp) if scene is None else scene
    per_pass = sampler_spp(exp.reference.sampler, PILOT_SPP)  # K passes of PILOT_SPP
    pilot = render_passes(
        exp, per_pass, N_SEEDS, seed0=10_000 + exp.reference.seed, scene=scene, progress=progress
    )
    _, pilot_noise = noise_of(pilot, water_mask(exp, w, h, scene=scene))
    total_pilot = per_pass * N_SEEDS
    per_sample_var = pilot_noise**2 * total_pilot  # noise^2 = var / spp_total
    target = exp.reference.target_noise
    need = per_sample_var / target**2
    spp = 2 ** max(2, math.ceil(math.log2(max(need, 1.0))))
    spp = max(N_SEEDS, min(spp, exp.reference.max_spp))
    info = {
        "pilot_spp": total_pilot,
        "pilot_noise": pilot_noise,
        "predicted_spp": need,
        "capped": bool(need > exp.reference.max_spp),
        "pilot_seconds": time.perf_counter() - t0,
    }
    return spp, info


def render_reference(
    exp: Experiment,
    variant: str,
    spp: int | None = None,
    progress=None,
    scene=None,
    keep_passes: bool = False,
) -> Reference:
    """Render the reference (no cache): ``N_SEEDS`` independent passes, mean and noise.
    ``scene``: the loaded scene of ``exp`` (:func:`~.mitsuba_scene.build_scene`, e.g. one
    animation frame's scene moved to this frame's waves), default: built here."""
    info = {}
    if spp is None:
        spp, info = (
            choose_spp(exp, progress, scene)
            if exp.reference.spp == "auto"
            else (int(exp.reference.spp), {})
        )
    per_pass = pass_spp(exp, spp)

    scene = build_scene(exp) if scene is None else scene
    t0 = time.perf_counter()
    passes = render_passes(
        exp,
        per_pass,
        N_SEEDS,
        seed0=exp.reference.seed * N_SEEDS,
        progress=progress,
        scene=scene,
    )
    seconds = time.perf_counter() - t0
    w, h = exp.resolution
    mask = water_mask(exp, w, h, scene=scene)
    stderr, noise = noise_of(passes, mask)
    image = passes.mean(0)
    if not np.all(np.isfinite(image)):
        raise RuntimeError(
            f"the reference render of {exp.name!r} has non-finite pixels; "
            "check the scene (e.g. degenerate geometry)"
        )
    prov = {
        "key": reference_key(exp, variant),
        "scene_hash": exp.scene_hash(),
        "experiment": exp.name,
        "spp": per_pass * N_SEEDS,
        "spp_asked": int(spp),
        "spp_per_pass": per_pass,
        "sampler": exp.reference.sampler,
        "n_seeds": N_SEEDS,
        "seed": exp.reference.seed,
        "variant": variant,
        "versions": versions(),
        "scene_version": SCENE_VERSION,
        "render_seconds": seconds,
        "noise": noise,
        "auto_spp": info,
        "integrator": "volpath" if any(v > 0 for v in exp.water.sigma_t) else "path",
    }
    return Reference(image.astype(np.float32), stderr, prov, passes=passes if keep_passes else None)


def load_or_render(
    exp: Experiment,
    variant: str,
    cache: Path | None = None,
    progress=None,
    log=print,
    scene=None,
    keep_passes: bool = False,
) -> Reference:
    """The cached reference of ``exp`` if its key matches, else a fresh render written to the cache.

    Safe with concurrent callers (a sweep's workers): a miss takes the entry's lock, looks again
    (another process may have rendered it meanwhile) and only then renders, so one key is
    rendered once. ``scene``: a callable returning the loaded scene of ``exp``, called on a miss
    only (an animation's frames share one scene, :class:`~.animation.FrameShared`); ``keep_passes``:
    a fresh render keeps its passes (``Reference.passes``, stored in the EXR as layers
    ``pass0..``; a cached file has them when it was rendered so)."""
    cache = (cache or cache_dir()) / "references"
    key = reference_key(exp, variant)
    path = cache / f"{key}.exr"
    ref = _cached_reference(exp, key, path, log)
    if ref is not None:
        return ref
    with file_lock(path.with_suffix(".lock"), "reference", log):
        ref = _cached_reference(exp, key, path, log)
        if ref is not None:
            return ref
        ref = render_reference(
            exp,
            variant,
            progress=progress,
            scene=scene() if scene is not None else None,
            keep_passes=keep_passes,
        )
        extra = {"stderr": ref.stderr}
        if ref.passes is not None:
            extra.update({f"pass{i}": p for i, p in enumerate(ref.passes)})
        write_exr(path, ref.image, ref.provenance, extra=extra)
    ref.path = path
    log(
        f"reference: rendered {spp_text(ref.provenance)} in "
        f"{ref.provenance['render_seconds']:.1f} s, "
        f"noise {ref.noise:.2e}; cached at {path}"
    )
    return ref


def _cached_reference(exp: Experiment, key: str, path: Path, log) -> Reference | None:
    """The reference stored at ``path`` if it is readable and is the one of ``key``, else None."""
    if not path.exists():
        return None
    try:
        rgb, prov, extra = read_exr(path)
        se = extra.get("stderr")
        if (
            prov.get("key") == key
            and rgb.shape[:2] == tuple(exp.resolution[::-1])
            and se is not None
            and se.shape == rgb.shape
        ):
            log(f"reference: cached {path} ({spp_text(prov)}, noise {prov['noise']:.2e})")
            passes = [extra.get(f"pass{i}") for i in range(N_SEEDS)]
            kept = np.stack(passes) if all(p is not None for p in passes) else None
            return Reference(rgb, se, prov, path, passes=kept)
        log(f"reference: {path} does not match this experiment; re-rendering")
    except ValueError as exc:
        log(f"reference: unreadable cache file ({exc}); re-rendering")
    return None
