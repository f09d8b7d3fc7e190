"""A real flight replayed through the firmware, and held against its log.

:func:`replay_log` is what ``aerobat log replay FILE[:N] --plant betaflight`` runs: it reads a
Betaflight blackbox log, applies the log's own tune (its header) to the SITL, flies the
pilot's recorded sticks on an airframe (the default 5-inch, or one identified from a log) in
ACRO, in the air (:func:`aerobat.plants.betaflight.replay.replay_sticks`), and compares per
axis (body FLU, deg/s):

* **set point**: the firmware's own set point (the lockstep SITL's motor packet carries it)
  and the tune's rate curve applied to the logged sticks (aerobat's model of Betaflight's
  ``applyRates``), each against the logged ``setpoint``;
* **gyro**: the simulated body rates against the logged ``gyroADC``;
* **tracking error**: set point − gyro, simulated against logged;
* **motors**: the firmware's commands against the logged ``motor[0..3]`` (both as fractions of
  the DShot range);
* **steps**: set-point steps found in the log (a change of at least ``step_min_deg_s``
  within 100 ms, then held for 100 ms): rise time (10 → 90 % of the step) and overshoot of
  the logged and the simulated gyro on each.

Samples within 0.5 s of a logged gyro at its 2000 °/s limit (a crash, a prop strike: nothing a
pilot's sticks explain) are left out of every number, and the result says how many.

* **PID terms**: the firmware's P, I, D, F per axis against the logged ``axisP/I/D/F``
  (firmware units; Betaflight logs no yaw D).
* **vibration**: where the log records the gyro before the firmware's filters (``debug_mode`` GYRO_SCALED,
  :attr:`~aerobat.quadrotor.flightlog.Channel.GYRO_UNFILTERED`), it against the gyro the SITL's firmware
  read (the sensor's errors and the airframe's vibration lines), sampled at the log's instants as the blackbox
  samples the real gyro, so that a rotor line above the log's Nyquist frequency folds alike: the rms above
  :data:`VIBRATION_LOW_HZ` and the strongest line there, per axis (:class:`VibrationMatch`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from aerobat.errors import ConfigError
from aerobat.logs import read_logs
from aerobat.logs.refs import parse_log_ref
from aerobat.quadrotor.flightlog import Channel, FlightLog, LogFormat
from aerobat.quadrotor.identification.vibration import LOW_HZ
from aerobat.quadrotor.log_analysis import band_pass, welch

__all__ = ["FLYING_MOTOR", "VIBRATION_LOW_HZ", "AxisMatch", "LogReplay", "StepMatch", "VibrationMatch", "find_steps",
           "flying_voltage_v", "load_betaflight_log", "log_props_out", "replay_log"]

AXES = ("roll", "pitch", "yaw")
_STEP_RISE_S = 0.10
_STEP_HOLD_S = 0.10
SATURATED_DEG_S = 1900.0
"""A logged gyro this fast is at the sensor's 2000 °/s limit: a crash or a prop strike."""
_CRASH_MARGIN_S = 0.5


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.corrcoef(a, b)[0, 1]) if np.std(a) > 0 and np.std(b) > 0 else math.nan


@dataclass(frozen=True)
class AxisMatch:
    """Simulated against logged on one series: rms of the difference, correlation, and the logged spread.

    ``band_correlation`` is the correlation of the two in :data:`~aerobat.quadrotor.log_analysis.BAND_HZ`
    (nan where not computed).
    """

    rms: float
    correlation: float
    logged_rms: float
    band_correlation: float = math.nan

    @staticmethod
    def of(sim: np.ndarray, real: np.ndarray, dt_s: float | None = None) -> AxisMatch:
        diff = float(np.sqrt(np.mean((sim - real) ** 2)))
        band = (_correlation(band_pass(sim, dt_s), band_pass(real, dt_s))
                if dt_s is not None and dt_s > 0 and sim.size > 8 else math.nan)
        return AxisMatch(diff, _correlation(sim, real), float(np.sqrt(np.mean(real ** 2))), band)


VIBRATION_LOW_HZ = LOW_HZ
"""The vibration band starts here [Hz] and ends at the log's Nyquist frequency: above the pilot's sticks and the
frame's rigid-body motion, where a 5-inch's rotor lines land once folded (identification's
:data:`~aerobat.quadrotor.identification.vibration.LOW_HZ`)."""
_VIBRATION_SEGMENT = 256


@dataclass(frozen=True)
class VibrationMatch:
    """The gyro before the firmware's filters on one axis, logged against the SITL's (the gyro its firmware read).

    Attributes
    ----------
    rms_log_deg_s, rms_sim_deg_s : rms of the band from :data:`VIBRATION_LOW_HZ` to the log's Nyquist frequency
        [deg/s] (Welch's spectrum, 256-sample segments, over the replayed window).
    peak_log_hz, peak_sim_hz : the frequency of the band's strongest line [Hz], as sampled (a line above the
        Nyquist frequency appears folded).
    """

    rms_log_deg_s: float
    rms_sim_deg_s: float
    peak_log_hz: float
    peak_sim_hz: float

    @staticmethod
    def of(sim_deg_s: np.ndarray, log_deg_s: np.ndarray, rate_hz: float) -> VibrationMatch:
        def band(x: np.ndarray) -> tuple[float, float]:
            f, p = welch(x - x.mean(), rate_hz, _VIBRATION_SEGMENT)
            inside = f >= VIBRATION_LOW_HZ
            if not inside.any():
                return math.nan, math.nan
            df = float(f[1] - f[0])
            return float(np.sqrt(np.sum(p[inside]) * df)), float(f[inside][np.argmax(p[inside])])

        (rms_log, peak_log), (rms_sim, peak_sim) = band(log_deg_s), band(sim_deg_s)
        return VibrationMatch(rms_log, rms_sim, peak_log, peak_sim)


@dataclass(frozen=True)
class StepMatch:
    """One set-point step: where, how big, and the logged and simulated gyro's response."""

    axis: str
    time_s: float
    size_deg_s: float
    rise_log_s: float
    rise_sim_s: float
    overshoot_log: float
    overshoot_sim: float


@dataclass(frozen=True)
class LogReplay:
    """What :func:`replay_log` measured. Series are on the log's time base, deg/s, body FLU.

    Attributes
    ----------
    log : ``file#N``; window_s the replayed window (log time).
    airframe : where the airframe came from.
    tune_report : what the tune became on the SITL (:class:`~aerobat.firmware.betaflight.translate.TuneReport`).
    time_s, setpoint_log, setpoint_model, setpoint_sim, gyro_log, gyro_sim, motors_log, motors_sim,
        pid_log, pid_sim : the traces (pid: (n, 4, 3) P, I, D, F terms per axis, firmware units; NaN
        where not logged or not reported).
    setpoint, setpoint_curve, gyro, tracking : per axis (:data:`AXES`); setpoint is the firmware's.
    pid : per term (P, I, D, F) per axis; None where a side has no such term.
    motors : per motor M1..M4.
    steps : every step found.
    wall_s : wall time of the flight; steps: lockstep steps.
    props : which way the propellers turned (``in`` or ``out``, from the log's mixer) and why: the SITL's
        ``yaw_motors_reversed`` and the physics' spins follow it.
    battery : how thrust followed the logged battery voltage (or why not).
    gyro_unfiltered_log, gyro_sensor_sim : (n, 3) the logged gyro before the firmware's filters and the gyro the
        SITL's firmware read, at the log's instants [deg/s]; None where the log or the plant does not have it.
    vibration : per axis, the two above :data:`VIBRATION_LOW_HZ` (:class:`VibrationMatch`); empty without both.
    """

    log: str
    window_s: tuple[float, float]
    airframe: str
    tune_report: Any
    time_s: np.ndarray
    setpoint_log: np.ndarray
    setpoint_model: np.ndarray
    setpoint_sim: np.ndarray
    gyro_log: np.ndarray
    gyro_sim: np.ndarray
    motors_log: np.ndarray
    motors_sim: np.ndarray
    pid_log: np.ndarray
    pid_sim: np.ndarray
    setpoint: tuple[AxisMatch, ...]
    setpoint_curve: tuple[AxisMatch, ...]
    pid: tuple[tuple[AxisMatch | None, ...], ...]
    gyro: tuple[AxisMatch, ...]
    tracking: tuple[AxisMatch, ...]
    motors: tuple[AxisMatch, ...]
    steps: tuple[StepMatch, ...]
    wall_s: float
    lockstep_steps: int
    excluded_s: float = 0.0
    props: str = "in"
    battery: str = "not followed"
    gyro_unfiltered_log: np.ndarray | None = None
    gyro_sensor_sim: np.ndarray | None = None
    vibration: tuple[VibrationMatch, ...] = ()

    def step_summary(self) -> dict[str, dict[str, float]]:
        """Per axis: steps found, median rise time [s] and overshoot (fraction), logged and simulated."""
        out: dict[str, dict[str, float]] = {}
        for axis in AXES:
            mine = [s for s in self.steps if s.axis == axis]

            def med(values: list[float]) -> float:
                finite = [v for v in values if math.isfinite(v)]
                return float(np.median(finite)) if finite else math.nan

            out[axis] = {"steps": float(len(mine)),
                         "rise_log_s": med([s.rise_log_s for s in mine]),
                         "rise_sim_s": med([s.rise_sim_s for s in mine]),
                         "overshoot_log": med([s.overshoot_log for s in mine]),
                         "overshoot_sim": med([s.overshoot_sim for s in mine])}
        return out

    def summary(self) -> dict[str, Any]:
        """JSON-ready numbers (no traces)."""
        def axes(matches: tuple[AxisMatch, ...], names: tuple[str, ...]) -> dict[str, dict[str, float]]:
            return {n: dataclasses.asdict(m) for n, m in zip(names, matches, strict=True)}

        return {"log": self.log, "window_s": list(self.window_s), "airframe": self.airframe,
                "units": "deg/s (set point, gyro, tracking), fraction of the DShot range (motors)",
                "setpoint": axes(self.setpoint, AXES), "setpoint_curve": axes(self.setpoint_curve, AXES),
                "gyro": axes(self.gyro, AXES),
                "pid": {term: {a: (dataclasses.asdict(m) if m is not None else None)
                               for a, m in zip(AXES, row, strict=True)}
                        for term, row in zip("PIDF", self.pid, strict=True)},
                "tracking": axes(self.tracking, AXES), "motors": axes(self.motors, ("M1", "M2", "M3", "M4")),
                "steps": self.step_summary(), "step_list": [dataclasses.asdict(s) for s in self.steps],
                "excluded_s": self.excluded_s, "props": self.props, "battery": self.battery,
                "vibration": {a: dataclasses.asdict(m) for a, m in zip(AXES, self.vibration, strict=True)}
                if self.vibration else None,
                "wall_s": self.wall_s, "lockstep_steps": self.lockstep_steps}


def _response(t: np.ndarray, y: np.ndarray, start: int, before: float, after: float, end: int
              ) -> tuple[float, float]:
    """Rise time (10 → 90 % of before → after) and overshoot (fraction of the step) of ``y`` from ``start``."""
    size = after - before
    rel = (y[start:end] - before) / size
    tt = t[start:end]
    hit10 = np.nonzero(rel >= 0.1)[0]
    hit90 = np.nonzero(rel >= 0.9)[0]
    rise = float(tt[hit90[0]] - tt[hit10[0]]) if hit10.size and hit90.size and hit90[0] >= hit10[0] else math.nan
    return rise, float(max(rel.max() - 1.0, 0.0))


def find_steps(t: np.ndarray, setpoint: np.ndarray, *, min_deg_s: float = 100.0) -> list[tuple[int, int, int]]:
    """(start, settled, end) sample indices of set-point steps of one axis (deg/s).

    A step: the set point starts to move and has moved by at least ``min_deg_s`` within 100 ms,
    then stays within 20 % of the move for 100 ms. Steps do not overlap.
    """
    dt = float(np.median(np.diff(t)))
    rise = max(1, round(_STEP_RISE_S / dt))
    hold = max(2, round(_STEP_HOLD_S / dt))
    out: list[tuple[int, int, int]] = []
    i = 0
    n = setpoint.shape[0]
    while i + rise + hold < n:
        move = setpoint[i + rise] - setpoint[i]
        if abs(move) >= min_deg_s and abs(setpoint[i + 1] - setpoint[i]) > 0.05 * abs(move):
            level = setpoint[i + rise: i + rise + hold]
            if np.all(np.abs(level - level.mean()) <= 0.2 * abs(move)):
                out.append((i, i + rise, i + rise + hold))
                i += rise + hold
                continue
        i += 1
    return out


def _steps(t: np.ndarray, sp: np.ndarray, log: np.ndarray, sim: np.ndarray, min_deg_s: float) -> list[StepMatch]:
    found: list[StepMatch] = []
    for j, axis in enumerate(AXES):
        for start, settled, end in find_steps(t, sp[:, j], min_deg_s=min_deg_s):
            before = float(sp[start, j])
            after = float(np.mean(sp[settled:end, j]))
            rl, ol = _response(t, log[:, j], start, before, after, end)
            rs, os_ = _response(t, sim[:, j], start, before, after, end)
            found.append(StepMatch(axis, float(t[start]), after - before, rl, rs, ol, os_))
    return found


def load_betaflight_log(file: str | Path, index: int | None = None) -> FlightLog:
    """Log ``index`` (else the ``FILE:N`` in ``file``, else 1) of a Betaflight blackbox file; ConfigError otherwise."""
    ref = parse_log_ref(file)
    index = index if index is not None else (ref.index or 1)
    logs = read_logs(ref.path)
    if index > len(logs):
        raise ConfigError(f"{ref.path}: log {index} does not exist; the file holds {len(logs)} log(s)")
    log = logs[index - 1]
    if log.source is not LogFormat.BLACKBOX:
        raise ConfigError(f"{ref.path}: a {log.source.firmware} log; replay needs a Betaflight blackbox log "
                          "(its header is the tune, its rcCommand the sticks)")
    return log


def replay_log(file: str | Path, *, index: int | None = None, window_s: tuple[float, float] | None = None,
               params: Any = None, airframe_source: str = "the default 5-inch (params.airframe)",
               step_min_deg_s: float = 100.0, seed: int = 0, lead_in_s: float = 0.5,
               progress: Callable[[float, float], None] | None = None, tune: Any = None,
               changes: Sequence[str] = (), props_out: bool | None = None, battery: bool = True,
               plant: str | None = None) -> LogReplay:
    """Replay ``file`` (``FILE`` or ``FILE:N``; ``index`` wins) through Betaflight and compare with the log.

    ``plant`` flies it: a registered plant whose spec replays logs (:attr:`aerobat.plants.PlantSpec.replay`;
    None: the first, :func:`aerobat.plants.replaying_plants`, which is ``betaflight`` among the built-ins).
    ``params`` (the plant's settings, e.g. :class:`~aerobat.plants.fpv.params.BetaflightParams`;
    None: its defaults) gives the airframe, sensors and firmware; its ``tune`` is replaced by the log's
    header, or by ``tune`` (a :class:`~aerobat.firmware.betaflight.tune.Tune`: what-if), with ``changes``
    (``NAME=VALUE`` each, :func:`~aerobat.firmware.betaflight.tune.with_settings`) on top. The propellers
    turn as the log's mixer says (:func:`log_props_out`), or as ``props_out`` says when given. With
    ``battery`` (and a logged voltage) thrust follows the battery: every rotor's thrust × (V/V_ref)², V the
    logged voltage and V_ref the airframe's ``battery_reference_v`` (else the log's median in flight).
    ``window_s`` (log time, seconds) limits the comparison; default the whole log. The flight starts
    ``lead_in_s`` before the window (where the log allows), so that the vehicle, which starts at rest, has
    caught up with the pilot when the comparison begins.
    """
    import time

    from aerobat.firmware.betaflight.tune import tune_from_blackbox_header, with_settings
    from aerobat.plants import PLANTS, replaying_plants

    replaying = replaying_plants()
    if plant is None and not replaying:
        raise ConfigError("no registered plant replays a log (PlantSpec.replay)")
    spec = PLANTS.get(replaying[0] if plant is None else plant, source="log replay --plant")
    if spec.replay is None:
        raise ConfigError(f"log replay --plant {spec.name}: the {spec.name} plant replays no log; plants that do: "
                          f"{', '.join(replaying) or 'none'}")
    log = load_betaflight_log(file, index)
    where = f"{log.path}: log {log.index}"
    duration = log.duration_s
    start, end = window_s if window_s is not None else (0.0, duration)
    if not (0.0 <= start < end) or start >= duration:
        raise ConfigError(f"--window-s {start:g} {end:g}: the window must lie in the log's 0..{duration:.3f} s "
                          "and end after it starts")
    end = min(end, duration)
    if end - start < 0.1:
        raise ConfigError(f"--window-s {start:g} {end:g}: at least 0.1 s of log is needed")
    cut = log.window(max(0.0, start - lead_in_s), end)
    for channel in (Channel.STICKS, Channel.THROTTLE_STICK, Channel.RATE_SETPOINT, Channel.GYRO,
                    Channel.MOTOR_COMMAND):
        cut.signal(channel, purpose="replay")
    if tune is None:
        tune = tune_from_blackbox_header(dict(log.metadata.parameters), source=f"{log.path}#log{log.index}")
    from_log = props_out is None
    if props_out is None:  # the log's mixer decides which way the propellers turn, whatever the airframe says
        props_out = log_props_out(log)
    replayer = spec.replay(params, tune=with_settings(tune, changes), props_out=props_out, seed=seed)
    settings = replayer.settings
    sticks = cut.signals[Channel.STICKS]
    t = sticks.time_s
    throttle = cut.signals[Channel.THROTTLE_STICK].at(t)[:, 0]
    channels = replayer.channels(sticks.values * 500.0, throttle)
    scale, battery_note = (_battery_scale(log, t, replayer.battery_reference_v) if battery
                           else (None, "not followed (as asked)"))
    wall = time.perf_counter()
    trace = replayer.fly(t, channels, progress=progress, thrust_scale=scale)
    wall = time.perf_counter() - wall
    rel = t - t[0]
    keep = t >= start - 1e-9
    # the tune's curve on the pulses; yaw: a right stick is a negative (FLU) rate
    sp_model = np.array([[settings.rate_deg_s(axis, (row[col] - 1500.0) / 500.0) * sign
                          for axis, col, sign in (("roll", 0, 1.0), ("pitch", 1, 1.0), ("yaw", 3, -1.0))]
                         for row in channels])
    sp_log = np.degrees(cut.signals[Channel.RATE_SETPOINT].at(t))
    gyro_log = np.degrees(cut.signals[Channel.GYRO].at(t))
    gyro_sim = np.degrees(np.column_stack([np.interp(rel, trace.time_s, trace.rates_rad_s[:, j]) for j in range(3)]))
    motors_log = cut.signals[Channel.MOTOR_COMMAND].at(t)
    motors_sim = np.column_stack([np.interp(rel, trace.time_s, trace.motors[:, j]) for j in range(4)])
    sp_sim = np.column_stack([np.interp(rel, trace.time_s, trace.setpoint_deg_s[:, j]) for j in range(3)])
    pid_sim = np.stack([np.column_stack([np.interp(rel, trace.time_s, trace.pid[:, k, j]) for j in range(3)])
                        for k in range(4)], axis=1)
    # the gyro the firmware read, sampled at the log's instants (the latest sample at or before each): a point
    # sample, as the blackbox takes the real gyro's, so that lines above the log's Nyquist frequency fold alike
    if trace.gyro_sensor_rad_s is not None:
        at = np.clip(np.searchsorted(trace.time_s, rel + 1e-9, side="right") - 1, 0, trace.time_s.shape[0] - 1)
        sensor_sim = np.degrees(trace.gyro_sensor_rad_s[at])
    else:
        sensor_sim = np.full((t.shape[0], 3), math.nan)
    unfiltered_log = (np.degrees(cut.signals[Channel.GYRO_UNFILTERED].at(t)) if cut.has(Channel.GYRO_UNFILTERED)
                      else np.full((t.shape[0], 3), math.nan))
    pid = np.full((t.shape[0], 4, 3), math.nan)
    for k, channel in enumerate((Channel.PID_P, Channel.PID_I, Channel.PID_D, Channel.PID_F)):
        if cut.has(channel):
            values = cut.signals[channel].at(t)
            pid[:, k, : values.shape[1]] = values
    (t, sp_model, sp_sim, sp_log, gyro_log, gyro_sim, motors_log, motors_sim, pid, pid_sim, sensor_sim,
     unfiltered_log) = (
        a[keep] for a in (t, sp_model, sp_sim, sp_log, gyro_log, gyro_sim, motors_log, motors_sim, pid, pid_sim,
                          sensor_sim, unfiltered_log))
    saturated = t[np.any(np.abs(gyro_log) >= SATURATED_DEG_S, axis=1)]
    valid = np.ones(t.shape[0], dtype=bool)
    for ts in saturated:
        valid &= np.abs(t - ts) > _CRASH_MARGIN_S
    dt = float(np.median(np.diff(t))) if t.shape[0] > 1 else 0.0
    if valid.sum() < 10:
        raise ConfigError(f"{where}: the window {start:g}..{end:g} s is all crash (the logged gyro at its "
                          f"{SATURATED_DEG_S:g} °/s limit); nothing to compare")
    if not np.all(np.isfinite(gyro_sim)):
        raise ConfigError(f"{where}: the simulated flight went non-finite")
    v = valid
    both = bool(np.all(np.isfinite(sensor_sim)) and np.all(np.isfinite(unfiltered_log)) and dt > 0)
    vibration = tuple(VibrationMatch.of(sensor_sim[:, j], unfiltered_log[:, j], 1.0 / dt) for j in range(3)) \
        if both else ()
    return LogReplay(
        log=log.name, window_s=(float(start), float(end)), airframe=airframe_source,
        tune_report=replayer.tune_report, time_s=t, setpoint_log=sp_log, setpoint_model=sp_model, setpoint_sim=sp_sim,
        pid_sim=pid_sim,
        gyro_log=gyro_log, gyro_sim=gyro_sim, motors_log=motors_log, motors_sim=motors_sim, pid_log=pid,
        setpoint=tuple(AxisMatch.of(sp_sim[v, j], sp_log[v, j]) for j in range(3)),
        setpoint_curve=tuple(AxisMatch.of(sp_model[v, j], sp_log[v, j]) for j in range(3)),
        pid=tuple(tuple(AxisMatch.of(pid_sim[v, k, j], pid[v, k, j])
                        if np.all(np.isfinite(pid[v, k, j])) and np.all(np.isfinite(pid_sim[v, k, j])) else None
                        for j in range(3)) for k in range(4)),
        gyro=tuple(AxisMatch.of(gyro_sim[v, j], gyro_log[v, j], dt) for j in range(3)),
        tracking=tuple(AxisMatch.of(sp_model[v, j] - gyro_sim[v, j], sp_log[v, j] - gyro_log[v, j], dt)
                       for j in range(3)),
        motors=tuple(AxisMatch.of(motors_sim[v, j], motors_log[v, j], dt) for j in range(4)),
        steps=tuple(s for s in _steps(t, sp_log, gyro_log, gyro_sim, step_min_deg_s)
                    if v[int(np.searchsorted(t, s.time_s))]),
        wall_s=wall, lockstep_steps=trace.steps, excluded_s=float((~v).sum() * dt),
        props=("out" if props_out else "in") + (f" ({_mixer_note(log)})" if from_log else " (as asked)"),
        battery=battery_note,
        gyro_unfiltered_log=unfiltered_log if np.all(np.isfinite(unfiltered_log)) else None,
        gyro_sensor_sim=sensor_sim if np.all(np.isfinite(sensor_sim)) else None, vibration=vibration)


FLYING_MOTOR = 0.15
"""A log sample whose mean motor command is above this fraction is in flight (for the battery's reference)."""


def flying_voltage_v(log: FlightLog) -> float:
    """The median battery voltage [V] of ``log`` while it flies (mean motor command above :data:`FLYING_MOTOR`);
    nan without a logged voltage or a flying sample."""
    if not (log.has(Channel.BATTERY_VOLTAGE) and log.has(Channel.MOTOR_COMMAND)):
        return math.nan
    b = log.signals[Channel.BATTERY_VOLTAGE]
    flying = log.signals[Channel.MOTOR_COMMAND].at(b.time_s).mean(axis=1) > FLYING_MOTOR
    volts = b.values[flying, 0]
    volts = volts[np.isfinite(volts) & (volts > 0)]
    return float(np.median(volts)) if volts.size else math.nan


def _battery_scale(log: FlightLog, t: np.ndarray, reference_v: float | None) -> tuple[np.ndarray | None, str]:
    """Per stick sample the thrust factor (V/V_ref)², and what it did."""
    if not log.has(Channel.BATTERY_VOLTAGE):
        return None, "not followed: the log records no battery voltage"
    volts = log.signals[Channel.BATTERY_VOLTAGE].at(t)[:, 0]
    ref = reference_v if reference_v is not None else flying_voltage_v(log)
    which = "the airframe's battery_reference_v" if reference_v is not None else "the log's median in flight"
    if not (math.isfinite(ref) and np.all(np.isfinite(volts)) and np.all(volts > 0)):
        return None, "not followed: the logged voltage is not usable"
    scale = (volts / ref) ** 2
    return scale, (f"thrust × (V/{ref:.2f} V)², V the logged voltage, V_ref {which}: "
                   f"{scale.min():.2f}–{scale.max():.2f}, median {np.median(scale):.2f}")


def log_props_out(log: FlightLog) -> bool:
    """True when ``log``'s mixer turns the propellers out (:func:`aerobat.logs.betaflight.props_out`)."""
    from aerobat.logs.betaflight import props_out

    return props_out(log.motor_layout)


def _mixer_note(log: FlightLog) -> str:
    """What the reader said about the mixer (the header's ``yaw_motors_reversed`` or the yaw mixing)."""
    return next((n for n in log.notes if "mixer" in n or "props" in n), "the log's mixer")
