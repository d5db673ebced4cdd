"""Error metrics on water pixels, and the pieces every comparison needs.

* RMSE in linear RGB over the water pixels (all three channels).
* FLIP (``flip-evaluator``), LDR variant: both images are linear RGB clipped to [0, 1] (what
  a display shows without tone mapping) and passed with ``inputsRGB=False``; the mean of
  the FLIP map over the water pixels is reported. Default viewing conditions (67 ppd).
* The water mask: pixels whose centre sees the water quad, eroded by one pixel so that no
  pixel whose footprint also covers the pool wall is scored (the reference integrates the
  pixel footprint with a box filter, the shader shades the centre only).
"""

from __future__ import annotations

import numpy as np


def erode(mask: np.ndarray, r: int = 1) -> np.ndarray:
    """Binary erosion with a (2r+1)^2 square; pixels outside the image count as False."""
    m = np.asarray(mask, bool)
    out = m.copy()
    h, w = m.shape
    p = np.pad(m, r, constant_values=False)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            out &= p[r + dy : r + dy + h, r + dx : r + dx + w]
    return out


def downsample(img: np.ndarray, factor_y: int, factor_x: int) -> np.ndarray:
    """Box-filter an (H, W, ...) image by integer factors (a larger pixel's footprint)."""
    h, w = img.shape[:2]
    if h % factor_y or w % factor_x:
        raise ValueError(f"cannot box-downsample {w}x{h} by {factor_x}x{factor_y}")
    s = img.reshape(h // factor_y, factor_y, w // factor_x, factor_x, *img.shape[2:])
    return s.mean(axis=(1, 3))


def downsample_stderr(se: np.ndarray, factor_y: int, factor_x: int) -> np.ndarray:
    """The standard error of :func:`downsample`'s box mean of pixels with independent errors of
    standard error ``se`` (H, W, ...): ``sqrt(mean(se^2) / (factor_y * factor_x))``."""
    return np.sqrt(
        downsample(np.square(se, dtype=np.float64), factor_y, factor_x) / (factor_y * factor_x)
    )


def check_finite(name: str, img: np.ndarray, mask: np.ndarray | None = None) -> None:
    """Raise ValueError when ``img`` has non-finite values (inside ``mask`` if given)."""
    bad = ~np.isfinite(img)
    if bad.ndim == 3:
        bad = bad.any(-1)
    if mask is not None:
        bad &= mask
    if bad.any():
        raise ValueError(f"{name}: {int(bad.sum())} pixels are not finite; refusing to score them")


def rmse(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    """RMSE over the masked pixels of two (H, W, 3) linear RGB images."""
    check_finite("rmse input", a, mask)
    check_finite("rmse input", b, mask)
    if not mask.any():
        raise ValueError("rmse: the water mask is empty; does the camera see the water?")
    d = (np.asarray(a, np.float64) - np.asarray(b, np.float64))[mask]
    return float(np.sqrt(np.mean(d**2)))


def flip_map(reference: np.ndarray, test: np.ndarray) -> np.ndarray:
    """(H, W) LDR-FLIP error map of two linear RGB images (clipped to [0, 1])."""
    import flip_evaluator

    ref = np.ascontiguousarray(np.clip(reference, 0, 1), dtype=np.float32)
    tst = np.ascontiguousarray(np.clip(test, 0, 1), dtype=np.float32)
    fmap, _, _ = flip_evaluator.evaluate(
        ref, tst, "LDR", inputsRGB=False, applyMagma=False, computeMeanError=False
    )
    fmap = np.asarray(fmap, np.float32)
    return fmap[..., 0] if fmap.ndim == 3 else fmap


def flip(reference: np.ndarray, test: np.ndarray, mask: np.ndarray) -> float:
    """Mean LDR-FLIP over the masked pixels."""
    check_finite("flip input", reference, mask)
    check_finite("flip input", test, mask)
    return float(flip_map(reference, test)[mask].mean())


def errors(reference: np.ndarray, test: np.ndarray, mask: np.ndarray) -> dict:
    """RMSE and mean FLIP on the masked pixels, and ``flip_map``, FLIP per pixel (H, W)
    float32 over the whole image."""
    check_finite("flip input", reference, mask)
    check_finite("flip input", test, mask)
    fmap = flip_map(reference, test)
    return {"rmse": rmse(reference, test, mask), "flip": float(fmap[mask].mean()),
            "flip_map": fmap}  # fmt: skip


def information_criteria(residual: np.ndarray, k: int) -> dict:
    """AIC and BIC of a least-squares fit with ``k`` fitted constants from its residual
    (``residual``: (n,) port - reference over the scored water pixels and RGB channels).

    With i.i.d. Gaussian errors of unknown variance the maximised log-likelihood is
    ``-n/2 ln(RSS/n)`` up to a constant, so ``AIC = n ln(RSS/n) + 2k`` and
    ``BIC = n ln(RSS/n) + k ln n``. Only differences between shaders fitted on the same
    reference, mask and resolution mean anything (lower is better; a BIC difference above
    10 is conventionally "very strong" evidence). Caveat: neighbouring residuals are
    correlated (shader model error is spatially smooth), so the effective n is smaller than
    the count of residuals and the penalty per constant is understated: a richer shader that
    wins by a few units has not earned its constants.

    Returns ``{"n": n, "k": k, "rss": RSS, "aic": AIC, "bic": BIC}``.
    """
    r = np.asarray(residual, dtype=np.float64).ravel()
    n = r.size
    if n <= k or not np.all(np.isfinite(r)):
        raise ValueError(
            f"information criteria need a finite residual longer than k = {k} (got n = {n})"
        )
    rss = float(r @ r)
    ll = n * np.log(max(rss, 1e-300) / n)
    return {
        "n": int(n),
        "k": int(k),
        "rss": rss,
        "aic": float(ll + 2 * k),
        "bic": float(ll + k * np.log(n)),
    }


def temporal_errors(
    references: list,
    shaded: list,
    mask: np.ndarray,
    stderr: list | None = None,
    passes: list | None = None,
) -> dict:
    """The shader's frame-to-frame change against the reference's, on the masked pixels.

    ``references``, ``shaded``: the frames (n >= 2 of (H, W, 3) linear RGB each); ``mask``: (H, W)
    bool, the pixels that are water in every frame; ``stderr``: the references' per-pixel
    standard errors (optional). With ``dR_k = R_{k+1} - R_k`` and ``dS_k = S_{k+1} - S_k``:

    * ``trmse``: RMS of ``dS - dR`` over pairs, pixels and channels (0: the shader changes from
      frame to frame exactly as the reference does); ``per_pair``: the same for each pair;
    * ``reference_change``, ``shader_change``: RMS of ``dR`` and of ``dS``; ``change_ratio``:
      shader over reference (below 1 the shader moves less than the water, above 1 it flickers
      more);
    * ``noise_floor`` (with ``stderr``): ``sqrt(mean(se_k^2 + se_{k+1}^2))``, the RMS of ``dR``'s
      Monte Carlo noise if the frames' samples were independent (an upper bound here: the frames
      share their sampler seeds, so part of their noise cancels in ``dR``); a ``trmse`` near it
      is within the reference's noise;
    * ``noise`` (with ``passes``: each frame's independent passes (P, H, W, 3), or None where not
      kept): the RMS standard error of ``dR`` measured from the spread over the passes of the
      passes' own differences (the frames' shared seeds included), over the pairs whose two frames
      have passes (``noise_pairs`` of them); ``trmse_excess``: ``sqrt(max(trmse^2 - noise^2, 0))``,
      the part of ``trmse`` the reference's noise does not explain; ``reference_change_excess``:
      ``sqrt(max(reference_change^2 - noise^2, 0))``, the reference's change without its noise,
      and ``change_ratio_excess``: ``shader_change`` over it;
    * ``maps``: (H, W) float32 maps of the RMS over pairs and channels of ``dS - dR``
      (``flicker``), ``dR`` (``reference``) and ``dS`` (``shader``), 0 outside ``mask``.

    Raises ValueError on fewer than two frames, mismatched shapes, an empty mask or non-finite
    pixels in the mask."""
    n = len(references)
    if n < 2 or len(shaded) != n:
        raise ValueError(
            f"a temporal error needs two or more frames on both sides (got {n} references, "
            f"{len(shaded)} shader frames); set animation.frames >= 2"
        )
    if not mask.any():
        raise ValueError("temporal error: no pixel is water in every frame")
    for i, (a, b) in enumerate(zip(references, shaded)):
        if a.shape != b.shape or a.shape[:2] != mask.shape:
            raise ValueError(f"temporal error: frame {i} shapes {a.shape}, {b.shape}, {mask.shape}")
        check_finite(f"temporal error, reference frame {i}", a, mask)
        check_finite(f"temporal error, shader frame {i}", b, mask)
    R = np.stack([np.asarray(a, np.float64) for a in references])
    S = np.stack([np.asarray(b, np.float64) for b in shaded])
    dR, dS = np.diff(R, axis=0), np.diff(S, axis=0)
    e = (dS - dR)[:, mask]  # (n - 1, m, 3)
    out = {
        "trmse": float(np.sqrt(np.mean(e**2))),
        "per_pair": [float(np.sqrt(np.mean(p**2))) for p in e],
        "reference_change": float(np.sqrt(np.mean(dR[:, mask] ** 2))),
        "shader_change": float(np.sqrt(np.mean(dS[:, mask] ** 2))),
    }
    ref_change = out["reference_change"]
    out["change_ratio"] = out["shader_change"] / ref_change if ref_change > 0 else float("inf")
    if stderr is not None:
        v = np.stack([np.square(np.asarray(s, np.float64)) for s in stderr])
        out["noise_floor"] = float(np.sqrt(np.mean((v[1:] + v[:-1])[:, mask])))
    if passes is not None:
        var = [
            np.var(np.asarray(b, np.float64) - a, axis=0, ddof=1)[mask] / len(a)
            for a, b in zip(passes[:-1], passes[1:])
            if a is not None and b is not None
        ]
        if var:
            out["noise"] = float(np.sqrt(np.mean(var)))
            out["noise_pairs"] = len(var)
            out["trmse_excess"] = float(np.sqrt(max(out["trmse"] ** 2 - out["noise"] ** 2, 0.0)))
            rc = float(np.sqrt(max(ref_change**2 - out["noise"] ** 2, 0.0)))
            out["reference_change_excess"] = rc
            out["change_ratio_excess"] = out["shader_change"] / rc if rc > 0 else float("inf")

    def rms_map(d):
        m = np.sqrt(np.mean(d**2, axis=(0, 3))).astype(np.float32)
        return np.where(mask, m, 0.0).astype(np.float32)

    out["maps"] = {"flicker": rms_map(dS - dR), "reference": rms_map(dR), "shader": rms_map(dS)}
    return out
