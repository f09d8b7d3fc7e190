"""Regularized corrections: truncated-SVD or damped filter factors with noise-aware thresholds."""

from __future__ import annotations

from typing import Any

import numpy as np

from aerobat.core.bounds import OneOf
from aerobat.core.correction import RegularizedKind
from aerobat.core.design import Design
from aerobat.core.plant import Trial
from aerobat.core.rules.base import Schedule
from aerobat.core.rules.broyden import BroydenJacobian
from aerobat.core.rules.scaled import (
    KestenGamma,
    NoiseEstimator,
    Scaled,
    bounded_solve,
    filter_factors,
    json_array,
    json_floats,
)

__all__ = ["BroydenRule", "RegularizedRule"]


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
    ``schedule`` (e.g. :class:`~aerobat.core.rules.base.PaperSchedule`) for all directions.

    If the step would leave the parameter bounds, the bounded least-squares step that
    best achieves the same predicted error change is proposed instead.
    """

    def __init__(self, design: Design, *, kind: str = "tsvd", schedule: Schedule | None = None,
                 gamma_min: float = 0.1, noise: np.ndarray | None = None, noise_prior: float = 0.5,
                 max_noise_step: float = 10.0, rtol: float = 1e-4, jacobian: BroydenJacobian | None = None,
                 name: str | None = None) -> None:
        self.kind: RegularizedKind = OneOf(RegularizedKind).check("kind", kind)
        self.design = design
        self.name = name or kind
        self.sc = Scaled.of(design)
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

    def propose(self, i: int, params: np.ndarray, error: np.ndarray, trial: Trial | None) -> tuple[np.ndarray, float]:
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
        x = bounded_solve(Js, target, Vt, penalties, lo, hi, x)
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
            "sigma": json_floats(self.noise.sigma()),
            "gamma": self.gamma.state(),
            "last_params": json_floats(self.last_params),
            "last_error": json_floats(self.last_error),
            "last_gammas": json_floats(self.last_gammas),
            "last_factors": json_floats(self.last_factors),
        }
        if self.jacobian is not None:
            out["jacobian"] = self.jacobian.state()
        return out

    def load_state(self, state: dict[str, Any]) -> None:
        self.noise.load_state(state.get("noise", {}))
        if "gamma" in state:
            self.gamma.load_state(state["gamma"])
        self.last_params = json_array(state.get("last_params"))
        self.last_error = json_array(state.get("last_error"))
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
        sc = Scaled.of(design)
        jac_options = {k: options.pop(k) for k in self._JACOBIAN_OPTIONS if k in options}
        jac = BroydenJacobian(sc.jac(design.jacobian), rank_rtol=options.get("rtol", 1e-4), **jac_options)
        super().__init__(design, kind=kind, jacobian=jac, name=name, **options)
