"""Shared machinery of the update rules: scaled coordinates, filter factors, noise and step sizes.

All linear algebra happens in *scaled* coordinates (parameters divided by their
scales, errors by theirs; see :mod:`aerobat.core.correction`), where "small
singular value" means "a direction that barely moves the errors that matter".
Rule states are JSON-ready (:func:`json_floats`) and load back exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from aerobat.core.bounds import OneOf
from aerobat.core.correction import RegularizedKind
from aerobat.core.design import Design
from aerobat.core.maneuver import bounds_arrays, error_scales, parameter_scales
from aerobat.errors import ConfigError

__all__ = [
    "KestenGamma",
    "NoiseEstimator",
    "Scaled",
    "bounded_solve",
    "filter_factors",
    "json_array",
    "json_floats",
    "required_array",
]


def json_floats(a: np.ndarray | None) -> Any:
    """JSON-ready nested lists (None stays None, non-finite values become None)."""
    if a is None:
        return None
    arr = np.asarray(a, dtype=float)
    if arr.ndim == 0:
        v = float(arr)
        return v if math.isfinite(v) else None
    return [json_floats(x) for x in arr]


def json_array(v: Any, shape: tuple[int, ...] | None = None) -> np.ndarray | None:
    if v is None:
        return None
    arr = np.array([[np.nan if x is None else x for x in row] for row in v] if (v and isinstance(v[0], list))
                   else [np.nan if x is None else x for x in v], dtype=float)
    if shape is not None and arr.shape != shape:
        raise ValueError(f"rule state: expected shape {shape}, got {arr.shape}")
    return arr


def required_array(v: Any, shape: tuple[int, ...] | None = None) -> np.ndarray:
    arr = json_array(v, shape)
    if arr is None:
        raise ValueError("rule state: a required array is missing")
    return arr


@dataclass(frozen=True)
class Scaled:
    """Scales and bounds of a design's maneuver."""

    p_scales: np.ndarray
    e_scales: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def of(cls, design: Design) -> Scaled:
        m = design.maneuver
        lower, upper = bounds_arrays(m.parameters)
        return cls(parameter_scales(m.parameters), error_scales(m.errors), lower, upper)

    def on_bound(self, params: np.ndarray) -> np.ndarray:
        """Which parameters sit on (within 1e-6 scales of) a bound."""
        tol = 1e-6 * self.p_scales
        return (params <= self.lower + tol) | (params >= self.upper - tol)

    def touches_bound(self, a: np.ndarray, b: np.ndarray) -> bool:
        """True if any parameter sits on a bound at either end of the pair (a, b).

        At a bound the plant sits at an envelope edge where its response may clip; a secant
        through such a pair can learn the clipping rather than the Jacobian. (Measured: with
        only pairs that *moved* a bound parameter excluded, Kalman + Broyden crashed on the
        arena with a half-inertia design model.)
        """
        return bool(np.any(self.on_bound(np.asarray(a)) | self.on_bound(np.asarray(b))))

    def jac(self, J: np.ndarray) -> np.ndarray:
        return (J / self.e_scales[:, None]) * self.p_scales[None, :]

    def unjac(self, Js: np.ndarray) -> np.ndarray:
        return (Js * self.e_scales[:, None]) / self.p_scales[None, :]


def filter_factors(s: np.ndarray, lam: np.ndarray, kind: str, floor: float) -> np.ndarray:
    """Per-direction filter factors f_k of a regularized inverse Σ f_k/s_k v_k u_kᵀ.

    ``tsvd``: 1 where s_k ≥ λ_k, else 0; ``damped``: s_k²/(s_k² + λ_k²). Directions with
    s_k < ``floor``·s₁ are always dropped (the model cannot be trusted there at all).
    """
    s = np.asarray(s, dtype=float)
    lam = np.broadcast_to(np.asarray(lam, dtype=float), s.shape)
    if kind == "tsvd":
        f = (s >= lam).astype(float)
    elif kind == "damped":
        f = s**2 / np.maximum(s**2 + lam**2, 1e-300)
    else:
        raise ConfigError(f"kind = {kind!r}: allowed {OneOf(RegularizedKind).describe()}")
    if s.size:
        f = np.where(s >= floor * s[0], f, 0.0)
    return f


def bounded_solve(
    Js: np.ndarray,
    target: np.ndarray,
    Vt: np.ndarray,
    penalties: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    unconstrained: np.ndarray,
) -> np.ndarray:
    """Scaled x minimizing ‖Js x − target‖² + Σ penalties_k² (v_kᵀx)² within lo ≤ x ≤ hi.

    The Simon & Chia (2002) idea for box bounds: keep the predicted error change as
    close as possible to the unconstrained one while staying feasible. Returns
    ``unconstrained`` when it is feasible already.
    """
    if np.all(unconstrained >= lo - 1e-12) and np.all(unconstrained <= hi + 1e-12):
        return unconstrained
    A = np.vstack([Js, penalties[:, None] * Vt])
    b = np.concatenate([target, np.zeros(Vt.shape[0])])
    lo2 = np.minimum(lo, 0.0)  # the current point (x = 0) is always feasible
    hi2 = np.maximum(hi, 0.0)
    from scipy.optimize import lsq_linear  # here, not at import: loading scipy.optimize takes ~0.5 s

    res = lsq_linear(A, b, bounds=(lo2, hi2), method="bvls")
    return np.clip(res.x, lo2, hi2)


# -------------------------------------------------------------- noise level


class NoiseEstimator:
    """Per-component error noise σ from trial-to-trial residuals of the linear model.

    For two measured trials j < i, r = (e_i − e_j) − J(p_i − p_j) has covariance 2·Σ_v
    if the offset d of eq 3 is constant and J right; σ² per component is estimated
    robustly (median of r²/2 over the last ``window`` pairs, divided by 0.455, the
    median of a χ²₁ variable) and blended with a prior worth ``prior_weight`` pairs.
    A configured ``noise`` (error units) overrides the estimate.
    """

    def __init__(self, prior: np.ndarray, *, prior_weight: float = 2.0, window: int = 20,
                 noise: np.ndarray | None = None) -> None:
        self.prior = np.asarray(prior, dtype=float)
        self.prior_weight = float(prior_weight)
        self.window = int(window)
        self.fixed = None if noise is None else np.broadcast_to(np.asarray(noise, dtype=float),
                                                                self.prior.shape).copy()
        self.samples: list[list[float]] = []

    def add(self, residual: np.ndarray, predicted: np.ndarray | None = None, *, max_snr: float = 2.0) -> bool:
        """Add one pair's residual r (error units); returns whether it was used.

        With ``predicted`` (the model's predicted error change JΔp, error units) the pair is
        skipped when the step was large against the noise (‖JΔp/σ‖ > ``max_snr``·√2·‖1‖):
        then the residual measures the model's error more than the noise (and is what a
        Jacobian update learns from instead).
        """
        r = np.asarray(residual, dtype=float)
        if not np.all(np.isfinite(r)):
            return False
        if predicted is not None:
            sig = self.sigma()
            snr = float(np.linalg.norm(np.asarray(predicted) / sig)) / math.sqrt(2.0 * sig.size)
            if snr > max_snr:
                return False
        self.samples.append([float(v) for v in 0.5 * r**2])
        del self.samples[: -self.window]
        return True

    @property
    def count(self) -> int:
        return len(self.samples)

    def sigma(self) -> np.ndarray:
        if self.fixed is not None:
            return self.fixed
        n = len(self.samples)
        if n == 0:
            return self.prior
        med = np.median(np.array(self.samples), axis=0) / 0.455
        var = (self.prior_weight * self.prior**2 + n * med) / (self.prior_weight + n)
        return np.sqrt(var)

    def state(self) -> dict[str, Any]:
        return {"samples": self.samples}

    def load_state(self, state: dict[str, Any]) -> None:
        self.samples = [list(map(float, s)) for s in state.get("samples", [])]


# -------------------------------------------------------------- step sizes


class KestenGamma:
    """Per-direction step sizes by Kesten's rule (Kesten 1958, accelerated stochastic approximation).

    γ_k = max(γ_min, 1/(1 + m_k)) with m_k the number of trials at which the error's
    component along direction k changed sign, grew clearly (× ``growth`` and above 2σ),
    or lay within ``noise_band``·σ_k of zero (nothing systematic left to correct).
    Far from the target the components keep their sign well above the noise and γ
    stays 1 (full Newton-like steps); once noise dominates, nearly every trial counts
    and γ falls like 1/n, averaging the noise out as the paper's schedule does; the
    floor keeps tracking slow drift (the paper's γ_min = 0.1).
    """

    def __init__(self, size: int, *, minimum: float = 0.1, growth: float = 2.0, noise_band: float = 1.0) -> None:
        self.minimum = float(minimum)
        self.noise_band = float(noise_band)
        self.growth = float(growth)
        self.changes = np.zeros(size)
        self.last: np.ndarray | None = None

    def gammas(self, components: np.ndarray, noise: np.ndarray) -> np.ndarray:
        c = np.asarray(components, dtype=float)
        if self.last is not None:
            flipped = np.sign(c) != np.sign(self.last)
            grew = (np.abs(c) > self.growth * np.abs(self.last)) & (np.abs(c) > 2.0 * noise)
            settled = np.abs(c) < self.noise_band * noise
            self.changes += (flipped | grew | settled).astype(float)
        self.last = c.copy()
        return np.maximum(self.minimum, 1.0 / (1.0 + self.changes))

    def state(self) -> dict[str, Any]:
        return {"changes": json_floats(self.changes), "last": json_floats(self.last)}

    def load_state(self, state: dict[str, Any]) -> None:
        self.changes = required_array(state["changes"])
        self.last = json_array(state.get("last"))


