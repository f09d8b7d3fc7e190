"""A flight log made ready to fit: one time base, the flight found, split into blocks.

What a log can identify without motion capture rests on two measured signals and one
command: the gyro (differentiated: angular acceleration), the accelerometer (specific force,
whose body-z part is the collective thrust per mass) and the motor commands. This module puts
them on the gyro's time base, finds where the vehicle was in the air, cuts that into blocks
of :data:`BLOCK_S` and assigns every :data:`HOLDOUT_EVERY`-th block to validation.

Signals are compared after the same zero-phase low-pass (:func:`smooth`), applied to what
is measured and to what the model predicts alike, so that differentiation noise and sensor
vibration weigh little and the filter itself biases nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal as sps

from aerobat.errors import ConfigError
from aerobat.quadrotor.flightlog import Channel, FlightLog

__all__ = ["BLOCK_S", "HOLDOUT_EVERY", "MIN_FLIGHT_S", "PreparedLog", "prepare_log", "smooth"]

BLOCK_S = 2.0           # length of a fit/validation block [s]
HOLDOUT_EVERY = 5       # every fifth block is held out for validation
MIN_FLIGHT_S = 8.0      # identification needs at least this much flight [s]
MIN_RATE_HZ = 100.0     # the gyro must be logged at least this fast to differentiate it
HIGHPASS_HZ = 2.0       # angular channels: high-pass corner of the comparison band [Hz]
CUTOFF_HZ = 20.0        # comparison low-pass corner [Hz]: well above the motors' (~5 Hz), below vibration
FLYING_ABOVE_IDLE = 0.1  # in the air: the mean motor command this far above its idle (fraction)
GAP_S = 0.3             # motors below that for less than this: still in the air [s]
TRIM_S = 0.5            # dropped at each end of a flight segment (take-off, landing)
IMPACT_M_S2 = 12 * 9.81  # a specific force above this is an impact or a saturated accelerometer


@dataclass(frozen=True)
class PreparedLog:
    """A log on one time base.

    Attributes
    ----------
    name : the log's name (``file.bbl#1``).
    time_s : (n,) the gyro's sample times [s].
    dt_s : the median step [s].
    gyro_rad_s : (n, 3) body rates, FLU.
    specific_force_m_s2 : (n, 3) accelerometer, FLU.
    motor_command : (n, motors) commands, fraction of full range, held from the last logged value.
    motor_rate_hz : how fast the motor commands were logged.
    in_flight : (n,) bool, samples used at all.
    block : (n,) int, block number of each in-flight sample (-1 elsewhere).
    holdout : (n,) bool, in-flight samples of validation blocks.
    segments_s : the in-flight segments (start, end) [s].
    cutoff_hz : the comparison low-pass's corner [Hz].
    acc_filter_hz : the corner of the firmware's own first-order accelerometer filter, 0 if none known.
    rate_setpoint_rad_s : (n, 3) the firmware's rate set point, FLU, if the log has it (the
        instrument that makes closed-loop flight data identifiable, see :mod:`.logfit`).
    """

    name: str
    time_s: np.ndarray
    dt_s: float
    gyro_rad_s: np.ndarray
    specific_force_m_s2: np.ndarray
    motor_command: np.ndarray
    motor_rate_hz: float
    in_flight: np.ndarray
    block: np.ndarray
    holdout: np.ndarray
    segments_s: tuple[tuple[float, float], ...]
    cutoff_hz: float
    acc_filter_hz: float
    rate_setpoint_rad_s: np.ndarray | None = None
    notes: tuple[str, ...] = ()

    @property
    def flight_s(self) -> float:
        return float(sum(b - a for a, b in self.segments_s))

    def smoothed_gyro(self) -> np.ndarray:
        """(n, 3) the gyro through :func:`smooth` (computed once)."""
        cached = self.__dict__.get("_smoothed_gyro")
        if cached is None:
            cached = band(self.gyro_rad_s, self)
            self.__dict__["_smoothed_gyro"] = cached
        return cached

    def angular_acceleration(self) -> np.ndarray:
        """(n, 3) smoothed derivative of the gyro [rad/s²]."""
        return band(np.gradient(self.gyro_rad_s, self.time_s, axis=0), self)


def smooth(x: np.ndarray, log: PreparedLog) -> np.ndarray:
    """Zero-phase 4th-order Butterworth low-pass at ``log.cutoff_hz``, along time, segment by segment."""
    out = np.array(x, dtype=float, copy=True)
    sos = sps.butter(2, log.cutoff_hz, fs=1.0 / log.dt_s, output="sos")
    for start, end in _runs(log.in_flight):
        if end - start > 30:
            out[start:end] = sps.sosfiltfilt(sos, out[start:end], axis=0)
    return out


def band(x: np.ndarray, log: PreparedLog) -> np.ndarray:
    """:func:`smooth`, then a zero-phase 2nd-order high-pass at :data:`HIGHPASS_HZ`, segment by segment.

    For the moments: slow changes of the motor differential answer slow disturbance moments
    (airspeed, a shifting centre of thrust) and make no angular acceleration; above about 1 Hz
    the differential is the pilot's and the rate loop's, and its effect is what the log shows.
    """
    out = smooth(x, log)
    sos = sps.butter(1, HIGHPASS_HZ, btype="highpass", fs=1.0 / log.dt_s, output="sos")
    for start, end in _runs(log.in_flight):
        if end - start > 30:
            out[start:end] = sps.sosfiltfilt(sos, out[start:end], axis=0)
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    return list(zip(edges[::2], edges[1::2], strict=True))


def _hold(t_src: np.ndarray, v: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Zero-order hold of samples (t_src, v) at times t."""
    idx = np.clip(np.searchsorted(t_src, t, side="right") - 1, 0, len(t_src) - 1)
    return v[idx]


DROPOUT_S = 0.05
FIT_RATE_HZ = 300.0  # logs sampled faster are averaged down to at most this rate before fitting


def _block_mean(x: np.ndarray, factor: int) -> np.ndarray:
    n = len(x) // factor * factor
    return x[:n].reshape(n // factor, factor, *x.shape[1:]).mean(axis=1)


def _fill_dropouts(u: np.ndarray, dt: float) -> tuple[np.ndarray, int]:
    """Hold the previous command over short runs where every motor reads exactly 0 between spinning samples."""
    zero = np.all(u == 0.0, axis=1)
    if not zero.any():
        return u, 0
    u = u.copy()
    filled = 0
    for start, end in _runs(zero):
        if start > 0 and end < len(u) and (end - start) * dt < DROPOUT_S and u[start - 1].min() > 0 and \
                u[end].min() > 0:
            u[start:end] = u[start - 1]
            filled += end - start
    return u, filled


def acc_filter_hz(log: FlightLog) -> float:
    """The firmware's accelerometer low-pass corner in the log (Betaflight's acc_lpf_hz, ×100 in 4.x headers)."""
    raw = log.metadata.parameters.get("acc_lpf_hz") if log.metadata.firmware == "Betaflight" else None
    try:
        return float(raw) / 100.0 if raw else 0.0
    except ValueError:
        return 0.0


def _no_flight(log: FlightLog, purpose: str, mean: np.ndarray, commanded: np.ndarray, motors_up: np.ndarray,
               finite: np.ndarray, dt: float) -> None:
    """Raise the ConfigError that says why no sample of ``log`` is in flight: motors that never spin, or
    spinning motors whose samples are all unusable (not finite, or an impact)."""
    where = f"{log.path}: log {log.index}"
    if not motors_up.any():
        top = f"{float(np.max(mean[commanded])):.3f}" if commanded.any() else "NaN"
        raise ConfigError(f"{where}: the motors never spin (the mean motor command stays at or below {top} of full "
                          f"range for all {log.duration_s:.1f} s): the vehicle did not fly in this log, so {purpose} "
                          "has nothing to fit")
    spun = f"the motors spin for {float(motors_up.sum()) * dt:.1f} s"
    if not (motors_up & finite).any():
        raise ConfigError(f"{where}: {spun}, but the gyro or specific force is NaN or infinite in every one of those "
                          f"samples, so {purpose} has nothing to fit")
    raise ConfigError(f"{where}: {spun}, but the specific force is above {IMPACT_M_S2 / 9.81:.0f} g (an impact or "
                      f"a saturated accelerometer) in every one of those samples, so {purpose} has nothing to fit")


def prepare_log(log: FlightLog, *, purpose: str = "identification") -> PreparedLog:
    """The log on the gyro's time base with its flight found; ConfigError naming what is missing."""
    if not log.metadata.is_multirotor:
        raise ConfigError(f"{log.path}: log {log.index} is of a {log.metadata.vehicle_type}, not a multirotor; "
                          f"{purpose} needs a multirotor")
    gyro = log.signal(Channel.GYRO, purpose)
    acc = log.signal(Channel.SPECIFIC_FORCE, purpose)
    motors = log.signal(Channel.MOTOR_COMMAND, purpose)
    if log.motor_layout is None or log.motor_layout.motors != motors.values.shape[1]:
        raise ConfigError(f"{log.path}: log {log.index} has {motors.values.shape[1]} motor outputs and no known "
                          f"mixer geometry; {purpose} needs a quadrotor's")
    if gyro.rate_hz < MIN_RATE_HZ:
        raise ConfigError(f"{log.path}: log {log.index} logs the gyro at {gyro.rate_hz:.0f} Hz; {purpose} needs at "
                          f"least {MIN_RATE_HZ:.0f} Hz")
    t = gyro.time_s
    dt = float(np.median(np.diff(t)))
    f = acc.values if acc.time_s is gyro.time_s or np.array_equal(acc.time_s, t) else acc.at(t)
    u = _hold(motors.time_s, motors.values, t)
    u, dropouts = _fill_dropouts(u, dt)
    w = gyro.values
    sp = log.signals[Channel.RATE_SETPOINT].at(t) if log.has(Channel.RATE_SETPOINT) else None
    factor = max(1, int(1.0 / (dt * FIT_RATE_HZ)))
    if factor > 1:  # block means: nothing the 20 Hz comparison or the motors could see is lost
        t, w, f, u = (_block_mean(x, factor) for x in (t, w, f, u))
        sp = _block_mean(sp, factor) if sp is not None else None
        dt *= factor
    commanded = np.all(np.isfinite(u), axis=1)
    finite = np.all(np.isfinite(w), axis=1) & np.all(np.isfinite(f), axis=1) & commanded
    mean = u.mean(axis=1)
    idle = float(np.percentile(mean[finite if finite.any() else commanded], 1.0)) if commanded.any() else 0.0
    motors_up = commanded & (mean > max(idle, 0.0) + FLYING_ABOVE_IDLE)
    spinning = finite & motors_up
    for start, end in _runs(~spinning):  # a dive or a hard yaw brings the motors down for a moment: still flying
        if 0 < start and end < len(spinning) and (end - start) * dt < GAP_S:
            spinning[start:end] = finite[start:end]
    with np.errstate(invalid="ignore"):  # a NaN sample is not finite: left out above
        spinning &= np.linalg.norm(f, axis=1) < IMPACT_M_S2
    trim = int(round(TRIM_S / dt))
    in_flight = np.zeros_like(spinning)
    segments = []
    for start, end in _runs(spinning):
        a, b = start + trim, end - trim
        if (b - a) * dt >= 1.0:
            in_flight[a:b] = True
            segments.append((float(t[a]), float(t[b - 1])))
    flight = float(in_flight.sum()) * dt
    if not spinning.any() and log.duration_s >= MIN_FLIGHT_S:
        _no_flight(log, purpose, mean, commanded, motors_up, finite, dt)
    if flight < MIN_FLIGHT_S:
        raise ConfigError(f"{log.path}: log {log.index} holds {flight:.1f} s of flight (motors above idle) in "
                          f"{log.duration_s:.2f} s; {purpose} needs at least {MIN_FLIGHT_S:.0f} s")
    notes: list[str] = []
    block = np.full(t.shape, -1)
    # blocks of BLOCK_S counted along the flight time only, so held-out blocks spread over every segment
    flight_index = np.cumsum(in_flight) - 1
    block[in_flight] = (flight_index[in_flight] * dt // BLOCK_S).astype(int)
    holdout = in_flight & (block % HOLDOUT_EVERY == HOLDOUT_EVERY // 2)
    if dropouts:
        notes.append(f"{dropouts} samples where every motor command reads 0 for less than {DROPOUT_S * 1e3:.0f} ms "
                     "inside flight were held at the previous command (logger dropouts)")
    nyquist = 0.5 / dt
    return PreparedLog(notes=tuple(notes), name=log.name, time_s=t, dt_s=dt, gyro_rad_s=w, specific_force_m_s2=f,
                       motor_command=u,
                       motor_rate_hz=motors.rate_hz, in_flight=in_flight, block=block, holdout=holdout,
                       segments_s=tuple(segments), cutoff_hz=min(CUTOFF_HZ, 0.4 * nyquist),
                       acc_filter_hz=acc_filter_hz(log),
                       rate_setpoint_rad_s=sp)
