"""A Jacobian refined from observed trial pairs by safeguarded secant (Broyden) updates."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from aerobat.core.rules.scaled import json_floats, required_array

__all__ = ["BroydenJacobian"]


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
        return {"mode": self.mode, "Js": json_floats(self.Js), "alpha": json_floats(self.alpha),
                "updates": self.updates,
                "skipped": self.skipped, "resets": self.resets, "version": self.version, "pause": self.pause,
                "validation": [self.val_current, self.val_nominal, self.val_count]}

    def load_state(self, state: dict[str, Any]) -> None:
        self.Js = required_array(state["Js"], self.Js0.shape)
        if state.get("alpha") is not None:
            self.alpha = required_array(state["alpha"], self.s0.shape)
        self.updates = int(state.get("updates", 0))
        self.skipped = int(state.get("skipped", 0))
        self.resets = int(state.get("resets", 0))
        self.version = int(state.get("version", 0))
        self.pause = int(state.get("pause", 0))
        val = state.get("validation", [0.0, 0.0, 0])
        self.val_current, self.val_nominal, self.val_count = float(val[0]), float(val[1]), int(val[2])
