"""A recorded flight through the firmware: the pilot's sticks, with their timing, into the SITL.

:func:`replay_sticks` powers a fresh firmware on, lets it calibrate on the floor, arms it, takes
the floor away (:meth:`.flight.Flight.release`) and streams the pilot's channels in ACRO, one
radio frame per period, lossless and without link latency (the log recorded the sticks where
the firmware received them). No position loop, no floor: the vehicle flies as the pilot flew
it. What comes back is the true body rates and the firmware's motor commands, sampled within
each frame.

The sticks come as Betaflight logs them (:func:`channels_from_commands`): ``rcCommand`` roll,
pitch and yaw are ±500 after the deadband (yaw negated: a right stick is a negative
``rcCommand[2]``), so the pulse is 1500 ± (|rcCommand| + deadband); the throttle is the
firmware's throttle after its curve, which
:meth:`aerobat.firmware.betaflight.settings.BetaflightSettings.throttle_us_for_motor` inverts to a pulse.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from aerobat.errors import ConfigError
from aerobat.firmware.betaflight.packets import MOTOR_LOG_ORDER
from aerobat.firmware.betaflight.rc import RC_MAX_US, RC_MID_US, RC_MIN_US
from aerobat.firmware.betaflight.settings import BetaflightSettings
from aerobat.plants.betaflight.flight import (
    N_SAMPLE,
    SAMPLE_GYRO,
    SAMPLE_MOTORS,
    SAMPLE_PID,
    SAMPLE_RATES,
    SAMPLE_SETPOINT,
    SAMPLE_TIME,
)
from aerobat.plants.betaflight.physics import A_BATTERY, A_FMAX, airframe_plant

if TYPE_CHECKING:
    from aerobat.plants.betaflight.plant import BetaflightPlant

__all__ = ["MOTOR_LOG_ORDER", "LogReplayer", "ReplayTrace", "StickTrack", "channels_from_commands", "replay_sticks"]



@dataclass(frozen=True)
class StickTrack:
    """The pilot's channels over time.

    Attributes
    ----------
    time_s : (n,) increasing sample times [s] (the log's).
    channels_us : (n, 4) roll, pitch, throttle, yaw pulses [us] (AETR).
    """

    time_s: np.ndarray
    channels_us: np.ndarray

    def __post_init__(self) -> None:
        t = np.asarray(self.time_s, dtype=float)
        c = np.asarray(self.channels_us, dtype=float)
        if t.ndim != 1 or c.shape != (t.shape[0], 4) or t.shape[0] < 2:
            raise ValueError(f"stick track: time {t.shape}, channels {c.shape}; need (n,) and (n, 4), n >= 2")
        if np.any(np.diff(t) <= 0):
            raise ValueError("stick track: times must increase")
        object.__setattr__(self, "time_s", t)
        object.__setattr__(self, "channels_us", c)

    @property
    def duration_s(self) -> float:
        return float(self.time_s[-1] - self.time_s[0])

    def at(self, t_s: float) -> np.ndarray:
        """The channels held from the last sample at or before ``t_s`` (a receiver holds its frame)."""
        i = int(np.searchsorted(self.time_s, t_s, side="right")) - 1
        return self.channels_us[max(i, 0)]


@dataclass(frozen=True)
class ReplayTrace:
    """What the SITL flew.

    Attributes
    ----------
    time_s : (m,) times from the track's first sample [s].
    rates_rad_s : (m, 3) true body rates, body FLU.
    motors : (m, 4) the firmware's motor commands in Betaflight's motor order M1..M4 (0 stopped,
        1 full; the armed idle is ``motor_idle``).
    setpoint_deg_s : (m, 3) the firmware's rate set point (as blackbox logs it: firmware axes,
        roll, pitch, yaw), NaN from a SITL whose motor packet does not carry it.
    pid : (m, 4, 3) the firmware's P, I, D, F terms (rows) per axis (columns), blackbox units; NaN
        likewise.
    armed_at_s : simulated time of arming since power-on.
    steps : lockstep steps taken.
    gyro_sensor_rad_s : (m, 3) the gyro the firmware read, body FLU: the true rates with the sensor's scale
        error, bias and noise and the frame's vibration (the airframe's ``vibration_*``); None from a plant that
        does not say it.
    """

    time_s: np.ndarray
    rates_rad_s: np.ndarray
    motors: np.ndarray
    setpoint_deg_s: np.ndarray
    pid: np.ndarray
    armed_at_s: float
    steps: int
    gyro_sensor_rad_s: np.ndarray | None = None


def channels_from_commands(settings: BetaflightSettings, roll_pitch_yaw: np.ndarray, throttle: np.ndarray
                           ) -> np.ndarray:
    """(n, 4) AETR pulses for Betaflight's logged ``rcCommand`` roll, pitch, yaw (±500) and throttle (0..1).

    ``throttle`` is ``(rcCommand[3] − 1000) / 1000``: the throttle after the firmware's curve.
    """
    rpy = np.asarray(roll_pitch_yaw, dtype=float)
    band = float(settings.value("deadband"))
    yaw_band = float(settings.value("yaw_deadband"))
    out = np.empty((rpy.shape[0], 4))
    for col, axis, sign, dead in ((0, 0, 1.0, band), (1, 1, 1.0, band), (3, 2, -1.0, yaw_band)):
        v = rpy[:, axis]
        pulse = RC_MID_US + sign * np.sign(v) * (np.abs(v) + np.where(v != 0.0, dead, 0.0))
        out[:, col] = np.clip(np.round(pulse), RC_MIN_US, RC_MAX_US)
    idle = float(settings.value("motor_idle")) / 10000.0
    thr = np.clip(np.asarray(throttle, dtype=float), 0.0, 1.0)
    out[:, 2] = [round(settings.throttle_us_for_motor(idle + (1.0 - idle) * y)) for y in thr]
    return out


def replay_sticks(plant: BetaflightPlant, track: StickTrack, *, samples_per_frame: int = 4,
                  progress: Callable[[float, float], None] | None = None,
                  thrust_scale: np.ndarray | None = None) -> ReplayTrace:
    """Fly ``track`` through ``plant``'s firmware (a :class:`~.plant.BetaflightPlant`) in ACRO, in the air.

    ``progress(done_s, total_s)`` is called about once per simulated second. ``thrust_scale`` (one per
    ``track.time_s``) multiplies every rotor's thrust from frame to frame (a battery's sag, the logged voltage's);
    None: 1. The airframe's own battery model (``battery_rest_v``, for learning) never flies in a replay.
    """
    from aerobat.plants.supervisor import TrialStop

    params = plant.params
    flight = plant.open_flight(rng=np.random.default_rng(plant.seed), plant=airframe_plant(params))
    with flight:
        flight.latency_steps = 0
        try:
            armed = plant.pilot.power_on_and_arm(flight)
        except TrialStop as stop:
            raise ConfigError(f"the tune does not arm: {stop}") from None
        flight.release()
        period = 1.0 / params.radio.rate_hz
        frames = max(1, math.ceil(track.duration_s / period))
        rows = np.empty((frames * samples_per_frame, N_SAMPLE))
        aux = plant.settings.aux_us(ARM=True, ANGLE=False)
        tail = (*aux, *([RC_MIN_US] * (12 - len(aux))))
        t0 = flight.time_s
        next_report = 1.0
        f_max = float(flight.aux[A_FMAX])
        scale = None if thrust_scale is None else np.asarray(thrust_scale, dtype=float)
        if scale is not None and scale.shape != track.time_s.shape:
            raise ValueError(f"thrust_scale: {scale.shape}, expected one per track sample {track.time_s.shape}")
        # a replay's thrust follows the logged voltage or stays as identified: the airframe's battery model (for
        # learning, where no log says the voltage) stands down, as the logged voltage already holds the pack's sag
        flight.aux[A_BATTERY + 2] = 0.0
        for k in range(frames):
            c = track.at(track.time_s[0] + k * period)
            if scale is not None:
                flight.aux[A_FMAX] = f_max * float(np.interp(track.time_s[0] + k * period, track.time_s, scale))
            channels = (int(c[0]), int(c[1]), int(c[2]), int(c[3]), *tail)
            flight.sampled_frame(channels, rows[k * samples_per_frame:(k + 1) * samples_per_frame])
            if progress is not None and (k + 1) * period >= next_report:
                progress((k + 1) * period, frames * period)
                next_report += 1.0
        steps = flight.tick
    motors = rows[:, SAMPLE_MOTORS][:, list(MOTOR_LOG_ORDER)]
    setpoint, pid_terms = rows[:, SAMPLE_SETPOINT].copy(), rows[:, SAMPLE_PID].copy()
    if not (np.any(setpoint) or np.any(pid_terms)):  # a SITL whose motor packet carries the motors only
        setpoint[:] = np.nan
        pid_terms[:] = np.nan
    pid = pid_terms.reshape(-1, 3, 4).transpose(0, 2, 1)
    return ReplayTrace(time_s=rows[:, SAMPLE_TIME] - t0, rates_rad_s=rows[:, SAMPLE_RATES].copy(), motors=motors,
                       setpoint_deg_s=setpoint, pid=pid, armed_at_s=armed, steps=steps,
                       gyro_sensor_rad_s=rows[:, SAMPLE_GYRO].copy())


class LogReplayer:
    """A pilot's logged sticks through this plant's firmware, as :func:`aerobat.experiments.log_replay.replay_log`
    asks of a plant (:attr:`aerobat.plants.PlantSpec.replay`).

    ``params`` (:class:`~aerobat.plants.fpv.params.BetaflightParams`, None: the defaults) gives the
    airframe, sensors and firmware; ``tune`` replaces its tune (the log's header or a what-if's) and
    ``props_out`` its propellers' direction. The plant is built around the ``fpv5`` model (a replay designs
    nothing: the nominal vehicle only gives g).
    """

    def __init__(self, params: Any, *, tune: Any, props_out: bool, seed: int = 0) -> None:
        import dataclasses

        from aerobat.plants.betaflight.plant import BetaflightPlant
        from aerobat.plants.fpv.params import BetaflightParams
        from aerobat.quadrotor.vehicle import fpv5

        params = params if params is not None else BetaflightParams()
        self.params = dataclasses.replace(params, tune=tune,
                                          airframe=dataclasses.replace(params.airframe, props_out=props_out))
        self.plant = BetaflightPlant(fpv5(), self.params, seed=seed)

    @property
    def settings(self) -> BetaflightSettings:
        """The firmware's settings as the replay flies them (the tune applied)."""
        return self.plant.settings

    @property
    def tune_report(self) -> Any:
        """What became of the tune on the SITL (:class:`~aerobat.firmware.betaflight.translate.TuneReport`)."""
        return self.plant.tune_report

    @property
    def battery_reference_v(self) -> float | None:
        """The airframe's battery voltage at which thrust is as identified [V] (None: not known)."""
        return self.params.airframe.battery_reference_v

    def channels(self, rc_commands: np.ndarray, throttle: np.ndarray) -> np.ndarray:
        """The pulses [µs] of the logged ``rcCommand`` roll, pitch, yaw (±500) and throttle (0..1)."""
        return channels_from_commands(self.settings, rc_commands, throttle)

    def fly(self, time_s: np.ndarray, channels_us: np.ndarray, *, progress: Callable[[float, float], None] | None,
            thrust_scale: np.ndarray | None) -> ReplayTrace:
        """Fly the channels (:meth:`channels`) at their times: :func:`replay_sticks`."""
        return replay_sticks(self.plant, StickTrack(time_s, channels_us), progress=progress,
                             thrust_scale=thrust_scale)
