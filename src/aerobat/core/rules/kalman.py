"""A Kalman estimate of the unmodeled offset d of eq 3 (Sect. 11)."""

from __future__ import annotations

from typing import Any

import numpy as np

from aerobat.core.design import Design
from aerobat.core.plant import Trial
from aerobat.core.rules.broyden import BroydenJacobian
from aerobat.core.rules.scaled import NoiseEstimator, Scaled, bounded_solve, filter_factors, json_floats

__all__ = ["KalmanRule"]


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
        self.sc = Scaled.of(design)
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

    def propose(self, i: int, params: np.ndarray, error: np.ndarray, trial: Trial | None) -> tuple[np.ndarray, float]:
        return self.propose_compensated(i, params, error, trial, None)

    def propose_compensated(self, i: int, params: np.ndarray, error: np.ndarray, trial: Trial | None,
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
        x = bounded_solve(Js, -d_s, Vt, penalties, lo, hi, x)
        return np.clip(self.p0 + x * self.sc.p_scales, self.sc.lower, self.sc.upper)

    def observe(self, params: np.ndarray, error: np.ndarray, step: np.ndarray) -> None:
        return None

    def state(self) -> dict[str, Any]:
        out = {
            "rule": self.name,
            "d": json_floats(self.d),
            "P": json_floats(self.P),
            "gain": self.gain,
            "sigma": json_floats(self.noise.sigma()),
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
