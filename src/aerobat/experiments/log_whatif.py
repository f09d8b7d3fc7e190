"""What if the pilot had flown this with another tune: a logged flight's sticks through the SITL twice.

:func:`what_if` is what ``aerobat log replay FILE[:N] --tune OTHER`` (and/or ``--set NAME=VALUE``) runs:
the log's sticks are flown through the Betaflight SITL once with the log's own tune (the twin of the
flight) and once with the other tune, on the same airframe, seed and window, and each is measured as
a pilot reads a flight (:class:`FlightReading`): the step response per axis (set point to gyro,
:func:`aerobat.quadrotor.log_analysis.estimate_step_response`, and the medians over the set-point steps
found), the tracking error, how often a motor is at full output, and the motors' noise above
:data:`NOISE_ABOVE_HZ`. The real flight is read the same way, so the three stand side by side. The
settings in which the two tunes differ, as the firmware runs them, are listed
(:func:`tune_differences`).

The sticks are the logged ones: a pilot flying the other tune would have moved them differently,
so the what-if shows how the quad answers the same inputs, not how the flight would have gone.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from aerobat.experiments.log_replay import AXES, LogReplay, replay_log
from aerobat.quadrotor.log_analysis import band_pass, estimate_step_response

__all__ = ["NOISE_ABOVE_HZ", "SATURATED_MOTOR", "AxisReading", "FlightReading", "TuneDifference", "WhatIf",
           "read_flight", "tune_differences", "what_if"]

NOISE_ABOVE_HZ = 20.0
"""Motor-command content above this [Hz] counts as noise (a pilot's inputs and the loop live below it)."""
SATURATED_MOTOR = 0.99
"""A motor command at or above this fraction of full output is saturated."""


@dataclass(frozen=True)
class AxisReading:
    """One axis of a flight as a pilot reads it.

    Attributes
    ----------
    delay_s, rise_s, overshoot : the estimated step response's 50 % time and 10 → 90 % rise [s], and
        overshoot (fraction); nan where the set point did not move enough to estimate.
    step_rise_s, step_overshoot : medians over the set-point steps found (nan if none).
    steps : set-point steps found.
    tracking_rms_deg_s : rms of set point − gyro [°/s].
    """

    delay_s: float
    rise_s: float
    overshoot: float
    step_rise_s: float
    step_overshoot: float
    steps: int
    tracking_rms_deg_s: float


@dataclass(frozen=True)
class FlightReading:
    """A flight (logged or simulated) as a pilot reads it: per axis, then the motors.

    Attributes
    ----------
    name : what flew (``log``, ``SITL, the log's tune``, ``SITL, what-if``).
    axes : per axis (:data:`~aerobat.experiments.log_replay.AXES`).
    saturated_fraction : share of samples with a motor at or above :data:`SATURATED_MOTOR`.
    motor_noise_rms : rms of the motor commands above :data:`NOISE_ABOVE_HZ`, mean over the motors (fraction).
    """

    name: str
    axes: tuple[AxisReading, ...]
    saturated_fraction: float
    motor_noise_rms: float


@dataclass(frozen=True)
class TuneDifference:
    """A setting the two tunes set to different values, as Betaflight 4.6 runs them."""

    name: str
    flown: str
    what_if: str


@dataclass(frozen=True)
class WhatIf:
    """The log, its twin (the log's own tune) and the what-if (another tune), over the same sticks."""

    flown: LogReplay
    what_if: LogReplay
    differences: tuple[TuneDifference, ...]
    what_if_source: str
    readings: tuple[FlightReading, FlightReading, FlightReading]

    def summary(self) -> dict[str, Any]:
        """Plain numbers for ``--json``: the differences and the three readings."""
        import dataclasses

        return {"log": self.flown.log, "window_s": list(self.flown.window_s), "what_if": self.what_if_source,
                "differences": [dataclasses.asdict(d) for d in self.differences],
                "readings": [_plain(dataclasses.asdict(r)) for r in self.readings]}


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _high_pass_rms(t: np.ndarray, x: np.ndarray, above_hz: float) -> float:
    """rms of ``x``'s content above ``above_hz`` (evenly spaced ``t``), by :func:`.band_pass`."""
    if x.size < 4:
        return math.nan
    dt = float(np.median(np.diff(t)))
    return float(np.sqrt(np.mean(band_pass(x, dt, (above_hz, 0.5 / dt)) ** 2)))


def read_flight(name: str, time_s: np.ndarray, setpoint_deg_s: np.ndarray, gyro_deg_s: np.ndarray,
                motors: np.ndarray, steps: dict[str, tuple[int, float, float]]) -> FlightReading:
    """A flight's :class:`FlightReading` from its (n, 3) set point and gyro [°/s] and (n, 4) motors (fractions);
    ``steps`` per axis: (count, median rise [s], median overshoot) of the set-point steps found."""
    axes = []
    for k, axis in enumerate(AXES):
        r = estimate_step_response(time_s, setpoint_deg_s[:, k], gyro_deg_s[:, k])
        count, rise, over = steps.get(axis, (0, math.nan, math.nan))
        axes.append(AxisReading(
            delay_s=r.delay_s if r else math.nan, rise_s=r.rise_s if r else math.nan,
            overshoot=r.overshoot if r else math.nan, step_rise_s=rise, step_overshoot=over, steps=count,
            tracking_rms_deg_s=float(np.sqrt(np.mean((setpoint_deg_s[:, k] - gyro_deg_s[:, k]) ** 2)))))
    saturated = float(np.mean(np.any(motors >= SATURATED_MOTOR, axis=1))) if motors.size else math.nan
    noise = float(np.mean([_high_pass_rms(time_s, motors[:, j], NOISE_ABOVE_HZ) for j in range(motors.shape[1])]))
    return FlightReading(name=name, axes=tuple(axes), saturated_fraction=saturated, motor_noise_rms=noise)


def _readings(flown: LogReplay, other: LogReplay) -> tuple[FlightReading, FlightReading, FlightReading]:
    def steps(result: LogReplay, side: str) -> dict[str, tuple[int, float, float]]:
        return {axis: (int(s["steps"]), s[f"rise_{side}_s"], s[f"overshoot_{side}"])
                for axis, s in result.step_summary().items()}

    def setpoint(result: LogReplay) -> np.ndarray:
        return result.setpoint_sim if np.all(np.isfinite(result.setpoint_sim)) else result.setpoint_model

    return (read_flight("log", flown.time_s, flown.setpoint_log, flown.gyro_log, flown.motors_log,
                        steps(flown, "log")),
            read_flight("SITL, the log's tune", flown.time_s, setpoint(flown), flown.gyro_sim, flown.motors_sim,
                        steps(flown, "sim")),
            read_flight("SITL, what-if", other.time_s, setpoint(other), other.gyro_sim, other.motors_sim,
                        steps(other, "sim")))


def tune_differences(flown: Any, other: Any) -> tuple[TuneDifference, ...]:
    """The settings two tunes (:class:`~aerobat.firmware.betaflight.tune.Tune`) give different values, as the
    firmware runs them (each translated to 4.6 over its defaults), sorted by name."""
    from aerobat.firmware.betaflight.settings import load_settings
    from aerobat.firmware.betaflight.translate import translate

    base = load_settings()
    a, b = base.with_tune(translate(flown)), base.with_tune(translate(other))
    out = []
    for name in sorted({n for n, _ in a.values} | {n for n, _ in b.values}):
        try:
            va, vb = a.resolved(name), b.resolved(name)
        except KeyError:
            continue
        if va.strip().lower() != vb.strip().lower():
            out.append(TuneDifference(name, va, vb))
    return tuple(out)


def what_if(file: str | Path, *, tune: Any = None, changes: Sequence[str] = (),
            window_s: tuple[float, float] | None = None, params: Any = None,
            airframe_source: str = "the default 5-inch (params.airframe)", step_min_deg_s: float = 100.0,
            seed: int = 0, progress: Callable[[float, float], None] | None = None) -> WhatIf:
    """Fly ``file``'s sticks with the log's own tune and with ``tune`` (default: the log's) plus ``changes``.

    Raises
    ------
    ConfigError
        As :func:`~aerobat.experiments.log_replay.replay_log`; also when neither ``tune`` nor ``changes`` is
        given (nothing to compare) or a change is not ``NAME=VALUE`` or names no setting.
    """
    from aerobat.errors import ConfigError
    from aerobat.experiments.log_replay import load_betaflight_log
    from aerobat.firmware.betaflight.tune import tune_from_blackbox_header, with_settings
    from aerobat.logs.refs import parse_log_ref

    if tune is None and not changes:
        raise ConfigError("a what-if replay needs --tune OTHER or --set NAME=VALUE (or both)")
    log = load_betaflight_log(file)
    own = tune_from_blackbox_header(dict(log.metadata.parameters), source=f"{log.path}#log{log.index}")
    other = with_settings(tune if tune is not None else own, changes)
    differences = tune_differences(own, other)  # refuses an unknown setting before anything flies
    from aerobat.firmware.betaflight.configure import check_commands
    from aerobat.firmware.betaflight.settings import load_settings
    from aerobat.firmware.betaflight.translate import translate

    report = translate(other)
    for _, _, line, why in report.refused:  # a change asked for by name is never dropped quietly
        if line < 0:
            raise ConfigError(f"{other.where(line)}: refused: {why}")
    check_commands(load_settings().with_tune(report))  # and a value out of its range
    common = {"window_s": window_s, "params": params, "airframe_source": airframe_source,
              "step_min_deg_s": step_min_deg_s, "seed": seed, "progress": progress}
    ref = parse_log_ref(file)
    flown = replay_log(ref.path, index=log.index, **common)
    replayed = replay_log(ref.path, index=log.index, tune=other, **common)
    return WhatIf(flown=flown, what_if=replayed, differences=differences, what_if_source=other.source,
                  readings=_readings(flown, replayed))
