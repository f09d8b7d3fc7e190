"""Update rules beyond the paper's (issue 8): regularized, Kalman, Broyden, initial-state compensation.

Every rule implements :class:`aerobat.learning.UpdateRule` (``propose``,
``observe``, ``state``) plus ``load_state`` to resume a session, and is built by
name with :func:`make_rule`:

=================  ===========================================================================
``paper``          the paper's rule (eq 4): Δp = −γ_i·C·e with the design's C and γ_i = max(1/i, 0.1)
``tsvd``           :class:`RegularizedRule`: truncated-SVD correction, noise-aware threshold,
                   per-direction step sizes by Kesten's rule
``damped``         the same with damped (Levenberg–Marquardt) filter factors
``kalman``         :class:`KalmanRule`: Kalman estimate of the unmodeled offset d of eq 3 (Sect. 11),
                   p = p⁰ − C·d̂ projected onto the parameter bounds
``broyden``        :class:`BroydenRule`: ``tsvd`` with a safeguarded good-Broyden update of J
``<name>+isc``     :class:`InitialStateCompensation` around any of the above (Sect. 11)
=================  ===========================================================================

Conventions. All linear algebra happens in *scaled* coordinates (parameters
divided by their scales, errors by theirs; see :mod:`aerobat.correction`), where
"small singular value" means "a direction that barely moves the errors that
matter". σ denotes the per-trial error noise (standard deviation per error
component). Rules never assume that ``propose`` calls are consecutive trials:
``learn`` skips lost (``no_trigger``) and rejected trials, and every rule works
from the parameters and errors it is handed.

Nothing here knows about quadrocopters: initial-state compensation takes the
model's sensitivity matrix and a deviation function as plain inputs (built by
:func:`aerobat.rules_quadrotor.quadrotor_isc` for the flips).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import lsq_linear

from .design import Design
from .learning import CorrectionRule, PaperSchedule, Schedule, UpdateRule
from .maneuvers.base import bounds_arrays
from .plants.base import Trial

__all__ = [
    "RULE_NAMES",
    "BroydenJacobian",
    "BroydenRule",
    "InitialStateCompensation",
    "KalmanRule",
    "KestenGamma",
    "NoiseEstimator",
    "PaperRule",
    "RegularizedRule",
    "filter_factors",
    "make_rule",
]

RULE_NAMES = ("paper", "tsvd", "damped", "kalman", "broyden")

DeviationFn = Callable[[Trial, np.ndarray], np.ndarray]


# ----------------------------------------------------------------- helpers


def _floats(a: np.ndarray | None) -> Any:
    """JSON-ready nested lists (None stays None, non-finite values become None)."""
    if a is None:
        return None
    arr = np.asarray(a, dtype=float)
    if arr.ndim == 0:
        v = float(arr)
        return v if math.isfinite(v) else None
    return [_floats(x) for x in arr]


def _array(v: Any, shape: tuple[int, ...] | None = None) -> np.ndarray | None:
    if v is None:
        return None
    arr = np.array([[np.nan if x is None else x for x in row] for row in v] if (v and isinstance(v[0], list))
                   else [np.nan if x is None else x for x in v], dtype=float)
    if shape is not None and arr.shape != shape:
        raise ValueError(f"rule state: expected shape {shape}, got {arr.shape}")
    return arr


def _required(v: Any, shape: tuple[int, ...] | None = None) -> np.ndarray:
    arr = _array(v, shape)
    if arr is None:
        raise ValueError("rule state: a required array is missing")
    return arr


@dataclass(frozen=True)
class _Scaled:
    """Scales and bounds of a design's maneuver."""

    p_scales: np.ndarray
    e_scales: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def of(cls, design: Design) -> _Scaled:
        m = design.maneuver
        lower, upper = bounds_arrays(m.parameters)
        return cls(np.array([p.scale for p in m.parameters], dtype=float),
                   np.array([e.scale for e in m.errors], dtype=float), lower, upper)

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
        raise ValueError(f"kind = {kind!r}: allowed 'tsvd' or 'damped'")
    if s.size:
        f = np.where(s >= floor * s[0], f, 0.0)
    return f


def _bounded_solve(
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
        return {"changes": _floats(self.changes), "last": _floats(self.last)}

    def load_state(self, state: dict[str, Any]) -> None:
        self.changes = _required(state["changes"])
        self.last = _array(state.get("last"))


# ---------------------------------------------------------------- Broyden


class BroydenJacobian:
    """A Jacobian refined from observed (Δp, Δe) pairs by safeguarded secant (Broyden) updates.

    Scaled coordinates; after measured trials j and i, Δx = scaled p_i − p_j and
    Δε = scaled e_i − e_j. Two modes:

    ``"full"`` — good Broyden: J ← J + θ·(Δε − JΔx)Δxᵀ/‖Δx‖². Learns any model error
        along the directions actually stepped in, but a rank-one change also rotates the
        singular directions, so the weak directions a regularized inverse drops can move.
    ``"diagonal"`` — a structured secant update that keeps the nominal singular
        directions and corrects only the gains: J = U₀ diag(α∘s₀) V₀ᵀ, with α_k moved
        towards the observed response ratio (u_kᵀΔε)/(s₀_k v_kᵀΔx) in every direction
        whose predicted change stands out of the noise. Mis-scaled responses (a wrong
        inertia scales angular accelerations) are what it corrects; the null structure
        and the condition number (≤ ``max_gain``² × that of J⁰) stay under control.

    Safeguards (both modes):

    * skip unless the predicted change stands ``min_snr`` × above the noise expected in Δε
      (√2·σ): small steps tell nothing but noise;
    * θ = ``relaxation``·snr²/(1 + snr²) shrinks updates as the noise share grows;
    * full mode: the change of the predicted response along Δx is clipped to
      ``max_relative`` × ‖JΔx‖, the total departure from J⁰ to ``max_total`` × ‖J⁰‖_F, and
      an update that would push the condition number above ``max_condition_factor`` × that
      of J⁰ or lose rank (at ``rank_rtol``) is rejected; diagonal mode: α ∈ [1/max_gain, max_gain];
    * validation fallback: every pair is first used to *test* the current J against J⁰
      (prediction error ‖Δε − JΔx‖² for both, accumulated since the last change); once
      ``validate_after`` pairs say J⁰ predicts better, J returns to J⁰ and updates pause
      for ``pause_after_reset`` pairs.
    """

    def __init__(self, Js0: np.ndarray, *, mode: str = "full", min_snr: float = 3.0,
                 relaxation: float = 0.7, max_relative: float = 0.5, max_total: float = 1.0,
                 max_condition_factor: float = 10.0, max_gain: float = 3.0, rank_rtol: float = 1e-4,
                 validate_after: int = 3, pause_after_reset: int = 5) -> None:
        if mode not in ("full", "diagonal"):
            raise ValueError(f"mode = {mode!r}: allowed 'full' or 'diagonal'")
        self.mode = mode
        self.Js0 = np.array(Js0, dtype=float)
        self.U0, self.s0, self.Vt0 = np.linalg.svd(self.Js0, full_matrices=False)
        self.alpha = np.ones_like(self.s0)
        self.Js = self.Js0.copy()
        self.min_snr = min_snr
        self.relaxation = relaxation
        self.max_relative = max_relative
        self.max_total = max_total
        self.max_gain = max_gain
        self.rank_rtol = rank_rtol
        s0 = self.s0
        self.cond0 = float(s0[0] / s0[-1]) if s0[-1] > 0 else float("inf")
        self.rank0 = int(np.sum(s0 > rank_rtol * s0[0]))
        self.max_condition = max_condition_factor * self.cond0
        self.validate_after = int(validate_after)
        self.pause_after_reset = int(pause_after_reset)
        self.updates = 0
        self.skipped = 0
        self.resets = 0
        self.version = 0  # bumped whenever Js changes
        self.pause = 0
        self.val_current = 0.0
        self.val_nominal = 0.0
        self.val_count = 0

    def _set(self, Js: np.ndarray) -> bool:
        """Take a new J; False (nothing changes) if it is the same as the current one."""
        if np.linalg.norm(Js - self.Js) <= 1e-12 * np.linalg.norm(self.Js):
            return False
        self.Js = Js
        self.version += 1
        self.val_current = self.val_nominal = 0.0
        self.val_count = 0
        return True

    def _validate(self, dx: np.ndarray, de: np.ndarray) -> bool:
        """Score J against J⁰ on this pair; True if J was reset."""
        if self.updates == 0 or np.array_equal(self.Js, self.Js0):
            return False
        self.val_current += float(np.sum((de - self.Js @ dx) ** 2))
        self.val_nominal += float(np.sum((de - self.Js0 @ dx) ** 2))
        self.val_count += 1
        if self.val_count >= self.validate_after and self.val_current > self.val_nominal:
            self.reset()
            return True
        return False

    def update(self, dx: np.ndarray, de: np.ndarray, noise_s: np.ndarray) -> str:
        """Validate, then try one update; returns what happened."""
        dx = np.asarray(dx, dtype=float)
        de = np.asarray(de, dtype=float)
        if not (np.all(np.isfinite(de)) and np.all(np.isfinite(dx))) or float(dx @ dx) <= 0:
            self.skipped += 1
            return "skipped: no parameter change"
        if self._validate(dx, de):
            return "reset: the nominal Jacobian predicts better"
        if self.pause > 0:
            self.pause -= 1
            self.skipped += 1
            return "skipped: paused after a reset"
        noise_s = np.asarray(noise_s, dtype=float)
        if self.mode == "diagonal":
            return self._update_diagonal(dx, de, noise_s)
        return self._update_full(dx, de, noise_s)

    def _update_diagonal(self, dx: np.ndarray, de: np.ndarray, noise_s: np.ndarray) -> str:
        z = self.Vt0 @ dx  # step along each right singular vector
        observed = self.U0.T @ de
        predicted = self.alpha * self.s0 * z
        sigma_k = np.sqrt((self.U0**2).T @ noise_s**2) * math.sqrt(2.0)
        snr = np.abs(predicted) / np.maximum(sigma_k, 1e-300)
        use = (snr >= self.min_snr) & (self.s0 > self.rank_rtol * self.s0[0])
        if not use.any():
            self.skipped += 1
            return "skipped: no direction above the noise"
        theta = self.relaxation * snr**2 / (1.0 + snr**2)
        ratio = observed / np.where(use, self.s0 * z, 1.0)
        alpha = np.where(use, self.alpha + theta * (ratio - self.alpha), self.alpha)
        self.alpha = np.clip(alpha, 1.0 / self.max_gain, self.max_gain)
        if not self._set((self.U0 * (self.alpha * self.s0)) @ self.Vt0):
            return "unchanged: the observed response matches"
        self.updates += 1
        return "updated"

    def _update_full(self, dx: np.ndarray, de: np.ndarray, noise_s: np.ndarray) -> str:
        nx2 = float(dx @ dx)
        predicted = self.Js @ dx
        noise = math.sqrt(2.0) * float(np.linalg.norm(noise_s))
        snr = float(np.linalg.norm(predicted)) / max(noise, 1e-300)
        if snr < self.min_snr:
            self.skipped += 1
            return f"skipped: signal/noise {snr:.2g} < {self.min_snr:g}"
        theta = self.relaxation * snr**2 / (1.0 + snr**2)
        change = theta * (de - predicted)
        limit = self.max_relative * float(np.linalg.norm(predicted))
        norm_change = float(np.linalg.norm(change))
        if norm_change > limit:
            change *= limit / norm_change
        candidate = self.Js + np.outer(change, dx) / nx2
        total = float(np.linalg.norm(candidate - self.Js0))
        budget = self.max_total * float(np.linalg.norm(self.Js0))
        if total > budget:
            candidate = self.Js0 + (candidate - self.Js0) * (budget / total)
        s = np.linalg.svd(candidate, compute_uv=False)
        cond = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
        rank = int(np.sum(s > self.rank_rtol * s[0]))
        if cond > self.max_condition or rank < self.rank0:
            self.skipped += 1
            return f"rejected: condition {cond:.3g} or rank {rank} out of bounds"
        if not self._set(candidate):
            return "unchanged: the observed response matches"
        self.updates += 1
        return "updated"

    def reset(self) -> None:
        self.alpha = np.ones_like(self.s0)
        self._set(self.Js0.copy())
        self.val_current = self.val_nominal = 0.0
        self.val_count = 0
        self.resets += 1
        self.pause = self.pause_after_reset

    def state(self) -> dict[str, Any]:
        return {"mode": self.mode, "Js": _floats(self.Js), "alpha": _floats(self.alpha), "updates": self.updates,
                "skipped": self.skipped, "resets": self.resets, "version": self.version, "pause": self.pause,
                "validation": [self.val_current, self.val_nominal, self.val_count]}

    def load_state(self, state: dict[str, Any]) -> None:
        self.Js = _required(state["Js"], self.Js0.shape)
        if state.get("alpha") is not None:
            self.alpha = _required(state["alpha"], self.s0.shape)
        self.updates = int(state.get("updates", 0))
        self.skipped = int(state.get("skipped", 0))
        self.resets = int(state.get("resets", 0))
        self.version = int(state.get("version", 0))
        self.pause = int(state.get("pause", 0))
        val = state.get("validation", [0.0, 0.0, 0])
        self.val_current, self.val_nominal, self.val_count = float(val[0]), float(val[1]), int(val[2])


# ------------------------------------------------------------- paper rule


class PaperRule(CorrectionRule):
    """The paper's rule (eq 4) with a no-op ``load_state``, for a uniform interface."""

    def load_state(self, state: dict[str, Any]) -> None:
        return None


# ------------------------------------------------------- regularized rule


class RegularizedRule:
    """Δp = −Σ_k γ_k f_k (u_kᵀε)/s_k v_k in scaled coordinates (item 1 of issue 8).

    ``Js = U diag(s) Vᵀ`` is the scaled Jacobian and ε the scaled error. The filter
    factors f_k (:func:`filter_factors`) drop (``tsvd``) or damp (``damped``) the
    directions whose correction would be mostly noise: λ_k = γ_k·σ_k/``max_noise_step``,
    with σ_k the noise along u_k (estimated online by :class:`NoiseEstimator`, or
    ``noise`` configured in error units) and ``max_noise_step`` the parameter change
    (in parameter scales) that noise alone may cause in one correction. Directions below
    ``rtol``·s₁ are always dropped (the model's own blind spot; ``rtol`` = 1e-3 as the
    design's TSVD).

    Step sizes: per direction by :class:`KestenGamma` (γ = 1 while the error keeps its
    sign, falling as it starts to oscillate, floor ``gamma_min``), or a fixed
    ``schedule`` (e.g. :class:`~aerobat.learning.PaperSchedule`) for all directions.

    If the step would leave the parameter bounds, the bounded least-squares step that
    best achieves the same predicted error change is proposed instead.
    """

    def __init__(self, design: Design, *, kind: str = "tsvd", schedule: Schedule | None = None,
                 gamma_min: float = 0.1, noise: np.ndarray | None = None, noise_prior: float = 0.5,
                 max_noise_step: float = 10.0, rtol: float = 1e-4, jacobian: BroydenJacobian | None = None,
                 name: str | None = None) -> None:
        if kind not in ("tsvd", "damped"):
            raise ValueError(f"kind = {kind!r}: allowed 'tsvd' or 'damped'")
        self.design = design
        self.kind = kind
        self.name = name or kind
        self.sc = _Scaled.of(design)
        self.schedule = schedule
        self.max_noise_step = float(max_noise_step)
        self.rtol = float(rtol)
        self.noise = NoiseEstimator(noise_prior * self.sc.e_scales, noise=noise)
        Js0 = self.sc.jac(design.jacobian)
        self.jacobian = jacobian
        self._Js0 = Js0
        self.gamma = KestenGamma(Js0.shape[0], minimum=gamma_min)
        self.last_params: np.ndarray | None = None
        self.last_error: np.ndarray | None = None
        self.last_gammas: np.ndarray | None = None
        self.last_factors: np.ndarray | None = None

    # -- the Jacobian in use
    @property
    def Js(self) -> np.ndarray:
        return self.jacobian.Js if self.jacobian is not None else self._Js0

    def _learn_from_pair(self, params: np.ndarray, error: np.ndarray) -> None:
        if self.last_params is None:
            return
        dx = (params - self.last_params) / self.sc.p_scales
        de = (error - self.last_error) / self.sc.e_scales
        self.noise.add((de - self.Js @ dx) * self.sc.e_scales, (self.Js @ dx) * self.sc.e_scales)
        if self.jacobian is not None and not self.sc.touches_bound(self.last_params, params):
            self.jacobian.update(dx, de, self.noise.sigma() / self.sc.e_scales)

    def propose(self, i: int, params: np.ndarray, error: np.ndarray, trial: Trial) -> tuple[np.ndarray, float]:
        params = np.asarray(params, dtype=float)
        error = np.asarray(error, dtype=float)
        self._learn_from_pair(params, error)
        self.last_params, self.last_error = params.copy(), error.copy()
        Js = self.Js
        U, s, Vt = np.linalg.svd(Js, full_matrices=False)
        eps = error / self.sc.e_scales
        c = U.T @ eps
        sigma_s = self.noise.sigma() / self.sc.e_scales
        sigma_k = np.sqrt((U**2).T @ sigma_s**2)
        if self.schedule is not None:
            gammas = np.full(s.size, float(self.schedule.gamma(i)))
            self.gamma.gammas(c, sigma_k)  # keep the sign history current anyway
        else:
            gammas = self.gamma.gammas(c, sigma_k)
        lam = gammas * sigma_k / self.max_noise_step
        f = filter_factors(s, lam, self.kind, self.rtol)
        coef = np.where(f > 0, -gammas * f * c / np.where(s > 0, s, 1.0), 0.0)
        x = Vt.T @ coef
        lo = (self.sc.lower - params) / self.sc.p_scales
        hi = (self.sc.upper - params) / self.sc.p_scales
        target = Js @ x  # the predicted error change of the unconstrained step
        penalties = np.where(f > 0, lam, s[0] if s.size else 1.0)
        x = _bounded_solve(Js, target, Vt, penalties, lo, hi, x)
        self.last_gammas, self.last_factors = gammas, f
        used = f > 0.5
        gamma_report = float(np.mean(gammas[used])) if used.any() else 0.0
        return x * self.sc.p_scales, gamma_report

    def observe(self, params: np.ndarray, error: np.ndarray, step: np.ndarray) -> None:
        return None

    def state(self) -> dict[str, Any]:
        out = {
            "rule": self.name,
            "kind": self.kind,
            "noise": self.noise.state(),
            "sigma": _floats(self.noise.sigma()),
            "gamma": self.gamma.state(),
            "last_params": _floats(self.last_params),
            "last_error": _floats(self.last_error),
            "last_gammas": _floats(self.last_gammas),
            "last_factors": _floats(self.last_factors),
        }
        if self.jacobian is not None:
            out["jacobian"] = self.jacobian.state()
        return out

    def load_state(self, state: dict[str, Any]) -> None:
        self.noise.load_state(state.get("noise", {}))
        if "gamma" in state:
            self.gamma.load_state(state["gamma"])
        self.last_params = _array(state.get("last_params"))
        self.last_error = _array(state.get("last_error"))
        if self.jacobian is not None and "jacobian" in state:
            self.jacobian.load_state(state["jacobian"])


# ------------------------------------------------------------------ Broyden


class BroydenRule(RegularizedRule):
    """:class:`RegularizedRule` whose Jacobian is refined by :class:`BroydenJacobian` (item 3).

    Options ``mode`` (``"full"``, the default, or ``"diagonal"``), ``min_snr``, ``relaxation``,
    ``max_relative``, ``max_total``, ``max_condition_factor``, ``max_gain``,
    ``validate_after``, ``pause_after_reset`` go to the Jacobian; the rest to
    :class:`RegularizedRule`.
    """

    _JACOBIAN_OPTIONS = ("mode", "min_snr", "relaxation", "max_relative", "max_total", "max_condition_factor",
                         "max_gain", "validate_after", "pause_after_reset")

    def __init__(self, design: Design, *, kind: str = "tsvd", name: str = "broyden", **options: Any) -> None:
        sc = _Scaled.of(design)
        jac_options = {k: options.pop(k) for k in self._JACOBIAN_OPTIONS if k in options}
        jac = BroydenJacobian(sc.jac(design.jacobian), rank_rtol=options.get("rtol", 1e-4), **jac_options)
        super().__init__(design, kind=kind, jacobian=jac, name=name, **options)


# ------------------------------------------------------------------ Kalman


class KalmanRule:
    """Kalman estimate of the unmodeled offset d of eq 3 (Sect. 11, item 2 of issue 8).

    Model: eᵢ = J(pᵢ − p⁰) + dᵢ + vᵢ, with dᵢ₊₁ = dᵢ + wᵢ (a random walk with tiny
    process noise Q = diag((``drift`` × error scale)²) per trial, so slow drift such as
    battery wear is tracked) and measurement noise R = diag(σ²) (:class:`NoiseEstimator`,
    or ``noise`` configured). Each measured trial gives one observation
    yᵢ = eᵢ − J(pᵢ − p⁰) of d. The prior on d is diffuse, so the first update takes
    d̂ = y₁ (the paper's first full step) and the gain then falls like 1/n until it meets
    the drift floor: the estimate falls to the noise floor fast and then stops chasing
    noise.

    Next parameters: p = p⁰ + x with x minimizing ‖Js x + d̂_s‖² + Σ λ_k²(v_kᵀx)²
    within the bounds (Simon & Chia 2002, projection of the estimate onto the feasible
    set). λ_k = σ_d,k/``max_noise_step`` uses the *estimate's* uncertainty along u_k, so
    weakly observable directions are damped while d̂ is uncertain and released as it
    firms up; directions below ``rtol``·s₁ are never used.

    The filter is re-run over the stored history (the last ``max_history`` trials) at
    every trial, with the current noise estimate and Jacobian: both improve as data
    come in. With ``broyden=True`` the Jacobian is refined by :class:`BroydenJacobian`.

    Initial-state compensation (:class:`InitialStateCompensation` calls
    :meth:`propose_compensated`): each trial's start-state term cᵢ = S·δᵢ is stored with
    it, and every refilter uses yᵢ − (cᵢ − c̄) with c̄ the mean over the *whole* history —
    the start-state scatter leaves the observations while their mean, which learning
    must absorb, stays (see the wrapper's notes on why centring matters).
    """

    def __init__(self, design: Design, *, kind: str = "damped", noise: np.ndarray | None = None,
                 noise_prior: float = 0.5, drift: float = 0.02, prior: float = 100.0,
                 max_noise_step: float = 30.0, rtol: float = 1e-4, broyden: bool = False,
                 broyden_options: dict[str, Any] | None = None, max_history: int = 500,
                 name: str = "kalman") -> None:
        self.design = design
        self.name = name
        self.kind = kind
        self.sc = _Scaled.of(design)
        n = self.sc.e_scales.size
        self.p0 = np.array(design.p_nominal, dtype=float)
        self.noise = NoiseEstimator(noise_prior * self.sc.e_scales, noise=noise)
        self.Q = np.diag((drift * self.sc.e_scales) ** 2)
        self.P0 = np.diag((prior * self.sc.e_scales) ** 2)
        self.max_noise_step = float(max_noise_step)
        self.rtol = float(rtol)
        self._Js0 = self.sc.jac(design.jacobian)
        self.jacobian = BroydenJacobian(self._Js0, **(broyden_options or {})) if broyden else None
        self.d = np.zeros(n)
        self.P = self.P0.copy()
        self.history: list[tuple[list[float], list[float], list[float] | None]] = []
        self.max_history = int(max_history)
        self.gain = 1.0

    @property
    def J(self) -> np.ndarray:
        return self.sc.unjac(self.jacobian.Js) if self.jacobian is not None else self.design.jacobian

    def _filter_step(self, y: np.ndarray, R: np.ndarray) -> None:
        self.P = self.P + self.Q
        S = self.P + R
        K = np.linalg.solve(S.T, self.P.T).T  # P S⁻¹
        self.d = self.d + K @ (y - self.d)
        self.P = (np.eye(self.d.size) - K) @ self.P
        self.P = 0.5 * (self.P + self.P.T)
        self.gain = float(np.mean(np.diag(K)))

    def _refilter(self) -> None:
        """Run the filter over the whole history with the current J and noise estimate."""
        R = np.diag(self.noise.sigma() ** 2)
        self.d = np.zeros_like(self.d)
        self.P = self.P0.copy()
        J = self.J
        comps = [np.asarray(c) for _, _, c in self.history if c is not None]
        mean_c = np.mean(comps, axis=0) if comps else None
        for p, e, c in self.history:
            y = np.asarray(e) - J @ (np.asarray(p) - self.p0)
            if c is not None:
                y = y - (np.asarray(c) - mean_c)
            self._filter_step(y, R)

    def propose(self, i: int, params: np.ndarray, error: np.ndarray, trial: Trial) -> tuple[np.ndarray, float]:
        return self.propose_compensated(i, params, error, trial, None)

    def propose_compensated(self, i: int, params: np.ndarray, error: np.ndarray, trial: Trial,
                            compensation: np.ndarray | None) -> tuple[np.ndarray, float]:
        """As :meth:`propose`, with this trial's start-state term S·δ (None: unknown)."""
        params = np.asarray(params, dtype=float)
        error = np.asarray(error, dtype=float)
        comp = None if compensation is None else np.asarray(compensation, dtype=float)
        if comp is not None and not np.all(np.isfinite(comp)):
            comp = None
        if self.history:
            last_p, last_e, cj = self.history[-1]
            pj, ej = np.asarray(last_p), np.asarray(last_e)
            dx = (params - pj) / self.sc.p_scales
            de_raw = (error - ej) / self.sc.e_scales
            de = de_raw
            if comp is not None and cj is not None:  # the noise that matters is what compensation leaves
                de = de_raw - (comp - np.asarray(cj)) / self.sc.e_scales
            Js = self.jacobian.Js if self.jacobian is not None else self._Js0
            self.noise.add((de - Js @ dx) * self.sc.e_scales, (Js @ dx) * self.sc.e_scales)
            if self.jacobian is not None and not self.sc.touches_bound(pj, params):
                self.jacobian.update(dx, de, self.noise.sigma() / self.sc.e_scales)
        self.history.append(([float(v) for v in params], [float(v) for v in error],
                             None if comp is None else [float(v) for v in comp]))
        del self.history[: -self.max_history]
        # the filter is re-run over the history with the current J and R: both are estimates
        # that improve as data come in, and a gain computed with yesterday's R is not optimal
        self._refilter()
        target = self._next_params()
        return target - params, self.gain

    def _next_params(self) -> np.ndarray:
        Js = self.sc.jac(self.J)
        U, s, Vt = np.linalg.svd(Js, full_matrices=False)
        d_s = self.d / self.sc.e_scales
        c = U.T @ d_s
        Ps = self.P / np.outer(self.sc.e_scales, self.sc.e_scales)
        sigma_d = np.sqrt(np.maximum(np.einsum("ik,ij,jk->k", U, Ps, U), 0.0))
        lam = sigma_d / self.max_noise_step
        f = filter_factors(s, lam, self.kind, self.rtol)
        coef = np.where(f > 0, -f * c / np.where(s > 0, s, 1.0), 0.0)
        x = Vt.T @ coef
        lo = (self.sc.lower - self.p0) / self.sc.p_scales
        hi = (self.sc.upper - self.p0) / self.sc.p_scales
        penalties = np.where(f > 0, np.sqrt(np.maximum(s**2 * (1.0 / np.maximum(f, 1e-12) - 1.0), 0.0)),
                             s[0] if s.size else 1.0)
        x = _bounded_solve(Js, -d_s, Vt, penalties, lo, hi, x)
        return np.clip(self.p0 + x * self.sc.p_scales, self.sc.lower, self.sc.upper)

    def observe(self, params: np.ndarray, error: np.ndarray, step: np.ndarray) -> None:
        return None

    def state(self) -> dict[str, Any]:
        out = {
            "rule": self.name,
            "d": _floats(self.d),
            "P": _floats(self.P),
            "gain": self.gain,
            "sigma": _floats(self.noise.sigma()),
            "noise": self.noise.state(),
            "history": [[list(p), list(e), c] for p, e, c in self.history],
        }
        if self.jacobian is not None:
            out["jacobian"] = self.jacobian.state()
        return out

    def load_state(self, state: dict[str, Any]) -> None:
        self.noise.load_state(state.get("noise", {}))
        self.history = [([float(v) for v in h[0]], [float(v) for v in h[1]],
                         None if len(h) < 3 or h[2] is None else [float(v) for v in h[2]])
                        for h in state.get("history", [])]
        if self.jacobian is not None and "jacobian" in state:
            self.jacobian.load_state(state["jacobian"])
        self._refilter()  # d̂ and P follow from the history


# ------------------------------------------------- initial-state compensation


class InitialStateCompensation:
    """Removes the part of each error explained by the measured start-state deviation (item 4).

    e_c = e − gain·S·(δ − δ̄), where S (n_err × n_dev) is the model's sensitivity of the
    final error to the initial state, δ = ``deviation(trial, params)`` the measured
    deviation of this trial's start from the maneuver's nominal initial state and δ̄
    the mean of all deviations seen so far (``center=True``, the default). The inner
    rule learns from e_c, so trial-to-trial start-state scatter stops driving
    corrections. A non-finite δ leaves the error as it is.

    Rules with a history (:class:`KalmanRule`) take the uncentred term S·δ per trial
    through ``propose_compensated`` and re-centre their whole history on the latest
    mean; for the others the wrapper centres each trial on the running mean.

    Why centred: learning must still zero the *raw* mean error, flown from the start
    states the plant actually delivers. Any constant part of δ — a biased deviation
    estimate, or a hover controller that settles consistently off the nominal start —
    is part of the offset d that learning should absorb; subtracting S·δ itself would
    instead drive the raw error to −S·mean(δ). (Measured on the arena: uncentred, the
    raw last-10 error of the paper's rule went from 0.07 m to 0.12 m.)
    """

    def __init__(self, inner: UpdateRule, sensitivity: np.ndarray, deviation: DeviationFn, *,
                 gain: float | np.ndarray = 1.0, center: bool = True, name: str | None = None) -> None:
        self.inner = inner
        self.S = np.asarray(sensitivity, dtype=float)
        self.deviation = deviation
        self.gain = np.asarray(gain, dtype=float)
        self.center = bool(center)
        self.name = name or f"{getattr(inner, 'name', 'rule')}+isc"
        self.deviation_sum = np.zeros(self.S.shape[1])
        self.deviation_count = 0
        self.last_deviation: np.ndarray | None = None
        self.last_compensation: np.ndarray | None = None
        self._last_error: np.ndarray | None = None

    def compensate(self, params: np.ndarray, error: np.ndarray, trial: Trial) -> np.ndarray:
        """The compensated error e_c for one trial (and the running mean of δ updated)."""
        delta = np.asarray(self.deviation(trial, np.asarray(params, dtype=float)), dtype=float)
        self.last_deviation = delta
        if delta.shape != (self.S.shape[1],) or not np.all(np.isfinite(delta)):
            self.last_compensation = np.zeros(self.S.shape[0])
            return np.asarray(error, dtype=float)
        self.deviation_sum += delta
        self.deviation_count += 1
        if self.center:
            delta = delta - self.deviation_sum / self.deviation_count
        comp = self.S @ (self.gain * delta)
        self.last_compensation = comp
        return np.asarray(error, dtype=float) - comp

    def propose(self, i: int, params: np.ndarray, error: np.ndarray, trial: Trial) -> tuple[np.ndarray, float]:
        native = getattr(self.inner, "propose_compensated", None)
        if native is not None and self.center:
            # the inner rule keeps its history and re-centres all of it on the latest mean
            delta = np.asarray(self.deviation(trial, np.asarray(params, dtype=float)), dtype=float)
            self.last_deviation = delta
            ok = delta.shape == (self.S.shape[1],) and bool(np.all(np.isfinite(delta)))
            comp = self.S @ (self.gain * delta) if ok else None
            if ok:
                self.deviation_sum += delta
                self.deviation_count += 1
            self.last_compensation = comp
            self._last_error = np.asarray(error, dtype=float) if comp is None else np.asarray(error) - comp
            return native(i, params, error, trial, comp)
        compensated = self.compensate(params, error, trial)
        self._last_error = compensated
        return self.inner.propose(i, params, compensated, trial)

    def observe(self, params: np.ndarray, error: np.ndarray, step: np.ndarray) -> None:
        self.inner.observe(params, self._last_error if self._last_error is not None else error, step)

    def state(self) -> dict[str, Any]:
        return {"rule": self.name, "inner": self.inner.state(), "deviation_sum": _floats(self.deviation_sum),
                "deviation_count": self.deviation_count, "last_deviation": _floats(self.last_deviation),
                "last_compensation": _floats(self.last_compensation)}

    def load_state(self, state: dict[str, Any]) -> None:
        loader = getattr(self.inner, "load_state", None)
        if loader is not None:
            loader(state.get("inner", {}))
        if "deviation_sum" in state:
            self.deviation_sum = _required(state["deviation_sum"], (self.S.shape[1],))
            self.deviation_count = int(state.get("deviation_count", 0))
        self.last_deviation = _array(state.get("last_deviation"))
        self.last_compensation = _array(state.get("last_compensation"))


# ------------------------------------------------------------------ factory


def make_rule(name: str, design: Design, *, schedule: Schedule | None = None, **options: Any) -> UpdateRule:
    """Build an update rule by name: ``paper``, ``tsvd``, ``damped``, ``kalman``, ``broyden``, or ``<name>+isc``.

    Parameters
    ----------
    name : the rule; a ``+isc`` suffix wraps it in :class:`InitialStateCompensation`
        (then ``sensitivity`` and ``deviation`` options are required, e.g. from
        :func:`aerobat.rules_quadrotor.quadrotor_isc`; ``isc_gain`` optional).
    design : the nominal design (p⁰, J, C, the maneuver's scales and bounds).
    schedule : a fixed γ schedule. ``paper``: default :class:`PaperSchedule`;
        ``tsvd``/``damped``/``broyden``: default per-direction Kesten step sizes.
        ``kalman`` has no schedule (its gain is the Kalman gain).
    options : passed to the rule's constructor (see each class). ``paper`` accepts
        ``correction`` (a C matrix, default ``design.correction``).
    """
    base, plus, suffix = name.partition("+")
    if plus and suffix != "isc":
        raise ValueError(f"rule {name!r}: the only suffix is '+isc'")
    isc_keys = ("sensitivity", "deviation", "isc_gain", "isc_center")
    isc = {k: options.pop(k) for k in isc_keys if k in options}
    if base == "paper":
        correction = options.pop("correction", design.correction)
        if options:
            raise ValueError(f"rule 'paper': unknown options {sorted(options)}")
        rule: UpdateRule = PaperRule(np.asarray(correction, dtype=float), schedule or PaperSchedule(), name="paper")
    elif base in ("tsvd", "damped"):
        rule = RegularizedRule(design, kind=base, schedule=schedule, **options)
    elif base == "kalman":
        if schedule is not None:
            raise ValueError("rule 'kalman' takes no schedule: its step is the Kalman gain")
        rule = KalmanRule(design, **options)
    elif base == "broyden":
        rule = BroydenRule(design, schedule=schedule, **options)
    else:
        raise ValueError(f"unknown rule {name!r}: allowed {', '.join(RULE_NAMES)} (optionally with '+isc')")
    if plus:
        missing = [k for k in ("sensitivity", "deviation") if k not in isc]
        if missing:
            raise ValueError(f"rule {name!r} needs options {missing} (see aerobat.rules_quadrotor.quadrotor_isc)")
        rule = InitialStateCompensation(rule, isc["sensitivity"], isc["deviation"], gain=isc.get("isc_gain", 1.0),
                                        center=isc.get("isc_center", True), name=name)
    return rule
