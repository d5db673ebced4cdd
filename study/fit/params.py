"""A fitted constant: its bounds and the transform the solvers step in (log, logit, clip...)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

TRANSFORMS = ("auto", "linear", "log", "neglog", "logit", "log_logit", "clip")


def _sigmoid(z, xp):
    return 0.5 + 0.5 * xp.tanh(0.5 * z)  # no overflow for large |z|


@dataclass(frozen=True)
class Param:
    """One fitted scalar: physical ``default``, bounds ``[lo, hi]``, ``scale`` (physical units;
    None: ``|default|``, or ``(hi - lo) / 10`` when the default is 0, or 1)."""

    name: str
    default: float
    lo: float = -math.inf
    hi: float = math.inf
    scale: float | None = None
    transform: str = "auto"
    derivative_free: bool = False

    def __post_init__(self):
        lo, hi, d = float(self.lo), float(self.hi), float(self.default)
        if self.transform not in TRANSFORMS:
            raise ValueError(
                f"parameter {self.name}: unknown transform {self.transform!r}; "
                f"choose one of {TRANSFORMS}"
            )
        if not math.isfinite(d) or not lo < hi:
            raise ValueError(
                f"parameter {self.name}: need a finite default and lo < hi, "
                f"got default={d}, lo={lo}, hi={hi}"
            )
        kind = self.kind
        if kind == "clip" and not lo <= d <= hi:
            raise ValueError(f"parameter {self.name}: default {d} must lie inside [{lo}, {hi}]")
        if kind not in ("linear", "clip") and not lo < d < hi:
            raise ValueError(
                f"parameter {self.name}: default {d} must lie strictly inside "
                f"({lo}, {hi}) for the {kind} transform; move it or widen the bounds"
            )
        if kind in ("logit", "log_logit") and not (math.isfinite(lo) and math.isfinite(hi)):
            raise ValueError(f"parameter {self.name}: transform {kind} needs finite bounds")
        if kind == "log_logit" and lo <= 0:
            raise ValueError(f"parameter {self.name}: transform log_logit needs lo > 0, got {lo}")
        if kind == "log" and not math.isfinite(lo):
            raise ValueError(f"parameter {self.name}: transform log needs a finite lo")
        if kind == "neglog" and not math.isfinite(hi):
            raise ValueError(f"parameter {self.name}: transform neglog needs a finite hi")
        if self.scale is not None and not (math.isfinite(self.scale) and self.scale > 0):
            raise ValueError(
                f"parameter {self.name}: scale must be finite and > 0, got {self.scale}"
            )

    @property
    def kind(self) -> str:
        """The transform actually used (``auto`` resolved from the bounds)."""
        if self.transform != "auto":
            return self.transform
        lo_f, hi_f = math.isfinite(self.lo), math.isfinite(self.hi)
        if lo_f and hi_f:
            return "log_logit" if self.lo > 0 and self.hi / self.lo >= 1e3 else "logit"
        return "log" if lo_f else ("neglog" if hi_f else "linear")

    @property
    def typical(self) -> float:
        """The scale actually used (physical units)."""
        if self.scale is not None:
            return float(self.scale)
        if self.default != 0:
            return abs(float(self.default))
        return (self.hi - self.lo) / 10 if math.isfinite(self.hi - self.lo) else 1.0

    # g, g^-1, g' -------------------------------------------------------------------------
    def _g(self, p):
        lo, hi, k = self.lo, self.hi, self.kind
        if k in ("linear", "clip"):
            return p
        if k == "log":
            return np.log(p - lo)
        if k == "neglog":
            return -np.log(hi - p)
        q = (p - lo) / (hi - lo) if k == "logit" else np.log(p / lo) / np.log(hi / lo)
        return np.log(q) - np.log1p(-q)

    def _ginv(self, z, xp=np):
        lo, hi, k = self.lo, self.hi, self.kind
        if k == "linear":
            return z
        if k == "clip":
            return xp.clip(z, lo, hi) if xp is np else xp.clip(z, float(lo), float(hi))
        if k == "log":
            return lo + xp.exp(z)
        if k == "neglog":
            return hi - xp.exp(-z)
        # clipped: at saturation the float rounding of lo*exp(log(hi/lo)) can exceed hi
        if k == "logit":
            p = lo + (hi - lo) * _sigmoid(z, xp)
        else:
            p = lo * xp.exp(math.log(hi / lo) * _sigmoid(z, xp))
        return np.clip(p, lo, hi) if xp is np else xp.clip(p, float(lo), float(hi))

    def _gprime(self, p):
        lo, hi, k = self.lo, self.hi, self.kind
        if k in ("linear", "clip"):
            return np.ones_like(p)
        if k == "log":
            return 1.0 / (p - lo)
        if k == "neglog":
            return 1.0 / (hi - p)
        if k == "logit":
            q = (p - lo) / (hi - lo)
            return 1.0 / ((hi - lo) * q * (1 - q))
        L = math.log(hi / lo)
        q = np.log(p / lo) / L
        return 1.0 / (p * L * q * (1 - q))

    @property
    def _s(self) -> float:
        return float(self._gprime(np.float64(self.default))) * self.typical

    def to_u(self, p) -> np.ndarray:
        """Physical value(s) -> unconstrained ``u`` (float64)."""
        p = np.asarray(p, np.float64)
        if self.kind == "clip" and np.any((p < self.lo) | (p > self.hi)):
            raise ValueError(f"parameter {self.name}: value {p} is outside [{self.lo}, {self.hi}]")
        if self.kind not in ("linear", "clip") and np.any((p <= self.lo) | (p >= self.hi)):
            raise ValueError(
                f"parameter {self.name}: value {p} is not strictly inside ({self.lo}, {self.hi})"
            )
        return (self._g(p) - self._g(np.float64(self.default))) / self._s

    def from_u(self, u, xp=np):
        """Unconstrained ``u`` -> physical value; ``xp`` = ``numpy`` or ``drjit``
        (differentiable)."""
        if xp is np:  # a float32 u (JAX's default) would clip to the bounds rounded to float32
            u = np.asarray(u, np.float64)
        return self._ginv(float(self._g(np.float64(self.default))) + self._s * u, xp)

    def at_bound(self, u) -> str | None:
        """``'lower'`` / ``'upper'`` when ``u`` maps onto (or beyond) a bound of a ``clip``
        parameter, else None (the other transforms never reach their bounds)."""
        if self.kind != "clip":
            return None
        z = float(self.default) + self._s * float(u)
        return "lower" if z <= self.lo else "upper" if z >= self.hi else None

    def dp_du(self, u) -> np.ndarray:
        """Derivative of the physical value with respect to ``u`` (float64); computed from
        ``z = g(default) + s*u`` so that it tends to 0, not NaN, where ``p`` saturates at a
        bound."""
        z = float(self._g(np.float64(self.default))) + self._s * np.asarray(u, np.float64)
        k, lo, hi = self.kind, self.lo, self.hi
        if k == "linear":
            d = np.ones_like(z)
        elif k == "clip":  # one-sided at the bound itself (the inward derivative)
            d = ((z >= lo) & (z <= hi)).astype(np.float64)
        elif k == "log":
            d = np.exp(z)
        elif k == "neglog":
            d = np.exp(-z)
        else:
            sg = _sigmoid(z, np)
            d = (
                (hi - lo) * sg * (1 - sg)
                if k == "logit"
                else self._ginv(z) * math.log(hi / lo) * sg * (1 - sg)
            )
        return self._s * d
