"""A small Dr.Jit image model for the bridge and fit tests (LLVM backend).

image(x, y) = amp * gain * exp(-rate * x) * T(x + shift, y) + 0.02 * floor(levels) * y
              + dead * max(x - 2, 0) + 0.1

over an (H, W) grid of pixel centres x, y in (0, 1); ``T`` is a smooth 16x16 texture sampled
bilinearly with wrap-around. By construction ``amp`` and ``gain`` enter only as their product
(one flat direction), ``dead`` has no effect on the image (x < 2) and ``levels`` is piecewise
constant (zero derivative almost everywhere). The residual is image(params) - image(truth).
"""

from __future__ import annotations

import math

import drjit as dr
import drjit.llvm.ad as m
import numpy as np

from study.fit.solvers import FitProblem, Param

TRUTH = {"amp": 0.8, "rate": 1.3, "shift": 0.15, "gain": 1.0, "dead": 0.5, "levels": 3.0}


def toy_params() -> list[Param]:
    return [
        Param("amp", 1.0, 1e-3, 10.0),
        Param("rate", 1.0, 0.0, math.inf, scale=1.0),
        Param("shift", 0.1, -1.0, 1.0, scale=0.1),
        Param("gain", 1.0, 0.1, 10.0),
        Param("dead", 0.4, 0.0, 1.0),
        Param("levels", 2.0, 1.0, 10.0, scale=1.0, transform="linear", derivative_free=True),
    ]


class ToyModel:
    """Float64 (default) or Float32 Dr.Jit image model; ``nan_rate``: the model image (not the
    reference) is NaN where ``rate > nan_rate`` (a log of a negative number), to test
    non-finite handling."""

    def __init__(self, height=48, width=64, truth=None, float32=False, nan_rate=None):
        self.F = m.Float if float32 else m.Float64
        Tex = m.Texture2f if float32 else m.Texture2f64
        T = m.TensorXf if float32 else m.TensorXf64
        i, j = np.meshgrid(np.arange(16), np.arange(16), indexing="ij")
        tex = 0.6 + 0.3 * np.sin(2 * np.pi * i / 16) * np.cos(2 * np.pi * j / 16 + 0.4)
        self.tex = Tex(
            T(tex[..., None].astype(np.float32 if float32 else np.float64)),
            filter_mode=dr.FilterMode.Linear,
            wrap_mode=dr.WrapMode.Repeat,
        )
        yy, xx = np.meshgrid(
            (np.arange(height) + 0.5) / height, (np.arange(width) + 0.5) / width, indexing="ij"
        )
        self.x, self.y = self.F(xx.ravel()), self.F(yy.ravel())
        self.nan_rate = None
        self.truth = dict(TRUTH if truth is None else truth)
        self.ref = None
        self.ref = self.image({k: self.F(v) for k, v in self.truth.items()})
        dr.eval(self.ref)
        self.nan_rate = nan_rate  # the reference itself is always finite
        self.m = height * width

    def image(self, v: dict):
        """Dr.Jit image (H*W,) from a dict of Dr.Jit scalars."""
        F = self.F
        pos = (
            m.Array2f64(self.x + v["shift"], self.y)
            if self.F is m.Float64
            else m.Array2f(self.x + v["shift"], self.y)
        )
        t = self.tex.eval(pos)[0]
        img = (
            v["amp"] * v["gain"] * dr.exp(-v["rate"] * self.x) * t
            + 0.02 * dr.floor(v["levels"]) * self.y
            + v["dead"] * dr.maximum(self.x - 2.0, 0.0)
            + 0.1
        )
        if self.nan_rate is not None:
            img = img + 1e-30 * dr.log(F(self.nan_rate) - v["rate"])  # NaN for rate > nan_rate
        return img if self.ref is None else img - self.ref

    def residual(self, values: dict) -> np.ndarray:
        r = self.image({k: dr.opaque(self.F, float(val)) for k, val in values.items()})
        return r.numpy().astype(np.float64)

    def residual_and_jacobian(self, values: dict, names: list[str]):
        """Forward-mode AD, one pass per name (fresh variables each pass). Values are opaque so
        that a new value reuses the compiled kernel instead of baking a literal into a new one."""
        cols, r = [], None
        for n in names:
            v = {k: dr.opaque(self.F, float(val)) for k, val in values.items()}
            dr.enable_grad(v[n])
            img = self.image(v)
            dr.forward(v[n])
            cols.append(dr.grad(img).numpy().astype(np.float64))
            r = dr.detach(img).numpy().astype(np.float64)
        if r is None:
            r = self.residual(values)
        return r, np.stack(cols, axis=1) if cols else np.zeros((len(r), 0))

    def loss_drjit(self, values: dict):
        v = {
            k: (val if isinstance(val, dr.ArrayBase) else self.F(val)) for k, val in values.items()
        }
        v = {k: (self.F(val) if type(val) is not self.F else val) for k, val in v.items()}
        r = self.image(v)
        return 0.5 * dr.sum(r * r)

    def problem(self, with_adam_reverse=True) -> FitProblem:
        return FitProblem(
            toy_params(),
            self.residual,
            self.residual_and_jacobian,
            loss_drjit=self.loss_drjit if with_adam_reverse else None,
            drjit_float=self.F,
            name="toy",
        )
