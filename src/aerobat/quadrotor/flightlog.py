"""One flight-log type for every source: time series in SI units and aerobat's frames.

A :class:`FlightLog` is what a reader (:mod:`aerobat.logs`) makes of one log in a file,
whatever wrote it: a Betaflight blackbox, a PX4 ULog, a Crazyflie uSD card. Everything in it
is already converted:

* body quantities in body **FLU** (x forward, y left, z up): a positive roll rate lowers the
  right side, a positive pitch rate lowers the nose, a positive yaw rate turns the nose left;
* world quantities in **ENU**-like z-up axes (x, y horizontal, z up), attitude as a unit
  quaternion ``(w, x, y, z)`` rotating body FLU vectors into the world;
* rates in rad/s, specific force (what an accelerometer measures: non-gravitational force per
  mass, +g up at rest) in m/s², time in seconds from the start of the log, motor commands as
  fractions of the motor's full range (0 stopped, 1 full), battery voltage in volts.

Each series is a :class:`Signal` with its own time base (a ULog logs each topic at its own
rate); :class:`Channel` names the standard ones. The source's own fields that have no SI
meaning (PID terms in firmware units, raw sticks) keep their units, and say so.

The motors' geometry is the :class:`MotorLayout` of the source's mixer: for each motor column
the direction of its position in body FLU and its spin. Lengths come from the user (a log
does not know how big the frame is).
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from aerobat.errors import ConfigError

__all__ = [
    "Channel",
    "FlightLog",
    "LogMetadata",
    "LogFormat",
    "MotorLayout",
    "Signal",
]


class LogFormat(enum.Enum):
    """A flight log's format, which also says what wrote it (:attr:`firmware`)."""

    BLACKBOX = "blackbox"
    ULOG = "ulog"
    CRAZYFLIE = "crazyflie"

    @property
    def firmware(self) -> str:
        """What writes this format: ``"betaflight"`` (blackbox), ``"px4"`` (ULog), ``"crazyflie"``."""
        return _FIRMWARE[self]


_FIRMWARE = {LogFormat.BLACKBOX: "betaflight", LogFormat.ULOG: "px4", LogFormat.CRAZYFLIE: "crazyflie"}


class Channel(enum.Enum):
    """The standard series a log may hold; ``value`` is the name used in files and on the CLI."""

    GYRO = "gyro"                          # body rates [rad/s], body FLU (x, y, z)
    GYRO_UNFILTERED = "gyro_unfiltered"    # the gyro before the firmware's filters [rad/s], body FLU (x, y, z)
    SPECIFIC_FORCE = "specific_force"      # accelerometer [m/s²], body FLU
    MOTOR_COMMAND = "motor_command"        # per motor, fraction of full range [0, 1]
    RATE_SETPOINT = "rate_setpoint"        # the firmware's body-rate set point [rad/s], body FLU
    THROTTLE = "throttle"                  # collective command, fraction [0, 1]
    STICKS = "sticks"                      # pilot's roll, pitch, yaw sticks [-1, 1] (right, forward, right)
    THROTTLE_STICK = "throttle_stick"      # pilot's throttle after the firmware's throttle curve, fraction [0, 1]
    PID_P = "pid_p"                        # rate-loop terms per axis, firmware units (roll, pitch, yaw)
    PID_I = "pid_i"
    PID_D = "pid_d"
    PID_F = "pid_f"
    BATTERY_VOLTAGE = "battery_voltage"    # [V]
    POSITION = "position"                  # world, z up [m]
    VELOCITY = "velocity"                  # world, z up [m/s]
    ATTITUDE = "attitude"                  # quaternion (w, x, y, z), body FLU -> world z up

    @property
    def description(self) -> str:
        return _DESCRIPTIONS[self]


_DESCRIPTIONS = {
    Channel.GYRO: "body rates, body FLU [rad/s]",
    Channel.GYRO_UNFILTERED: "body rates before the firmware's filters, body FLU [rad/s]",
    Channel.SPECIFIC_FORCE: "specific force (accelerometer), body FLU [m/s²]",
    Channel.MOTOR_COMMAND: "motor commands, fraction of full range",
    Channel.RATE_SETPOINT: "rate set point, body FLU [rad/s]",
    Channel.THROTTLE: "throttle (collective command), fraction",
    Channel.STICKS: "pilot sticks roll/pitch/yaw, -1..1 (right, forward, right)",
    Channel.THROTTLE_STICK: "pilot's throttle after the throttle curve, fraction",
    Channel.PID_P: "rate loop P term, firmware units",
    Channel.PID_I: "rate loop I term, firmware units",
    Channel.PID_D: "rate loop D term, firmware units",
    Channel.PID_F: "rate loop feedforward term, firmware units",
    Channel.BATTERY_VOLTAGE: "battery voltage [V]",
    Channel.POSITION: "position, world z up [m]",
    Channel.VELOCITY: "velocity, world z up [m/s]",
    Channel.ATTITUDE: "attitude quaternion w, x, y, z (body FLU to world z up)",
}


@dataclass(frozen=True)
class Signal:
    """One time series.

    Attributes
    ----------
    channel : what it is.
    time_s : (n,) sample times [s] from the start of the log, non-decreasing.
    values : (n, k) samples, in the channel's unit and frame.
    columns : k component names (``("x", "y", "z")``, ``("m1", …)``).
    unit : the unit of ``values``.
    source_fields : the fields of the source it was made from (for the record).
    """

    channel: Channel
    time_s: np.ndarray
    values: np.ndarray
    columns: tuple[str, ...]
    unit: str
    source_fields: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        t = np.asarray(self.time_s, dtype=float)
        v = np.asarray(self.values, dtype=float)
        if v.ndim == 1:
            v = v[:, None]
        if t.ndim != 1 or v.shape[0] != t.shape[0] or v.shape[1] != len(self.columns):
            raise ValueError(f"{self.channel.value}: time {t.shape}, values {v.shape}, {len(self.columns)} columns")
        object.__setattr__(self, "time_s", t)
        object.__setattr__(self, "values", v)

    @property
    def samples(self) -> int:
        return int(self.time_s.shape[0])

    @property
    def rate_hz(self) -> float:
        """Median sample rate [Hz] (0 for fewer than two samples)."""
        if self.samples < 2:
            return 0.0
        dt = float(np.median(np.diff(self.time_s)))
        return 1.0 / dt if dt > 0 else 0.0

    def at(self, times_s: np.ndarray) -> np.ndarray:
        """Values linearly interpolated at ``times_s`` (held at the ends), shape (len(times_s), k)."""
        return np.column_stack([np.interp(times_s, self.time_s, self.values[:, j])
                                for j in range(self.values.shape[1])])

    def window(self, start_s: float, end_s: float) -> Signal:
        keep = (self.time_s >= start_s) & (self.time_s <= end_s)
        return dataclasses.replace(self, time_s=self.time_s[keep], values=self.values[keep])


@dataclass(frozen=True)
class MotorLayout:
    """Where the motors are and which way they spin, in the log's motor order.

    Attributes
    ----------
    names : the source's motor names, in column order (``("M1", "M2", "M3", "M4")``).
    directions : per motor, the sign of its body FLU position (x, y): (+1, -1) is front right.
    spins : per motor, +1 if the propeller turns counter-clockwise seen from above (its drag
        torque on the body is clockwise, -z), -1 if clockwise.
    mixer : the source's name for the layout (``"QUADX"``).
    """

    names: tuple[str, ...]
    directions: tuple[tuple[float, float], ...]
    spins: tuple[int, ...]
    mixer: str

    def __post_init__(self) -> None:
        if not (len(self.names) == len(self.directions) == len(self.spins)):
            raise ValueError("motor layout: names, directions and spins differ in length")

    @property
    def motors(self) -> int:
        return len(self.names)

    def moment_arms(self, motor_x_m: float, motor_y_m: float) -> np.ndarray:
        """(motors, 3) roll, pitch and yaw moment per unit thrust of each motor: (y, −x, −spin·1).

        The yaw column is per unit of κ (drag torque per thrust [m]).
        """
        arms = np.zeros((self.motors, 3))
        for i, ((sx, sy), spin) in enumerate(zip(self.directions, self.spins, strict=True)):
            arms[i] = (sy * motor_y_m, -sx * motor_x_m, -float(spin))
        return arms


@dataclass(frozen=True)
class LogMetadata:
    """What the log says about itself.

    Attributes
    ----------
    firmware : ``"Betaflight"``, ``"PX4"``, ``"Crazyflie"``.
    firmware_version : ``"4.2.9"`` (empty if the log does not say).
    board : the flight controller board.
    craft_name : the pilot's name for the vehicle (may be empty).
    vehicle_type : ``"multirotor"``, or what the source calls a vehicle that is not one.
    parameters : the whole tune or parameter set, names to values as text, as the source wrote them.
    start_time : when the log started, as the source wrote it (may be empty).
    """

    firmware: str
    firmware_version: str = ""
    board: str = ""
    craft_name: str = ""
    vehicle_type: str = "multirotor"
    parameters: Mapping[str, str] = field(default_factory=dict)
    start_time: str = ""

    @property
    def is_multirotor(self) -> bool:
        return self.vehicle_type == "multirotor"


@dataclass(frozen=True)
class FlightLog:
    """One log: its series, its metadata and where it came from.

    Attributes
    ----------
    path : the file it was read from.
    index : which log in the file, from 1.
    logs_in_file : how many logs the file holds.
    source : its format, and with it what wrote it (:attr:`LogFormat.firmware`).
    metadata : firmware, board, craft and the whole tune.
    signals : the series it holds, by channel.
    motor_layout : the mixer's geometry, if the source has one.
    notes : what the reader noticed (skipped frames, fields it did not understand).
    window_s : the part of the log this is [s], when it is one that is named by its window (identification's
        ``--window-s``); None: the log as read, or a part that keeps the log's name.
    """

    path: Path
    index: int
    logs_in_file: int
    source: LogFormat
    metadata: LogMetadata
    signals: Mapping[Channel, Signal]
    motor_layout: MotorLayout | None = None
    notes: tuple[str, ...] = ()
    window_s: tuple[float, float] | None = None

    @property
    def name(self) -> str:
        """``file.bbl#2``: the file and, if it holds several, the log; ``@10-60s`` for a part named by its window."""
        name = f"{self.path.name}#{self.index}" if self.logs_in_file > 1 else self.path.name
        return name if self.window_s is None else f"{name}@{self.window_s[0]:g}-{self.window_s[1]:g}s"

    @property
    def duration_s(self) -> float:
        """From the first to the last sample of any series [s]."""
        starts = [s.time_s[0] for s in self.signals.values() if s.samples]
        ends = [s.time_s[-1] for s in self.signals.values() if s.samples]
        return float(max(ends) - min(starts)) if starts else 0.0

    def has(self, channel: Channel) -> bool:
        return channel in self.signals and self.signals[channel].samples > 0

    def signal(self, channel: Channel, purpose: str = "") -> Signal:
        """The series of ``channel``; ConfigError naming the file if the log has none."""
        if not self.has(channel):
            why = f" ({purpose} needs it)" if purpose else ""
            raise ConfigError(f"{self.path}: log {self.index} has no {channel.description}{why}")
        return self.signals[channel]

    def window(self, start_s: float, end_s: float) -> FlightLog:
        """The same log cut to [start_s, end_s] (times stay relative to the log's start)."""
        return dataclasses.replace(self, signals={c: s.window(start_s, end_s) for c, s in self.signals.items()})
