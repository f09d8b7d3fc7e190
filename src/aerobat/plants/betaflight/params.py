"""Settings of the Betaflight plant: the physical vehicle and the arena around the firmware.

One TOML file (``--betaflight FILE.toml``), one table per section, any field may be
omitted. Where the world around the vehicle is the same as the arena's, its sections are reused
(:class:`~aerobat.plants.world_params.Aerodynamics`, ``Drift``, ``Disturbances``,
``MotionCapture``, ``Volume``) with defaults for a 5-inch racer; the rest is the
Betaflight plant's own. Sources and reasons: ``docs/plants.md`` (Betaflight).

The firmware's own configuration (PIDs, rates, modes) is not here: it is the
versioned ``settings.toml`` applied through Betaflight's CLI (:mod:`.firmware_settings`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomli_w

from aerobat.config import (
    as_path,
    check_range,
    check_type,
    dataclass_from_table,
    dataclass_to_table,
    read_toml,
    replace_sections,
    write_file,
)
from aerobat.errors import ConfigError
from aerobat.plants.betaflight.packets import Exchange
from aerobat.plants.betaflight.tune import Tune
from aerobat.plants.world_params import Aerodynamics, Disturbances, Drift, MotionCapture, Volume

__all__ = [
    "Airframe",
    "BetaflightParams",
    "Firmware",
    "Pilot",
    "Radio",
    "Sensors",
    "load_betaflight",
    "params_to_table",
    "save_betaflight",
]


@dataclass(frozen=True, kw_only=True)
class Airframe:
    """The physical X-frame vehicle (defaults: the 5-inch racer of ``vehicles/fpv5.toml``).

    Attributes
    ----------
    mass_kg, inertia_kg_m2 : rigid body [kg], principal inertia (x, y, z) [kg m²].
    motor_x_m, motor_y_m : motor distance from the centre along body x (forward) and y [m];
        motors sit at (±x, ±y) in Betaflight's QUADX order.
    com_offset_m : centre of mass relative to the frame centre, body FLU [m].
    thrust_max_n : per-rotor thrust at motor command 1.
    curve_min_speed_ratio, curve_shape : the steady-state thrust curve
        ``f(u) = f_max [(1 − r) √(k u² + (1 − k) u) + r]²`` (r, k) for motor command u ∈ (0, 1];
        a stopped motor (u = 0, disarmed) gives no thrust.
    motor_tau_up_s, motor_tau_down_s : first-order thrust time constants, rising and falling [s].
    thrust_gains : per-motor thrust multipliers, Betaflight packet order (motor and prop spread).
    kappa_m : rotor drag-torque to thrust ratio [m].
    rotor_inertia_kg_m2 : inertia of one rotor (propeller and motor bell) about its axis; its
        reaction torque when the rotor speeds up or slows down acts on yaw.
    thrust_coefficient_n_s2 : k in f = k Ω² (relates thrust to rotor speed for that torque).
    output_delay_s : time from the firmware's motor output to the ESC acting on it [s]
        (DShot frame and ESC processing; lockstep computes the loop in zero time).
    """

    mass_kg: float = 0.752
    inertia_kg_m2: tuple[float, float, float] = (2.5e-3, 2.1e-3, 4.3e-3)
    motor_x_m: float = 0.075
    motor_y_m: float = 0.10
    com_offset_m: tuple[float, float, float] = (0.003, -0.002, 0.0)
    thrust_max_n: float = 8.5
    curve_min_speed_ratio: float = 341.75 / 3100.0
    curve_shape: float = 0.5
    motor_tau_up_s: float = 0.033
    motor_tau_down_s: float = 0.033
    thrust_gains: tuple[float, float, float, float] = (1.00, 0.98, 1.01, 0.97)
    kappa_m: float = 0.022
    rotor_inertia_kg_m2: float = 8e-6
    thrust_coefficient_n_s2: float = 1.562522e-6
    output_delay_s: float = 125e-6

    def __post_init__(self) -> None:
        check_range("mass_kg", self.mass_kg, low=0.05, high=20.0, unit="kg")
        for i, value in enumerate(self.inertia_kg_m2):
            check_range(f"inertia_kg_m2[{i}]", value, low=1e-6, high=10.0, unit="kg m²")
        check_range("motor_x_m", self.motor_x_m, low=0.01, high=2.0, unit="m")
        check_range("motor_y_m", self.motor_y_m, low=0.01, high=2.0, unit="m")
        for i, value in enumerate(self.com_offset_m):
            check_range(f"com_offset_m[{i}]", value, low=-0.05, high=0.05, unit="m")
        check_range("thrust_max_n", self.thrust_max_n, low=0.1, high=1000.0, unit="N")
        check_range("curve_min_speed_ratio", self.curve_min_speed_ratio, low=0.0, high=0.9)
        check_range("curve_shape", self.curve_shape, low=0.0, high=1.0)
        check_range("motor_tau_up_s", self.motor_tau_up_s, low=1e-3, high=1.0, unit="s")
        check_range("motor_tau_down_s", self.motor_tau_down_s, low=1e-3, high=1.0, unit="s")
        for i, value in enumerate(self.thrust_gains):
            check_range(f"thrust_gains[{i}]", value, low=0.5, high=1.5)
        check_range("kappa_m", self.kappa_m, low=1e-4, high=0.5, unit="m")
        check_range("rotor_inertia_kg_m2", self.rotor_inertia_kg_m2, low=0.0, high=1e-2, unit="kg m²")
        check_range("thrust_coefficient_n_s2", self.thrust_coefficient_n_s2, low=1e-9, high=1e-2, unit="N s²")
        check_range("output_delay_s", self.output_delay_s, low=0.0, high=0.05, unit="s")

    def thrust_n(self, command: float) -> float:
        """Steady-state thrust of one rotor at motor command ``command`` (0 = stopped)."""
        if command <= 0.0:
            return 0.0
        u = min(command, 1.0)
        r, k = self.curve_min_speed_ratio, self.curve_shape
        return self.thrust_max_n * ((1.0 - r) * math.sqrt(k * u * u + (1.0 - k) * u) + r) ** 2

    def command_for_thrust(self, thrust_n: float) -> float:
        """Inverse of :meth:`thrust_n` on (0, 1] (clamped to the curve's range)."""
        r, k = self.curve_min_speed_ratio, self.curve_shape
        s = (math.sqrt(max(thrust_n, 0.0) / self.thrust_max_n) - r) / (1.0 - r)
        s = min(max(s, 0.0), 1.0)
        if k == 0.0:
            return s * s
        # k u² + (1 − k) u − s² = 0
        return min(((k - 1.0) + math.sqrt((1.0 - k) ** 2 + 4.0 * k * s * s)) / (2.0 * k), 1.0)


@dataclass(frozen=True, kw_only=True)
class Sensors:
    """What the firmware's gyro and accelerometer read (its attitude comes from the state packet).

    Attributes
    ----------
    gyro_noise_rad_s : white noise per sample and axis [rad/s].
    gyro_scale_error : per-axis scale error (body FLU).
    gyro_bias_rad_s : constant bias per axis [rad/s] (Betaflight calibrates it away at boot).
    accel_noise_m_s2 : white noise per sample and axis [m/s²].
    attitude_error_rad : constant roll and pitch error of the attitude the firmware flies on
        (an accelerometer mounted slightly off level).
    """

    gyro_noise_rad_s: float = 0.005
    gyro_scale_error: tuple[float, float, float] = (0.01, -0.008, 0.005)
    gyro_bias_rad_s: tuple[float, float, float] = (0.004, -0.003, 0.002)
    accel_noise_m_s2: float = 0.05
    attitude_error_rad: tuple[float, float] = (0.004, -0.003)

    def __post_init__(self) -> None:
        check_range("gyro_noise_rad_s", self.gyro_noise_rad_s, low=0.0, high=0.5, unit="rad/s")
        for i, value in enumerate(self.gyro_scale_error):
            check_range(f"gyro_scale_error[{i}]", value, low=-0.2, high=0.2)
        for i, value in enumerate(self.gyro_bias_rad_s):
            check_range(f"gyro_bias_rad_s[{i}]", value, low=-0.5, high=0.5, unit="rad/s")
        check_range("accel_noise_m_s2", self.accel_noise_m_s2, low=0.0, high=5.0, unit="m/s²")
        for i, value in enumerate(self.attitude_error_rad):
            check_range(f"attitude_error_rad[{i}]", value, low=-0.1, high=0.1, unit="rad")


@dataclass(frozen=True, kw_only=True)
class Radio:
    """The RC link from the ground to the receiver: frame rate, loss and latency.

    250 Hz is a common ExpressLRS packet rate. A lost frame simply does not arrive (the
    firmware keeps the last one, as with a real receiver); a radio that stops altogether is
    tested separately (out-of-range channels, Betaflight's failsafe).
    """

    rate_hz: float = 250.0
    drop_probability: float = 0.02
    latency_s: float = 0.004

    def __post_init__(self) -> None:
        check_range("rate_hz", self.rate_hz, low=25.0, high=1000.0, unit="Hz")
        check_range("drop_probability", self.drop_probability, low=0.0, high=0.5)
        check_range("latency_s", self.latency_s, low=0.0, high=0.1, unit="s")


@dataclass(frozen=True, kw_only=True)
class Pilot:
    """The offboard pilot: a position loop flying ANGLE-mode sticks, and the trial's timing.

    Attributes
    ----------
    position_gain_per_s2, velocity_gain_per_s, integral_gain_per_s3 : the position PID on
        motion-capture estimates, giving a desired acceleration [1/s², 1/s, 1/s³].
    max_tilt_deg : largest tilt the position loop asks for [deg].
    max_climb_m_s : vertical speed limit of the position loop [m/s] (take-off and landing).
    yaw_gain_per_s : heading hold through the yaw stick (yaw stays a rate in ANGLE mode).
    calibration_s : time on the ground before arming; Betaflight calibrates its gyro first.
    settle_position_m, settle_velocity_m_s, settle_tilt_rad, settle_hold_s, settle_timeout_s :
        the start is reached when the estimate stays within these for ``settle_hold_s``.
    hover_s : hover at the start for at least this long before the trigger [s].
    return_time_s : closed-loop recovery and return after the maneuver [s].
    landing_timeout_s : time allowed to land and disarm [s].
    vehicle_mass_kg : the mass the pilot believes (the published one): collective → throttle uses
        it with the airframe's published thrust curve, whatever the true airframe weighs.
    """

    position_gain_per_s2: float = 4.0
    velocity_gain_per_s: float = 3.5
    integral_gain_per_s3: float = 2.0
    max_tilt_deg: float = 35.0
    max_climb_m_s: float = 2.5
    yaw_gain_per_s: float = 3.0
    calibration_s: float = 1.5
    settle_position_m: float = 0.02
    settle_velocity_m_s: float = 0.05
    settle_tilt_rad: float = 0.03
    settle_hold_s: float = 0.1
    settle_timeout_s: float = 10.0
    hover_s: float = 0.5
    return_time_s: float = 2.5
    landing_timeout_s: float = 6.0
    vehicle_mass_kg: float = 0.752

    def __post_init__(self) -> None:
        check_range("vehicle_mass_kg", self.vehicle_mass_kg, low=0.05, high=20.0, unit="kg")
        for name in ("position_gain_per_s2", "velocity_gain_per_s", "yaw_gain_per_s"):
            check_range(name, getattr(self, name), low=0.0, high=100.0, low_inclusive=False)
        check_range("integral_gain_per_s3", self.integral_gain_per_s3, low=0.0, high=100.0)
        check_range("max_tilt_deg", self.max_tilt_deg, low=1.0, high=60.0, unit="deg")
        check_range("max_climb_m_s", self.max_climb_m_s, low=0.1, high=10.0, unit="m/s")
        check_range("calibration_s", self.calibration_s, low=1.3, high=10.0, unit="s")
        check_range("settle_position_m", self.settle_position_m, low=0.001, high=1.0, unit="m")
        check_range("settle_velocity_m_s", self.settle_velocity_m_s, low=0.001, high=1.0, unit="m/s")
        check_range("settle_tilt_rad", self.settle_tilt_rad, low=0.001, high=0.5, unit="rad")
        check_range("settle_hold_s", self.settle_hold_s, low=0.0, high=10.0, unit="s")
        check_range("settle_timeout_s", self.settle_timeout_s, low=1.0, high=120.0, unit="s")
        check_range("hover_s", self.hover_s, low=0.0, high=60.0, unit="s")
        check_range("return_time_s", self.return_time_s, low=0.5, high=60.0, unit="s")
        check_range("landing_timeout_s", self.landing_timeout_s, low=1.0, high=60.0, unit="s")


@dataclass(frozen=True, kw_only=True)
class Firmware:
    """How the SITL runs: its virtual gyro rate (= the state packet rate) and the watchdog.

    Attributes
    ----------
    gyro_rate_hz : 8000 like a real F7/H7 flight controller's gyro loop; 4000 runs twice as
        fast in wall time (docs/plants.md compares both).
    step_timeout_s : wall time a lockstep step may wait for the firmware before it is declared
        hung (killed; the trial is lost, the next one starts a fresh firmware).
    exchange : how the per-step packets travel: ``"udp"`` (loopback sockets) or ``"shm"``
        (shared memory, :mod:`aerobat.plants.betaflight.shm`); the same flight bit for bit.
    """

    gyro_rate_hz: int = 8000
    step_timeout_s: float = 2.0
    exchange: Exchange = Exchange.UDP

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "exchange", Exchange(self.exchange))
        except ValueError:
            raise ConfigError(f"exchange = {self.exchange!r}: allowed 'udp' or 'shm'") from None
        if self.gyro_rate_hz not in (1000, 2000, 4000, 8000):
            raise ConfigError(f"gyro_rate_hz = {self.gyro_rate_hz}: allowed 1000, 2000, 4000 or 8000 (Hz)")
        check_range("step_timeout_s", self.step_timeout_s, low=0.05, high=60.0, unit="s")


def _aerodynamics() -> Aerodynamics:
    # blackbird.yaml: linear drag 0.26 N/(m/s) in the rotor plane at hover thrust m g = 7.38 N
    # -> rotor drag 0.26 / 7.38 = 0.035 s/m; quadratic drag 0.015 N/(m/s)²; damping [A]
    return Aerodynamics(body_drag_n_s2_m2=0.015, rotor_drag_s_m=0.035,
                        rotational_damping_n_m_s=(5e-4, 5e-4, 5e-4))


def _disturbances() -> Disturbances:
    # the real hover loop leaves its own start error: no extra residual at the trigger
    return Disturbances(start_velocity_std_m_s=0.0, start_tilt_std_rad=0.0)


@dataclass(frozen=True, kw_only=True)
class BetaflightParams:
    """Everything about the Betaflight plant except the firmware's own settings."""

    airframe: Airframe = field(default_factory=Airframe)
    aerodynamics: Aerodynamics = field(default_factory=_aerodynamics)
    sensors: Sensors = field(default_factory=Sensors)
    drift: Drift = field(default_factory=Drift)
    disturbances: Disturbances = field(default_factory=_disturbances)
    motion_capture: MotionCapture = field(default_factory=MotionCapture)
    radio: Radio = field(default_factory=Radio)
    volume: Volume = field(default_factory=Volume)
    pilot: Pilot = field(default_factory=Pilot)
    firmware: Firmware = field(default_factory=Firmware)
    tune: Tune | None = None
    """A real quad's configuration applied on top of ``settings.toml`` (:func:`.tune.load_tune`); None: none."""

    def replace(self, **sections: Any) -> BetaflightParams:
        """Copy with whole sections or ``section__field=value`` changes."""
        changed: BetaflightParams = replace_sections(self, sections)
        return changed


def load_betaflight(path: str | Path) -> BetaflightParams:
    """Read a Betaflight plant TOML file; :class:`ConfigError` names the file, field and range."""
    path = as_path(path)
    return dataclass_from_table(BetaflightParams, read_toml(path), source=str(path))


def params_to_table(params: BetaflightParams) -> dict[str, Any]:
    """The settings' stored form (the plant spec's ``settings``); the tune only when there is one."""
    table = dataclass_to_table(params)
    if params.tune is None:
        del table["tune"]
    else:
        table["tune"]["lines"] = [list(entry) for entry in params.tune.lines]
    return table


def save_betaflight(params: BetaflightParams, path: str | Path) -> None:
    check_type("params", params, BetaflightParams, "BetaflightParams")
    write_file(path, tomli_w.dumps(params_to_table(params)))
