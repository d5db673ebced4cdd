"""Resolution as a choice the tool makes: the named presets ``resolution`` and ``fit.resolution``
take in place of ``[width, height]``, and the rule behind ``fit.resolution = "auto"``.

* :data:`PRESETS`: ``"720p"`` (1280 x 720), ``"1080p"`` (1920 x 1080), ``"1440p"`` (2560 x 1440).
* :func:`supersample_factor`: how many samples per side a fit pixel takes so that it is shaded
  at the pixel footprint of ``fit.target_resolution``, the resolution the game runs at.
* :func:`auto_fit_resolution`: the largest image that divides ``resolution`` by one integer
  factor ``f`` on both axes (the reference is box-downsampled ``f x f`` to it, so its pixels stay
  square) and whose pixel count stays within the device's budget, :data:`FIT_PIXELS`: on the CPU
  (Dr.Jit's LLVM backend) 128 x 128 pixels, what the fit's default costs; on a CUDA device the
  pixels of 1920 x 1080, so a game's resolution up to 1080p is fitted at full resolution.

A pure function of the numbers; which device a run uses is ``study._backend``'s choice.
"""

from __future__ import annotations

import math

from .errors import ExperimentError

PRESETS: dict[str, tuple[int, int]] = {
    "720p": (1280, 720),
    "1080p": (1920, 1080),
    "1440p": (2560, 1440),
}
AUTO = "auto"

# the most pixels the fit's image has with fit.resolution = "auto", per Dr.Jit backend
FIT_PIXELS: dict[str, int] = {"llvm": 128 * 128, "cuda": 1920 * 1080}
MIN_SIDE = 8  # the schema's smallest fit.resolution side
# the most samples per side of a fit pixel (16 per pixel): the fit's cost grows as its square
MAX_SUPERSAMPLE = 4


def supersample_factor(fit_resolution, target_resolution) -> int:
    """Samples per side of a fit pixel (an int in 1..:data:`MAX_SUPERSAMPLE`) that shade it at
    the footprint of a pixel of ``target_resolution`` ([width, height], the game's; None: no
    supersampling): the target's rows over the fit's, rounded. Rows, since the camera's field
    of view is vertical (``camera.fov_y``): a target of another aspect than the scene keeps
    the pixel's angular size."""
    if target_resolution is None:
        return 1
    ratio = target_resolution[1] / fit_resolution[1]
    return int(min(MAX_SUPERSAMPLE, max(1, round(ratio))))


def auto_fit_resolution(resolution, device: str) -> list[int]:
    """``fit.resolution = "auto"``: ``[width, height]`` (pixels, ints) of the fit for a scene of
    ``resolution`` ``[width, height]`` on ``device`` ("llvm": the CPU, "cuda": an NVIDIA GPU):
    ``resolution / f`` for the smallest integer ``f`` that divides both sides and leaves at most
    ``FIT_PIXELS[device]`` pixels (see the module doc). ExperimentError naming the fix when no
    such factor leaves both sides at least 8 pixels (sides with no common factor)."""
    if device not in FIT_PIXELS:
        raise ValueError(f"device must be one of {', '.join(FIT_PIXELS)}, got {device!r}")
    w, h = (int(v) for v in resolution)
    budget = FIT_PIXELS[device]
    g = math.gcd(w, h)
    for f in range(1, g + 1):
        if g % f == 0 and (w // f) * (h // f) <= budget:
            if min(w // f, h // f) < MIN_SIDE:
                break
            return [w // f, h // f]
    raise ExperimentError(
        f'fit.resolution = "auto": no factor common to both sides of resolution [{w}, {h}] '
        f"brings the fit within {budget} pixels ({device}) with both sides at least "
        f"{MIN_SIDE}; set fit.resolution to [width, height] dividing resolution, or use a "
        f"resolution whose sides share a factor (e.g. {', '.join(PRESETS)})"
    )
