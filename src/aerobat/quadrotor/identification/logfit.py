"""Identify a vehicle from its own flight log, without motion capture.

The model (per motor i, command u_i, thrust f_i):

* static thrust curve ``f(u) = f_max · c(u)``, ``c(u) = [(1 − r)·√(k u² + (1 − k) u) + r]²``
  (the Betaflight plant's curve: r the thrust-at-zero term, k the shape; c(1) = 1);
* motor dynamics: ``f_i`` follows ``f(u_i(t − d))`` with first-order time constant τ
  (d the command-to-thrust delay of ESC, logging and filters);
* specific force along body z: ``a_z = Σ f_i / m``;
* angular acceleration per axis: ``ω̇ = M f / I + b`` with ``M`` the mixer's moment arms
  (roll ``y_i``, pitch ``−x_i``, yaw ``−spin_i κ``), plus on yaw the rotor-inertia reaction
  to changing rotor speed, ``−J_r Σ spin_i Ω̇_i`` with Ω ∝ √f.

What it can tell apart: τ and d; r and k; ``f_max/m`` (so ``f_max`` with the user's mass);
``f_max·|y|/I_xx`` and ``f_max·|x|/I_yy`` (so the inertias with the user's geometry); and
``κ·f_max/I_zz`` — the yaw moment per thrust only *relative* to I_zz: a log without motion
capture cannot separate κ from I_zz, so I_zz is taken from the prior's ratio
I_zz/(I_xx + I_yy) and κ follows. The hover command follows from the curve and the mass.

The fit is variable projection: τ, d, r, k by SciPy's least squares, and for each of their
values the linear gains and biases by linear least squares, per channel. Residuals are the
smoothed measured minus smoothed predicted signals (:func:`.logdata.smooth`), each channel
scaled by its own spread. Uncertainties are the jackknife spread over groups of blocks (the
residuals are strongly correlated in time, so the formal covariance would be far too small).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize
from scipy import signal as sps

from aerobat.config import check_type
from aerobat.core.bounds import Integer, Interval, bounded, required
from aerobat.core.bounds import validate as validate_bounds
from aerobat.errors import ConfigError, IdentificationFailed
from aerobat.quadrotor.flightlog import MotorLayout
from aerobat.quadrotor.identification.logdata import PreparedLog, band, smooth

__all__ = [
    "CHANNELS",
    "ChannelMetrics",
    "DelayPoint",
    "Geometry",
    "LogFit",
    "LogFitOptions",
    "LogModel",
    "delay_profile",
    "fit_log",
    "metrics",
    "predict",
    "targets",
    "thrust_curve",
    "validate",
]

CHANNELS = ("roll acceleration", "pitch acceleration", "yaw acceleration", "specific force z")
_UNITS = ("rad/s²", "rad/s²", "rad/s²", "m/s²")
MIN_MOTOR_RATE_HZ = 50.0  # motor commands logged slower than this cannot show the motor's time constant
_TAU_S = (0.003, 0.3)  # the motor time constants the fit searches [s]
_MOTOR_OFFSET = Interval(0.005, 2.0, unit="m")


@dataclass(frozen=True, kw_only=True)
class Geometry:
    """What a log cannot know: the vehicle's mass and where its motors are.

    Attributes
    ----------
    mass_kg : take-off mass [kg].
    motor_x_m, motor_y_m : motor distance from the centre along body x and y [m].
    inertia_zz_ratio : I_zz / (I_xx + I_yy), to split the yaw gain into κ and I_zz.
    """

    mass_kg: float = required(Interval(0.005, 50.0, unit="kg"))
    motor_x_m: float = required(_MOTOR_OFFSET)
    motor_y_m: float = required(_MOTOR_OFFSET)
    inertia_zz_ratio: float = bounded(0.93, Interval(0.3, 2.0))

    def __post_init__(self) -> None:
        validate_bounds(self)


@dataclass(frozen=True, kw_only=True)
class LogFitOptions:
    """Options of :func:`fit_log`.

    Attributes
    ----------
    jackknife_groups : block groups left out in turn for the uncertainties (0 or 1: none).
    instrument_setpoint : fit the moments with the set point's rate of change as instrument
        (instrumental variables) instead of least squares; see :func:`instruments` (off: on the
        shared 5-inch logs it gave negative held-out R², docs/logs.md).
    fixed_time_constant_s : use this motor time constant [s] instead of fitting it (it is fixed
        anyway when the motor commands are logged slower than 50 Hz); within the range the fit
        searches, 3 … 300 ms. None: fitted.
    max_delay_s : upper bound of the command-to-thrust delay the fit searches [s].
    """

    jackknife_groups: int = bounded(5, Integer(0, 100))
    instrument_setpoint: bool = False
    fixed_time_constant_s: float | None = bounded(None, Interval(*_TAU_S, unit="s"))
    max_delay_s: float = bounded(0.02, Interval(0.001, 0.2, unit="s"))

    def __post_init__(self) -> None:
        check_type("instrument_setpoint", self.instrument_setpoint, (bool, np.bool_), "True or False")
        validate_bounds(self, skip=("fixed_time_constant_s",) if self.fixed_time_constant_s is None else ())


@dataclass(frozen=True)
class LogModel:
    """The identified model: what :func:`predict` needs.

    ``tau_s, delay_s, r, k`` are the nonlinear parameters; ``gains[c], biases[c]`` per channel
    (roll, pitch, yaw: rad/s² per unit of normalized moment; specific force: f_max/m),
    and ``thrust_moments`` the roll, pitch and yaw
    acceleration per unit of normalized collective (a moment proportional to thrust);
    ``damping_per_s`` the rotational damping, angular acceleration per body rate [1/s].
    """

    tau_s: float
    delay_s: float
    r: float
    k: float
    gains: tuple[float, float, float, float]
    biases: tuple[float, float, float, float]
    thrust_moments: tuple[float, float, float]
    damping_per_s: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class ChannelMetrics:
    """Prediction quality on one channel: RMS error, RMS of the signal, R², correlation."""

    channel: str
    unit: str
    rms_error: float
    rms_signal: float
    r2: float
    correlation: float
    samples: int


@dataclass(frozen=True)
class LogFit:
    """Result of :func:`fit_log`.

    Attributes
    ----------
    name : the log fitted.
    model : the identified model.
    geometry : mass and motor positions used.
    values : identified quantities: name -> (value, 1-σ jackknife, unit).
    fit_segments_s, holdout_segments_s : (start, end) [s] of the blocks fitted on and held out.
    fit_metrics, holdout_metrics : prediction quality on fitted and held-out blocks.
    notes : what was fixed, assumed or could not be identified.
    wall_s : time the fit took [s].
    """

    name: str
    model: LogModel
    geometry: Geometry
    layout: MotorLayout
    values: dict[str, tuple[float, float, str]]
    fit_segments_s: tuple[tuple[float, float], ...]
    holdout_segments_s: tuple[tuple[float, float], ...]
    fit_metrics: tuple[ChannelMetrics, ...]
    holdout_metrics: tuple[ChannelMetrics, ...]
    notes: tuple[str, ...] = ()
    wall_s: float = 0.0
    evaluations: int = 0
    extra: dict[str, object] = field(default_factory=dict)

    def value(self, name: str) -> float:
        return self.values[name][0]


def thrust_curve(u: np.ndarray, r: float, k: float) -> np.ndarray:
    """c(u) = [(1 − r)·√(k u² + (1 − k) u) + r]² for u > 0, 0 for a stopped motor (c(1) = 1)."""
    u = np.clip(u, 0.0, 1.5)
    s = np.sqrt(np.maximum(k * u * u + (1.0 - k) * u, 0.0))
    return np.where(u > 0.0, ((1.0 - r) * s + r) ** 2, 0.0)


def _lag(x: np.ndarray, tau_s: float, dt_s: float) -> np.ndarray:
    alpha = 1.0 - math.exp(-dt_s / max(tau_s, 1e-4))
    zi = (1.0 - alpha) * x[:1]
    y, _ = sps.lfilter([alpha], [1.0, -(1.0 - alpha)], x, axis=0, zi=zi)
    return y


def _delayed(u: np.ndarray, delay_s: float, dt_s: float) -> np.ndarray:
    if delay_s <= 0:
        return u
    shift = delay_s / dt_s
    whole, frac = int(shift), shift - int(shift)
    padded = np.concatenate([np.repeat(u[:1], whole + 1, axis=0), u], axis=0)
    a = padded[1: len(u) + 1]       # u(t − whole·dt)
    b = padded[: len(u)]            # u(t − (whole + 1)·dt)
    return (1.0 - frac) * a + frac * b


def _regressors(log: PreparedLog, layout: MotorLayout, geometry: Geometry, tau_s: float, delay_s: float,
                r: float, k: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Band-passed (n, 3) normalized moments, smoothed (n,) collective, band-passed (n, 3) rates and collective."""
    thrust = _lag(thrust_curve(_delayed(log.motor_command, delay_s, log.dt_s), r, k), tau_s, log.dt_s)
    arms = layout.moment_arms(1.0, 1.0)  # signs only: gains carry the lengths
    moments = thrust @ arms               # (n, 3): Σ y_i c_i, −Σ x_i c_i, −Σ spin_i c_i
    collective = thrust.sum(axis=1)
    if log.acc_filter_hz > 0:  # the firmware filtered its accelerometer before logging it
        collective = _lag(collective, 1.0 / (2 * math.pi * log.acc_filter_hz), log.dt_s)
    return band(moments, log), smooth(collective, log), log.smoothed_gyro(), band(collective, log)


def targets(log: PreparedLog) -> np.ndarray:
    """(n, 4) smoothed measured roll, pitch, yaw accelerations and body-z specific force."""
    acc = log.angular_acceleration()
    return np.column_stack([acc, smooth(log.specific_force_m_s2[:, 2], log)])


def _design_matrices(reg: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]) -> list[np.ndarray]:
    moments, collective, rates, band_collective = reg
    # the collective column on each axis: a moment proportional to thrust (centre of mass off the
    # thrust centre, uneven motors), as the motion-capture identification's A_p, A_q
    # no offset on the specific force: an accelerometer is calibrated to far better than the
    # thrust at zero command, and a free offset would trade against the thrust curve (it did:
    # +3.6 m/s² on the Crazyflie, and the curve's hover command 0.79 against 0.62 measured)
    # and the body rate: rotational damping (rotor and body drag), which a flip at 1000 °/s shows
    return [np.column_stack([moments[:, c], band_collective, rates[:, c]]) for c in range(3)] + \
        [collective[:, None]]


def instruments(log: PreparedLog, mats: list[np.ndarray]) -> list[np.ndarray]:
    """Per channel, the instruments of its regressors: the set point's rate of change for the moment.

    In closed-loop flight the rate loop drives the motor differential against every disturbance
    moment (prop wash, drag, a gust), so the differential is correlated with what it does not
    explain and least squares shrinks the gain (the inertia comes out several times too large).
    The pilot's set point is outside that loop: its smoothed derivative, the angular acceleration
    the pilot asked for, is the instrument for the moment column (instrumental variables).
    """
    if log.rate_setpoint_rad_s is None:
        return mats
    demand = band(np.gradient(log.rate_setpoint_rad_s, log.time_s, axis=0), log)
    return [np.column_stack([demand[:, c], m[:, 1:]]) for c, m in enumerate(mats[:3])] + [mats[3]]


def _solve_linear(mats: list[np.ndarray], zs: list[np.ndarray], y: np.ndarray, rows: np.ndarray
                  ) -> list[np.ndarray]:
    out = []
    for c, (a, z) in enumerate(zip(mats, zs, strict=True)):
        if z is a:
            out.append(np.linalg.lstsq(a[rows], y[rows, c], rcond=None)[0])
        else:  # β = (Zᵀ X)⁻¹ Zᵀ y
            out.append(np.linalg.solve(z[rows].T @ a[rows], z[rows].T @ y[rows, c]))
    return out


def _model(nonlinear: np.ndarray, coefs: list[np.ndarray]) -> LogModel:
    tau, delay, r, k = (float(v) for v in nonlinear)
    return LogModel(tau_s=tau, delay_s=delay, r=r, k=k,
                    gains=(float(coefs[0][0]), float(coefs[1][0]), float(coefs[2][0]), float(coefs[3][0])),
                    biases=(0.0, 0.0, 0.0, 0.0),
                    thrust_moments=(float(coefs[0][1]), float(coefs[1][1]), float(coefs[2][1])),
                    damping_per_s=(-float(coefs[0][2]), -float(coefs[1][2]), -float(coefs[2][2])))


def predict(log: PreparedLog, model: LogModel, layout: MotorLayout, geometry: Geometry) -> np.ndarray:
    """(n, 4) smoothed predicted roll, pitch, yaw accelerations and body-z specific force."""
    mats = _design_matrices(_regressors(log, layout, geometry, model.tau_s, model.delay_s, model.r, model.k))
    a = model.thrust_moments
    coefs = [np.array([model.gains[c], a[c], -model.damping_per_s[c]]) for c in range(3)] + \
        [np.array([model.gains[3]])]
    return np.column_stack([a @ c for a, c in zip(mats, coefs, strict=True)])


def metrics(measured: np.ndarray, predicted: np.ndarray, rows: np.ndarray) -> tuple[ChannelMetrics, ...]:
    """Per-channel prediction quality on ``rows``."""
    out = []
    for c, (name, unit) in enumerate(zip(CHANNELS, _UNITS, strict=True)):
        y, p = measured[rows, c], predicted[rows, c]
        err = y - p
        sst = float(np.sum((y - y.mean()) ** 2))
        corr = float(np.corrcoef(y, p)[0, 1]) if len(y) > 2 and np.std(p) > 0 else float("nan")
        out.append(ChannelMetrics(channel=name, unit=unit, rms_error=float(np.sqrt(np.mean(err ** 2))),
                                  rms_signal=float(np.sqrt(np.mean((y - y.mean()) ** 2))),
                                  r2=1.0 - float(np.sum(err ** 2)) / sst if sst > 0 else float("nan"),
                                  correlation=corr, samples=int(rows.sum())))
    return tuple(out)


def _segments(log: PreparedLog, rows: np.ndarray) -> tuple[tuple[float, float], ...]:
    edges = np.flatnonzero(np.diff(np.concatenate([[0], rows.astype(np.int8), [0]])))
    return tuple((float(log.time_s[a]), float(log.time_s[b - 1])) for a, b in zip(edges[::2], edges[1::2],
                                                                                   strict=True))


def _stacked(logs: Sequence[PreparedLog], layout: MotorLayout, geometry: Geometry, theta: np.ndarray,
             iv: bool = False) -> tuple[list[np.ndarray], list[np.ndarray | None]]:
    """Design matrices and instruments of every log, stacked along time."""
    mats, zs = [], []
    for log in logs:
        m = _design_matrices(_regressors(log, layout, geometry, *theta))
        mats.append(m)
        zs.append(instruments(log, m) if iv else m)
    return ([np.vstack([m[c] for m in mats]) for c in range(4)],
            [np.vstack([z[c] for z in zs]) if any(z[c] is not m[c] for z, m in zip(zs, mats, strict=True))
             else None for c in range(4)])


def _solve(mats: list[np.ndarray], zs: list[np.ndarray | None], y: np.ndarray, rows: np.ndarray
           ) -> list[np.ndarray]:
    return _solve_linear(mats, [m if z is None else z for m, z in zip(mats, zs, strict=True)], y, rows)


def _rows(logs: Sequence[PreparedLog]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The logs' stacked targets, and their fit and held-out rows."""
    y = np.vstack([targets(log) for log in logs])
    train = np.concatenate([log.in_flight & ~log.holdout for log in logs])
    holdout = np.concatenate([log.holdout for log in logs])
    return y, train, holdout


@dataclass(frozen=True)
class DelayPoint:
    """The fit with its command-to-thrust delay held at ``delay_s`` (:func:`delay_profile`).

    ``tau_s``, ``r``, ``k``: the other nonlinear parameters refitted; ``cost``: the fit blocks'
    normalized sum of squares ÷ its value at the free fit's delay; ``holdout``: the held-out
    blocks' metrics (the moments' band, as :attr:`LogFit.holdout_metrics`).
    """

    delay_s: float
    tau_s: float
    cost: float
    holdout: tuple[ChannelMetrics, ...]


def delay_profile(logs: PreparedLog | Sequence[PreparedLog], layout: MotorLayout, geometry: Geometry,
                  fit: LogFit, delays_s: Sequence[float], *, options: LogFitOptions | None = None
                  ) -> tuple[DelayPoint, ...]:
    """The fit ``fit`` refitted with its delay held at each of ``delays_s`` [s] (the motor's time constant,
    thrust curve and every linear coefficient free): how much of the delay the logs decide."""
    logs = (logs,) if isinstance(logs, PreparedLog) else tuple(logs)
    options = options or LogFitOptions()
    y, train, holdout = _rows(logs)
    m = fit.model
    best = np.array([m.tau_s, m.delay_s, m.r, m.k])
    lo = np.array([_TAU_S[0], 0.0, 0.0, 0.0])
    hi = np.array([_TAU_S[1], max(options.max_delay_s, max(delays_s) + 1e-3), 0.6, 1.0])
    scale = np.std(y[train], axis=0)
    scale[scale <= 0] = 1.0

    def cost(theta: np.ndarray, coefs: list[np.ndarray]) -> float:
        mats, _ = _stacked(logs, layout, geometry, theta)
        return float(sum(np.sum(((y[train, c] - mats[c][train] @ coefs[c]) / scale[c]) ** 2) for c in range(4)))

    mats, zs = _stacked(logs, layout, geometry, best, options.instrument_setpoint)
    reference = cost(best, _solve(mats, zs, y, train))
    points = []
    for delay in delays_s:
        start = np.clip(best, lo + 1e-6, hi - 1e-6)
        theta, coefs, _ = _fit_rows(logs, layout, geometry, y, train, start, (lo, hi), {1: float(delay)},
                                    iv=options.instrument_setpoint)
        model = _model(theta, coefs)
        predicted = np.vstack([predict(log, model, layout, geometry) for log in logs])
        points.append(DelayPoint(delay_s=float(delay), tau_s=model.tau_s, cost=cost(theta, coefs) / reference,
                                 holdout=metrics(y, predicted, holdout)))
    return tuple(points)


def _fit_rows(logs: Sequence[PreparedLog], layout: MotorLayout, geometry: Geometry, y: np.ndarray,
              rows: np.ndarray, x0: np.ndarray, bounds: tuple[np.ndarray, np.ndarray], fixed: Mapping[int, float],
              max_nfev: int = 60, iv: bool = False) -> tuple[np.ndarray, list[np.ndarray], int]:
    """The nonlinear parameters (tau, delay, r, k) fitted on ``rows``, those in ``fixed`` (index: value) held."""
    scale = np.std(y[rows], axis=0)
    scale[scale <= 0] = 1.0
    sub = np.flatnonzero(rows)
    evaluations = 0
    free = [i for i in range(len(x0)) if i not in fixed]
    held = np.asarray(x0, dtype=float).copy()
    for i, value in fixed.items():
        held[i] = value

    def full(theta: np.ndarray) -> np.ndarray:
        out = held.copy()
        out[free] = theta
        return out

    def residuals(theta: np.ndarray) -> np.ndarray:
        nonlocal evaluations
        evaluations += 1
        mats, zs = _stacked(logs, layout, geometry, full(theta), iv)
        coefs = _solve(mats, zs, y, rows)
        return np.concatenate([(y[sub, c] - mats[c][sub] @ coefs[c]) / scale[c] for c in range(4)])

    lo, hi = bounds
    start, lower, upper = x0[free], lo[free], hi[free]
    sol = optimize.least_squares(residuals, start, bounds=(lower, upper), x_scale="jac", diff_step=1e-3,
                                 xtol=1e-6, ftol=1e-8, max_nfev=max_nfev)
    theta = full(sol.x)
    mats, zs = _stacked(logs, layout, geometry, theta, iv)
    return theta, _solve(mats, zs, y, rows), evaluations


def _quantities(model: LogModel, geometry: Geometry) -> dict[str, float]:
    m = geometry.mass_kg
    f_max = model.gains[3] * m
    out = {
        "motor_time_constant_s": model.tau_s,
        "motor_delay_s": model.delay_s,
        "thrust_curve_r": model.r,
        "thrust_curve_k": model.k,
        "thrust_max_n": f_max,
        "collective_max_m_s2": 4.0 * model.gains[3],
    }
    # hover: 4 f_max c(u) = m g (g from the log's own mean specific force would include manoeuvres)
    target = 9.81 / (4.0 * model.gains[3])
    u = np.linspace(0.0, 1.0, 20001)
    c = thrust_curve(u, model.r, model.k)
    out["hover_command"] = float(np.interp(target, c, u)) if c[-1] >= target else float("nan")
    ixx = f_max * geometry.motor_y_m / model.gains[0] if model.gains[0] > 0 else float("nan")
    iyy = f_max * geometry.motor_x_m / model.gains[1] if model.gains[1] > 0 else float("nan")
    izz = geometry.inertia_zz_ratio * (ixx + iyy)
    out.update({
        "roll_effectiveness_rad_s2": model.gains[0],
        "pitch_effectiveness_rad_s2": model.gains[1],
        "yaw_effectiveness_rad_s2": model.gains[2],
        "inertia_xx_kg_m2": ixx,
        "inertia_yy_kg_m2": iyy,
        "kappa_over_izz_1_kg_m": model.gains[2] / f_max,
        "inertia_zz_kg_m2": izz,
        "kappa_m": model.gains[2] * izz / f_max,
    })
    return out


UNITS = {"motor_time_constant_s": "s", "motor_delay_s": "s", "thrust_curve_r": "1", "thrust_curve_k": "1",
         "thrust_max_n": "N", "collective_max_m_s2": "m/s²", "hover_command": "fraction",
         "roll_effectiveness_rad_s2": "rad/s² at full differential", "pitch_effectiveness_rad_s2":
         "rad/s² at full differential", "yaw_effectiveness_rad_s2": "rad/s² at full differential",
         "inertia_xx_kg_m2": "kg m²", "inertia_yy_kg_m2": "kg m²", "kappa_over_izz_1_kg_m": "1/(kg m)",
         "inertia_zz_kg_m2": "kg m² (assumed ratio)", "kappa_m": "m (with the assumed I_zz)",
         "hover_command_measured": "fraction (hovering samples; ± half the interquartile range)"}


def fit_log(logs: PreparedLog | Sequence[PreparedLog], layout: MotorLayout, geometry: Geometry, *,
            options: LogFitOptions | None = None,
            x0: tuple[float, float, float, float] = (0.03, 0.002, 0.1, 0.5)) -> LogFit:
    """Identify the model from the fit blocks of one or several logs of one vehicle.

    Each log's every fifth block of :data:`.logdata.BLOCK_S` is held out; the metrics on those
    blocks are the validation.
    """
    logs = (logs,) if isinstance(logs, PreparedLog) else tuple(logs)
    if not logs:
        raise ConfigError("fit_log: no log given")
    options = options or LogFitOptions()
    started = time.perf_counter()
    notes: list[str] = [f"{log.name}: {note}" for log in logs for note in log.notes]
    iv = options.instrument_setpoint
    if iv and any(log.rate_setpoint_rad_s is None for log in logs):
        raise ConfigError(f"{', '.join(log.name for log in logs)}: instrument_setpoint needs a logged rate set point")
    notes.append("moments fitted in the 2-20 Hz band " + ("with the set point's rate of change as the instrument"
                                                          if iv else "by least squares"))
    fixed_tau = options.fixed_time_constant_s
    slowest = min(log.motor_rate_hz for log in logs)
    if fixed_tau is None and slowest < MIN_MOTOR_RATE_HZ:
        fixed_tau = x0[0]
        notes.append(f"motor commands logged at {slowest:.0f} Hz, too slow to show the motor's time "
                     f"constant: it is fixed at {fixed_tau * 1e3:.0f} ms, not identified")
    y, train, holdout = _rows(logs)
    offsets = np.cumsum([0] + [int(log.block.max()) + 1 for log in logs[:-1]])
    block = np.concatenate([np.where(log.block >= 0, log.block + off, -1) for log, off in zip(logs, offsets,
                                                                                              strict=True)])
    lo = np.array([_TAU_S[0], 0.0, 0.0, 0.0])
    hi = np.array([_TAU_S[1], options.max_delay_s, 0.6, 1.0])
    start = np.clip(np.array(x0, dtype=float), lo + 1e-6, hi - 1e-6)
    held = {0: fixed_tau} if fixed_tau is not None else {}
    theta, coefs, evaluations = _fit_rows(logs, layout, geometry, y, train, start, (lo, hi), held, iv=iv)
    model = _model(theta, coefs)
    names = ", ".join(log.name for log in logs)
    if min(model.gains) <= 0:
        bad = [CHANNELS[i] for i, g in enumerate(model.gains) if g <= 0]
        raise IdentificationFailed(f"{names}: the motors do not explain the {', '.join(bad)} with the expected "
                                   f"sign (gains {', '.join(f'{g:.3g}' for g in model.gains)}): the motor layout "
                                   f"({layout.mixer}) or the log's axes are not what this log holds")
    best = _quantities(model, geometry)
    # jackknife over groups of blocks, each refit starting from the full fit
    groups = options.jackknife_groups
    spread: dict[str, float] = {name: float("nan") for name in best}
    if groups >= 2:
        blocks = np.unique(block[train])
        samples = []
        for g in range(groups):
            drop = np.isin(block, blocks[g::groups])
            th, cf, n = _fit_rows(logs, layout, geometry, y, train & ~drop, theta, (lo, hi), held, max_nfev=12,
                                  iv=iv)
            evaluations += n
            samples.append(_quantities(_model(th, cf), geometry))
        for name in best:
            v = np.array([s[name] for s in samples])
            spread[name] = float(np.sqrt((groups - 1) / groups * np.sum((v - v.mean()) ** 2)))
    if fixed_tau is not None:
        spread["motor_time_constant_s"] = float("nan")
    notes.append(f"I_zz is not identifiable without motion capture (only κ/I_zz is): taken as "
                 f"{geometry.inertia_zz_ratio:.2f} × (I_xx + I_yy)")
    predicted = np.vstack([predict(log, model, layout, geometry) for log in logs])
    hover, hover_spread = measured_hover_command(logs)
    best["hover_command_measured"] = hover
    spread["hover_command_measured"] = hover_spread
    values = {name: (best[name], spread[name], UNITS[name]) for name in best}
    seg_fit = tuple(seg for log in logs for seg in _segments(log, log.in_flight & ~log.holdout))
    seg_hold = tuple(seg for log in logs for seg in _segments(log, log.holdout))
    return LogFit(name=names, model=model, geometry=geometry, layout=layout, values=values,
                  fit_segments_s=seg_fit, holdout_segments_s=seg_hold,
                  fit_metrics=metrics(y, predicted, train), holdout_metrics=metrics(y, predicted, holdout),
                  notes=tuple(notes), wall_s=time.perf_counter() - started, evaluations=evaluations)


def measured_hover_command(logs: Sequence[PreparedLog]) -> tuple[float, float]:
    """Median mean motor command (and its interquartile half-range) where the vehicle hovered.

    Hover: body-z specific force within 0.05 g of g and every rate below 0.3 rad/s (smoothed);
    no model involved, a check of the thrust curve's hover command.
    """
    picks = []
    for log in logs:
        az = smooth(log.specific_force_m_s2[:, 2], log)
        still = np.all(np.abs(smooth(log.gyro_rad_s, log)) < 0.3, axis=1)
        mask = log.in_flight & still & (np.abs(az - 9.81) < 0.05 * 9.81)
        picks.append(log.motor_command[mask].mean(axis=1))
    u = np.concatenate(picks)
    if len(u) < 50:
        return float("nan"), float("nan")
    q1, q2, q3 = np.percentile(u, [25, 50, 75])
    return float(q2), float((q3 - q1) / 2)


def validate(fit: LogFit, log: PreparedLog) -> tuple[ChannelMetrics, ...]:
    """Prediction quality of ``fit`` on every in-flight sample of another log of the same vehicle."""
    y = targets(log)
    return metrics(y, predict(log, fit.model, fit.layout, fit.geometry), log.in_flight)
