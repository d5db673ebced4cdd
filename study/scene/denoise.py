"""Open Image Denoise on the top-down renders, and the check of what it does to their mean."""

from __future__ import annotations

import numpy as np


def denoise_radiance(radiance: np.ndarray, albedo: np.ndarray) -> np.ndarray:
    """Open Image Denoise (``RT`` filter, HDR, high quality) of a (n, n, 3) float32 linear-RGB
    radiance image guided by its noise-free (n, n, 3) albedo; returns (n, n, 3) float32."""
    try:
        import pyoidn
    except ImportError as e:  # pragma: no cover - pinned dependency
        raise RuntimeError(
            'reference.lighting_denoise = "oidn" needs the pyoidn package '
            "(pip install pyoidn, pinned in pyproject.toml)"
        ) from e
    out = pyoidn.denoise(
        np.ascontiguousarray(radiance, np.float32),
        np.ascontiguousarray(albedo, np.float32),
        hdr=True,
        clean_aux=True,
        quality="high",
    )
    out = np.asarray(out, np.float32)
    if out.shape != radiance.shape or not np.all(np.isfinite(out)):
        raise RuntimeError("Open Image Denoise returned a non-finite or misshapen image")
    return np.maximum(out, 0.0)


def denoise_gain(
    denoised: np.ndarray, raw: np.ndarray, raw_se: np.ndarray, n_independent: float | None = None
) -> tuple[list, list]:
    """Per colour channel, the mean of the ``denoised`` texels over the mean of the ``raw`` texels
    they were denoised from (each (..., 3), linear RGB), and the standard error of that ratio from
    the raw texels' standard errors ``raw_se`` (..., 3), ``n_independent`` of them independent
    (default: every texel). The raw mean is unbiased, so a ratio away from 1 by several standard
    errors is the denoiser's own bias in the texture's brightness (docs/fast-references.md). A
    channel whose raw mean is not positive (no light at all) gets the ratio 1 and error 0."""
    m_raw = raw.reshape(-1, 3).astype(np.float64).mean(0)
    lit = m_raw > 0.0
    safe = np.where(lit, m_raw, 1.0)
    gain = np.where(lit, denoised.reshape(-1, 3).mean(0) / safe, 1.0)
    n = raw.size // 3 if n_independent is None else n_independent
    se = np.where(
        lit, np.sqrt((raw_se.reshape(-1, 3).astype(np.float64) ** 2).mean(0) / n) / safe * gain, 0.0
    )
    return [float(g) for g in gain], [float(e) for e in se]
