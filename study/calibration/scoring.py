"""The score of constants on a frame at the frame's full resolution, written once.

Every command and sweep judges a constants block the same way: the shader rendered at the
experiment's resolution on the frame's inputs, RMSE (linear RGB) and FLIP
(``study._metrics``) against the reference on the scored water pixels, and the render's
diagnostics (fetches, iterations, rays that did not cross, non-finite pixels). A
:class:`Scorer` builds each frame's full-resolution model once and scores any number of
constants blocks on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._backend import drjit_backend
from .._metrics import errors


@dataclass
class Score:
    """One constants block on one frame: ``image`` (H, W, 3) float32 linear RGB, ``mask``
    (H, W) bool (the scored water pixels), ``rmse`` and ``flip`` on them, ``diagnostics``
    (the render's ``Diagnostics``: ``maps`` name -> (H, W) and ``summary(mask)``),
    ``flip_map`` (H, W) float32 (FLIP per pixel, over the whole image: ``flip`` is its mean
    on ``mask``)."""

    image: np.ndarray
    mask: np.ndarray
    rmse: float
    flip: float
    diagnostics: object
    flip_map: np.ndarray | None = None

    @property
    def errors(self) -> dict:
        return {"rmse": self.rmse, "flip": self.flip}

    def per_pixel(self, keys=("fetches", "iterations", "refl_iterations")) -> dict:
        """Mean and 99th percentile over the water of each diagnostics map in ``keys``
        (``<key>_mean``, ``<key>_p99``), the share of rays that did not cross the floor
        (``not_crossed``) and the count of non-finite pixels (``nonfinite_pixels``)."""
        maps, m = self.diagnostics.maps, self.mask
        out = {}
        for k in keys:
            if k in maps:
                v = maps[k][m]
                out[f"{k}_mean"], out[f"{k}_p99"] = float(v.mean()), float(np.percentile(v, 99))
        if "crossed" in maps:
            out["not_crossed"] = float(1.0 - maps["crossed"][m].mean())
        out["nonfinite_pixels"] = int(maps["nonfinite"][m].sum()) if "nonfinite" in maps else 0
        return out


class Scorer:
    """Scores constants of ``shader`` (``study.calibration.shader.Shader``) on ``frames`` (a
    list of ``Frame``) at each frame's full resolution on the backend of ``variant``."""

    def __init__(self, shader, frames, variant: str):
        self.shader, self.frames = shader, list(frames)
        self.backend = drjit_backend(variant)
        self._models = {}

    def model(self, i: int):
        """Frame ``i``'s model at its experiment's resolution (built once)."""
        if i not in self._models:
            f = self.frames[i]
            self._models[i] = self.shader.model(
                f.exp, f.inputs, f.ref.image, self.backend, tuple(f.exp.resolution)
            )
        return self._models[i]

    def __call__(self, i: int, constants) -> Score:
        """``constants`` on frame ``i``."""
        model = self.model(i)
        img, diag = model.render(constants)
        e = errors(self.frames[i].ref.image, img, model.mask)
        return Score(img, model.mask, float(e["rmse"]), e["flip"], diag, e["flip_map"])

    def all(self, constants) -> list[Score]:
        """``constants`` on every frame."""
        return [self(i, constants) for i in range(len(self.frames))]
