"""Fit the nominal model's identifiable parameters to identification trials (SciPy least squares).

The residuals are what motion capture measures and nothing else: each trial's measured
positions and attitudes against the compiled model's
(:func:`aerobat.quadrotor.simulate.simulate`, continuous time) at the measurement times.
Velocities and rates are never used. Besides the vehicle's parameters (:mod:`.parameters`)
every trial has its own start — position, velocity and attitude at the trigger (9 nuisance
parameters) — because the vehicle never starts from an exact hover. The Jacobian is
sparse (a trial's start touches only that trial's residuals), so finite differences cost
about (parameters + 9) simulations of each trial, whatever the number of trials.

Residuals are scaled by ``position_scale_m`` and ``angle_scale_rad``; an uncertainty is the
square root of the diagonal of s²·(JᵀJ)⁻¹ at the optimum, with s² the residual variance.
It assumes independent errors; a model that does not fit leaves correlated residuals, so
treat the uncertainties as lower bounds and look at the spread over repeated
identifications (``docs/results.md`` has one over five seeds).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix

from aerobat.core.bounds import Integer, Interval, bounded, validate
from aerobat.core.plant import Trial
from aerobat.errors import ConfigError, IdentificationFailed
from aerobat.quadrotor.dynamics import N_STATE, RATE_INT, hover_state, quaternion_from_rotation_vector
from aerobat.quadrotor.identification.parameters import (
    PARAMETERS,
    config_from_parameters,
    envelope_margins,
    parameter_index,
    parameters_from_config,
)
from aerobat.quadrotor.identification.sequence import IdentificationTrial, TrialKind
from aerobat.quadrotor.simulate import simulate
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["FitOptions", "TrialFit", "VehicleFit", "fit_vehicle", "usable_trials"]

_START = 9  # nuisance parameters per trial: position, velocity, attitude at the trigger
_MIN_SAMPLES = 10


@dataclass(frozen=True, kw_only=True)
class FitOptions:
    """How the fit weighs, integrates, stops and judges.

    Attributes
    ----------
    position_scale_m, angle_scale_rad : residual scales (1 mm and 2 mrad is a lab's motion capture;
        larger values trust the model's structure less than the sensor).
    max_step_s : RK4 step of the model during the fit [s].
    max_evaluations : residual evaluations the least-squares solver may spend.
    max_position_rms_m, max_angle_rms_rad : a fit with a larger RMS residual is refused.
    fixed : parameters held at the prior's value (names from :data:`~.parameters.PARAMETERS`).
    """

    position_scale_m: float = bounded(0.003, Interval(1e-5, 1.0, unit="m"))
    angle_scale_rad: float = bounded(0.005, Interval(1e-5, 1.0, unit="rad"))
    max_step_s: float = bounded(1e-3, Interval(1e-5, 5e-3, unit="s"))
    max_evaluations: int = bounded(80, Integer(1, 10000))
    max_position_rms_m: float = bounded(0.02, Interval(1e-5, 10.0, unit="m"))
    max_angle_rms_rad: float = bounded(math.radians(3.0), Interval(1e-5, 3.0, unit="rad"))
    fixed: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        validate(self)
        for name in self.fixed:
            parameter_index(name)


@dataclass(frozen=True)
class TrialFit:
    """One trial, measured and fitted, at the measurement times.

    Attributes
    ----------
    trial : the identification trial.
    times_s : (M,) measurement times from the trigger [s].
    measured_position_m, fitted_position_m : (M, 3) positions relative to the start [m].
    measured_angles_rad, fitted_angles_rad : (M, 3) accumulated rotation about body x, y, z since the
        trigger [rad].
    position_rms_m, angle_rms_rad : RMS residuals of this trial.
    start : (9,) fitted start: position [m], velocity [m/s], attitude (rotation vector) [rad].
    """

    trial: IdentificationTrial
    times_s: np.ndarray
    measured_position_m: np.ndarray
    fitted_position_m: np.ndarray
    measured_angles_rad: np.ndarray
    fitted_angles_rad: np.ndarray
    position_rms_m: float
    angle_rms_rad: float
    start: np.ndarray


@dataclass(frozen=True)
class VehicleFit:
    """An identification's result: the parameters, their uncertainties, the residuals, the vehicle.

    Attributes
    ----------
    prior : the vehicle the trials were built on and the fit started from.
    config : the identified vehicle (prior's controller, fitted constants and effects).
    theta, sigma : (n,) fitted parameters and their 1-σ uncertainties (0 for fixed ones).
    free : (n,) which parameters were fitted.
    trials : the trials used, measured and fitted.
    notes : trials left out and why, assumptions that apply.
    position_rms_m, angle_rms_rad : RMS residuals over every sample used.
    residual_scale : s, the RMS of the scaled residuals (1 means "as noisy as the scales say").
    problems : why the fit is not acceptable (empty: it is).
    evaluations, wall_s : solver effort.
    """

    prior: VehicleConfig
    config: VehicleConfig
    theta: np.ndarray
    sigma: np.ndarray
    free: np.ndarray
    trials: tuple[TrialFit, ...]
    notes: tuple[str, ...]
    position_rms_m: float
    angle_rms_rad: float
    residual_scale: float
    problems: tuple[str, ...]
    evaluations: int
    wall_s: float
    covariance: np.ndarray = field(repr=False)

    @property
    def acceptable(self) -> bool:
        return not self.problems

    def value(self, name: str) -> float:
        return float(self.theta[parameter_index(name)])

    def uncertainty(self, name: str) -> float:
        return float(self.sigma[parameter_index(name)])

    def parameter_rows(self) -> list[dict[str, Any]]:
        """One JSON-ready row per parameter: name, symbol, unit, value, sigma, prior, fitted."""
        prior = parameters_from_config(self.prior)
        return [{"name": p.name, "symbol": p.symbol, "unit": p.unit, "description": p.description,
                 "value": float(self.theta[k]), "sigma": float(self.sigma[k]), "prior": float(prior[k]),
                 "fitted": bool(self.free[k])} for k, p in enumerate(PARAMETERS)]

    def derived(self) -> dict[str, tuple[float, float]]:
        """Physical quantities of the identified vehicle with uncertainties (delta method): name → (value, σ)."""
        funcs = _derived_functions(self.prior)
        out = {}
        for name, func in funcs.items():
            value = func(self.theta)
            grad = np.zeros(len(self.theta))
            for k in np.flatnonzero(self.free):
                h = 1e-6 * max(abs(self.theta[k]), PARAMETERS[k].scale)
                up, dn = self.theta.copy(), self.theta.copy()
                up[k] += h
                dn[k] -= h
                grad[k] = (func(up) - func(dn)) / (2 * h)
            out[name] = (float(value), float(math.sqrt(max(grad @ self.covariance @ grad, 0.0))))
        return out


def _derived_functions(prior: VehicleConfig) -> dict[str, Callable[[np.ndarray], float]]:
    c = prior.controller
    g = prior.vehicle.gravity_m_s2
    gains = (c.rate_gain_p_per_s, c.rate_gain_q_per_s, c.rate_gain_r_per_s)
    inertia_c = (c.inertia_xx_kg_m2, c.inertia_yy_kg_m2, c.inertia_zz_kg_m2)
    return {
        "mass_kg": lambda t: c.mass_kg / t[0],
        "hover_command_m_s2": lambda t: g / t[0],
        "rotor_thrust_max_n": lambda t: t[1] * c.mass_kg / t[0] / 4.0,
        "rotor_thrust_min_n": lambda t: max(t[2], 0.0) * c.mass_kg / t[0] / 4.0,
        "thrust_to_weight": lambda t: t[1] / g,
        "inertia_xx_kg_m2": lambda t: inertia_c[0] * gains[0] / t[5],
        "inertia_yy_kg_m2": lambda t: inertia_c[1] * gains[1] / t[6],
        "inertia_ratio_yy_xx": lambda t: (inertia_c[1] * gains[1] / t[6]) / (inertia_c[0] * gains[0] / t[5]),
        "yaw_gain_kappa_over_izz": lambda t: t[7] * c.drag_constant_m / (gains[2] * inertia_c[2]),
        "steady_rate_ratio_p": lambda t: 1.0 / (1.0 + t[11]),
        "steady_rate_ratio_q": lambda t: 1.0 / (1.0 + t[12]),
        "steady_rate_ratio_r": lambda t: 1.0 / (1.0 + t[13]),
    }


# ------------------------------------------------------------------ data


def usable_trials(flights: Sequence[tuple[IdentificationTrial, Trial]]) -> tuple[
        list[tuple[IdentificationTrial, Trial]], list[str]]:
    """The flights a fit can use (measured, enough finite samples), and a note for each one left out."""
    used, notes = [], []
    for trial, flown in flights:
        if not flown.ok:
            notes.append(f"{trial.name}: not used ({flown.status.value}: {flown.message})")
            continue
        states = np.asarray(flown.states)
        if states.ndim != 2 or states.shape[1] != N_STATE or len(flown.times_s) < _MIN_SAMPLES:
            notes.append(f"{trial.name}: not used (only {len(flown.times_s)} motion-capture samples)")
            continue
        if not (np.all(np.isfinite(states[:, 0:3])) and np.all(np.isfinite(states[:, 6:10]))):
            notes.append(f"{trial.name}: not used (non-finite motion-capture samples)")
            continue
        used.append((trial, flown))
    return used, notes


def _check_coverage(used: Sequence[tuple[IdentificationTrial, Trial]], flown_notes: Sequence[str]) -> None:
    kinds = {trial.kind for trial, _ in used}
    missing = [kind for kind in TrialKind if kind.required and kind not in kinds]
    if missing:
        what = "; ".join(f"no usable {kind.value.replace('_', ' ')} trial ({kind.identifies})" for kind in missing)
        detail = f" — {'; '.join(flown_notes)}" if flown_notes else ""
        raise IdentificationFailed(f"too few usable trials to fit ({len(used)} usable): {what}{detail}")


# ------------------------------------------------------------------ residuals


def _quaternion_rows_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a.T
    w2, x2, y2, z2 = b.T
    return np.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], axis=1)


def _attitude_error(q_model: np.ndarray, q_measured: np.ndarray) -> np.ndarray:
    """Rotation vectors (body frame) of q_modelᵀ ⊗ q_measured, (M, 3) [rad], shortest way round."""
    d = _quaternion_rows_multiply(q_model * np.array([1.0, -1.0, -1.0, -1.0]), q_measured)
    sign = np.where(d[:, 0] < 0.0, -1.0, 1.0)
    s = np.linalg.norm(d[:, 1:], axis=1)
    angle = 2.0 * np.arctan2(s, np.abs(d[:, 0]))
    scale = np.where(s > 1e-12, angle / np.maximum(s, 1e-12), 2.0) * sign
    return d[:, 1:] * scale[:, None]


def _start_state(config: VehicleConfig, start: np.ndarray) -> np.ndarray:
    x0 = hover_state(config.vehicle)
    x0[0:3] = start[0:3]
    x0[3:6] = start[3:6]
    x0[6:10] = quaternion_from_rotation_vector(np.asarray(start[6:9], dtype=float))
    return x0


def _model_at(config: VehicleConfig, trial: IdentificationTrial, start: np.ndarray, times: np.ndarray,
              max_step_s: float) -> np.ndarray:
    """Model states at ``times`` (linear interpolation between integration steps; quaternion renormalized)."""
    traj = simulate(trial.program, config, initial_state=_start_state(config, start), max_step_s=max_step_s)
    t = traj.times_s
    k = np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 2)
    w = np.clip((times - t[k]) / (t[k + 1] - t[k]), 0.0, 1.0)[:, None]
    states = traj.states[k] * (1.0 - w) + traj.states[k + 1] * w
    states[:, 6:10] /= np.linalg.norm(states[:, 6:10], axis=1, keepdims=True)
    return states


class _Problem:
    """The least-squares problem: vector x = (free parameters, 9 start values per trial)."""

    def __init__(self, prior: VehicleConfig, used: Sequence[tuple[IdentificationTrial, Trial]],
                 options: FitOptions) -> None:
        self.prior = prior
        self.used = list(used)
        self.options = options
        self.margins = envelope_margins(prior.vehicle)
        self.theta0 = parameters_from_config(prior)
        self.free = np.array([p.name not in options.fixed for p in PARAMETERS])
        self.n_free = int(self.free.sum())
        self.times = [np.asarray(flown.times_s, dtype=float) for _, flown in self.used]
        self.measured = [np.asarray(flown.states, dtype=float) for _, flown in self.used]
        self.sizes = [6 * len(t) for t in self.times]
        self.failed = False

    def theta(self, x: np.ndarray) -> np.ndarray:
        theta = self.theta0.copy()
        theta[self.free] = x[: self.n_free]
        return theta

    def start(self, x: np.ndarray, j: int) -> np.ndarray:
        return x[self.n_free + _START * j: self.n_free + _START * (j + 1)]

    def x0(self) -> np.ndarray:
        return np.concatenate([self.theta0[self.free], np.zeros(_START * len(self.used))])

    def scales(self) -> np.ndarray:
        per = np.array([p.scale * (max(abs(t), 1e-6) if p.relative else 1.0)
                        for p, t in zip(PARAMETERS, self.theta0, strict=True)])
        start = np.tile([0.01] * 3 + [0.02] * 3 + [0.005] * 3, len(self.used))
        return np.concatenate([per[self.free], start])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lower = np.array([p.lower for p in PARAMETERS])
        upper = np.array([p.upper for p in PARAMETERS])
        g = self.prior.vehicle.gravity_m_s2
        lower[parameter_index("collective_max")] = 1.01 * g  # a vehicle that cannot hover is no answer
        upper[parameter_index("collective_min")] = 0.98 * g
        lo = np.concatenate([lower[self.free], np.full(_START * len(self.used), -np.inf)])
        hi = np.concatenate([upper[self.free], np.full(_START * len(self.used), np.inf)])
        x0 = self.x0()
        bad = (x0 < lo) | (x0 > hi)
        if np.any(bad):
            names = [PARAMETERS[k].name for k in np.flatnonzero(self.free)[bad[: self.n_free]]]
            raise ConfigError(f"the prior vehicle {self.prior.name} lies outside the fit's range for "
                              f"{', '.join(names)}")
        return lo, hi

    def config(self, theta: np.ndarray) -> VehicleConfig:
        return config_from_parameters(theta, self.prior, margins=self.margins)

    def sparsity(self) -> Any:
        pattern = lil_matrix((sum(self.sizes), self.n_free + _START * len(self.used)), dtype=np.int8)
        row = 0
        for j, size in enumerate(self.sizes):
            pattern[row: row + size, : self.n_free] = 1
            pattern[row: row + size, self.n_free + _START * j: self.n_free + _START * (j + 1)] = 1
            row += size
        return pattern

    def trial_residual(self, config: VehicleConfig, j: int, start: np.ndarray) -> np.ndarray:
        trial, _ = self.used[j]
        model = _model_at(config, trial, start, self.times[j], self.options.max_step_s)
        meas = self.measured[j]
        dp = (meas[:, 0:3] - model[:, 0:3]) / self.options.position_scale_m
        da = _attitude_error(model[:, 6:10], meas[:, 6:10]) / self.options.angle_scale_rad
        return np.concatenate([dp.ravel(), da.ravel()])

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """Forward differences, dense: one evaluation per free parameter, one per start component for all trials."""
        r0 = self.residuals(x)
        n = len(x)
        jac = np.zeros((len(r0), n))
        scales = self.scales()
        lower, upper = self.bounds()
        for k in range(self.n_free):
            h = 1e-6 * max(scales[k], abs(x[k]) * 1e-3)
            if x[k] + h > upper[k]:
                h = -h
            xp = x.copy()
            xp[k] += h
            jac[:, k] = (self.residuals(xp) - r0) / h
        rows = np.repeat(np.arange(len(self.used)), self.sizes)
        for c in range(_START):
            cols = self.n_free + _START * np.arange(len(self.used)) + c
            h = 1e-6 * scales[cols[0]] * 100.0
            xp = x.copy()
            xp[cols] += h
            diff = (self.residuals(xp) - r0) / h
            jac[np.arange(len(r0)), cols[rows]] = diff
        return jac

    def residuals(self, x: np.ndarray) -> np.ndarray:
        try:
            config = self.config(self.theta(x))
        except ConfigError:  # a trial point outside flyable vehicles: a large, finite residual
            return np.full(sum(self.sizes), 1e3)
        out = [self.trial_residual(config, j, self.start(x, j)) for j in range(len(self.used))]
        r = np.concatenate(out)
        if not np.all(np.isfinite(r)):
            return np.full(sum(self.sizes), 1e3)
        return r


def _single_threaded_blas() -> Any:
    """One BLAS thread while fitting: the solver's SVDs of a tall, narrow Jacobian are several times
    faster that way on small machines (numba's threads are busy anyway)."""
    from threadpoolctl import threadpool_limits  # a declared dependency

    return threadpool_limits(limits=1, user_api="blas")


def fit_vehicle(prior: VehicleConfig, flights: Sequence[tuple[IdentificationTrial, Trial]], *,
                options: FitOptions | None = None, name: str = "identified") -> VehicleFit:
    """Fit the identifiable parameters to the flown trials, starting from ``prior``.

    Parameters
    ----------
    prior : the vehicle the trials were built on (its controller is the vehicle's onboard loop).
    flights : (trial, what the plant measured) pairs; failed trials are left out with a note.
    options : weights, step size, effort and acceptance limits.
    name : the identified vehicle's name.

    Returns
    -------
    VehicleFit
        Check ``acceptable`` (and ``problems``) before using ``config``.

    Raises
    ------
    IdentificationFailed
        Too few usable trials: the message names the kinds missing and what they identify.
    """
    options = options or FitOptions()
    started = time.perf_counter()
    used, notes = usable_trials(flights)
    _check_coverage(used, notes)
    kinds = {trial.kind for trial, _ in used}
    if TrialKind.ROLL_FLIP not in kinds or TrialKind.PITCH_FLIP not in kinds:
        notes.append("no slow flip about every axis: the steady roll/pitch rate shortfall rests on the doublets "
                     "alone and is less certain")
    problem = _Problem(prior, used, options)
    lower, upper = problem.bounds()
    x0 = problem.x0()
    with _single_threaded_blas():
        result = least_squares(problem.residuals, x0, jac=problem.jacobian, x_scale=problem.scales(),
                               bounds=(lower, upper), method="trf", tr_solver="exact",
                               max_nfev=options.max_evaluations, ftol=1e-6, xtol=1e-6, gtol=1e-8)
    theta = problem.theta(result.x)
    jac = result.jac.toarray() if hasattr(result.jac, "toarray") else np.asarray(result.jac)
    dof = max(len(result.fun) - len(result.x), 1)
    s2 = 2.0 * float(result.cost) / dof
    cov_full = np.linalg.pinv(jac.T @ jac) * s2
    covariance = np.zeros((len(PARAMETERS), len(PARAMETERS)))
    idx = np.flatnonzero(problem.free)
    covariance[np.ix_(idx, idx)] = cov_full[: problem.n_free, : problem.n_free]
    sigma = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    problems = []
    try:
        config = problem.config(theta)
        config = VehicleConfig(vehicle=config.vehicle, controller=config.controller, name=name,
                               effects=config.effects)
    except ConfigError as exc:
        problems.append(f"the fitted parameters make no flyable vehicle: {exc}")
        config = prior
    trial_fits = tuple(_trial_fit(problem, config, j, problem.start(result.x, j)) for j in range(len(used)))
    pos = np.concatenate([t.measured_position_m - t.fitted_position_m for t in trial_fits])
    position_rms = float(np.sqrt(np.mean(pos**2)))
    angle_rms = float(np.sqrt(np.mean([t.angle_rms_rad**2 for t in trial_fits])))
    if result.status <= 0:
        problems.append(f"the least-squares solver stopped without converging: {result.message}")
    if position_rms > options.max_position_rms_m:
        problems.append(f"position residual {position_rms * 1e3:.1f} mm RMS is larger than the limit "
                        f"{options.max_position_rms_m * 1e3:.1f} mm: the model does not explain the flights")
    if angle_rms > options.max_angle_rms_rad:
        problems.append(f"attitude residual {math.degrees(angle_rms):.2f}° RMS is larger than the limit "
                        f"{math.degrees(options.max_angle_rms_rad):.2f}°: the model does not explain the flights")
    notes.append("I_zz and κ act only through their ratio (the yaw gain): I_zz is scaled like the mean of I_xx "
                 "and I_yy, κ takes the rest; β̲, β̄ keep the prior's margins in the identified thrust span")
    return VehicleFit(prior=prior, config=config, theta=theta, sigma=sigma, free=problem.free, trials=trial_fits,
                      notes=tuple(notes), position_rms_m=position_rms, angle_rms_rad=angle_rms,
                      residual_scale=math.sqrt(s2), problems=tuple(problems), evaluations=int(result.nfev),
                      wall_s=time.perf_counter() - started, covariance=covariance)


def _trial_fit(problem: _Problem, config: VehicleConfig, j: int, start: np.ndarray) -> TrialFit:
    trial, _ = problem.used[j]
    times, meas = problem.times[j], problem.measured[j]
    model = _model_at(config, trial, start, times, problem.options.max_step_s)
    err = _attitude_error(model[:, 6:10], meas[:, 6:10])
    # accumulated body-axis rotation since the trigger (∫ω dt; measured: summed attitude increments): no
    # Euler singularity when a slow pitch flip passes 90°
    measured_angles = meas[:, RATE_INT] - meas[0, RATE_INT]
    fitted_angles = model[:, RATE_INT] - model[0, RATE_INT]
    return TrialFit(trial=trial, times_s=times, measured_position_m=meas[:, 0:3].copy(),
                    fitted_position_m=model[:, 0:3].copy(), measured_angles_rad=measured_angles,
                    fitted_angles_rad=fitted_angles,
                    position_rms_m=float(np.sqrt(np.mean((meas[:, 0:3] - model[:, 0:3]) ** 2))),
                    angle_rms_rad=float(np.sqrt(np.mean(err**2))), start=np.array(start, dtype=float))
