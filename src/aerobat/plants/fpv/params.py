"""Settings of the Betaflight plant: the physical vehicle and the arena around the firmware.

One TOML file (``--betaflight FILE.toml``), one table per section, any field may be
omitted. Where the world around the vehicle is the same as the arena's, its sections are reused
(:class:`~aerobat.plants.world_params.Aerodynamics`, ``Drift``, ``Disturbances``,
``MotionCapture``, ``Volume``) with defaults for a 5-inch racer; the rest is the
Betaflight plant's own. Sources and reasons: ``docs/plants.md`` (Betaflight).

The firmware's own configuration (PIDs, rates, modes) is not here: it is the
versioned ``settings.toml`` applied through Betaflight's CLI (:mod:`aerobat.firmware.betaflight.settings`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomli_w

from aerobat.config import (
    as_path,
    check_type,
    dataclass_from_table,
    dataclass_to_table,
    read_toml,
    replace_sections,
    write_file,
)
from aerobat.core.bounds import Interval, Items, OneOf, bounded, validate
from aerobat.firmware.betaflight.packets import Exchange, SpinPolicy
from aerobat.firmware.betaflight.tune import Tune
from aerobat.plants.world_params import (
    SETTLE_HOLD_S,
    SETTLE_POSITION_M,
    SETTLE_TILT_RAD,
    SETTLE_VELOCITY_M_S,
    Aerodynamics,
    Disturbances,
    Drift,
    MotionCapture,
    Volume,
)
from aerobat.quadrotor.xframe import Airframe

__all__ = [
    "GYRO_RATES_HZ",
    "Airframe",
    "BetaflightParams",
    "Firmware",
    "Pilot",
    "Radio",
    "Sensors",
    "instance_cores",
    "load_betaflight",
    "params_to_table",
    "save_betaflight",
]

GYRO_RATES_HZ = (1000, 2000, 4000, 8000)
"""The virtual gyro rates the SITL runs at [Hz] (:attr:`Firmware.gyro_rate_hz`)."""

_XYZ = "three numbers (x, y, z)"
_MASS = Interval(0.05, 20.0, unit="kg")
_GAIN = Interval(0.0, 100.0, closed="right")
"""A position-loop gain of the pilot, in (0, 100]."""


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

    gyro_noise_rad_s: float = bounded(0.005, Interval(0.0, 0.5, unit="rad/s"))
    gyro_scale_error: tuple[float, float, float] = bounded(
        (0.01, -0.008, 0.005), Items.each(Interval(-0.2, 0.2), 3, _XYZ))
    gyro_bias_rad_s: tuple[float, float, float] = bounded(
        (0.004, -0.003, 0.002), Items.each(Interval(-0.5, 0.5, unit="rad/s"), 3, _XYZ))
    accel_noise_m_s2: float = bounded(0.05, Interval(0.0, 5.0, unit="m/s²"))
    attitude_error_rad: tuple[float, float] = bounded(
        (0.004, -0.003), Items.each(Interval(-0.1, 0.1, unit="rad"), 2, "two numbers (roll, pitch)"))

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True, kw_only=True)
class Radio:
    """The RC link from the ground to the receiver: frame rate, loss and latency.

    250 Hz is a common ExpressLRS packet rate. A lost frame simply does not arrive (the
    firmware keeps the last one, as with a real receiver); a radio that stops altogether is
    tested separately (out-of-range channels, Betaflight's failsafe).
    """

    rate_hz: float = bounded(250.0, Interval(25.0, 1000.0, unit="Hz"))
    drop_probability: float = bounded(0.02, Interval(0.0, 0.5))
    latency_s: float = bounded(0.004, Interval(0.0, 0.1, unit="s"))

    def __post_init__(self) -> None:
        validate(self)


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

    position_gain_per_s2: float = bounded(4.0, _GAIN)
    velocity_gain_per_s: float = bounded(3.5, _GAIN)
    integral_gain_per_s3: float = bounded(2.0, Interval(0.0, 100.0))
    max_tilt_deg: float = bounded(35.0, Interval(1.0, 60.0, unit="deg"))
    max_climb_m_s: float = bounded(2.5, Interval(0.1, 10.0, unit="m/s"))
    yaw_gain_per_s: float = bounded(3.0, _GAIN)
    calibration_s: float = bounded(1.5, Interval(1.3, 10.0, unit="s"))
    settle_position_m: float = bounded(0.02, SETTLE_POSITION_M)
    settle_velocity_m_s: float = bounded(0.05, SETTLE_VELOCITY_M_S)
    settle_tilt_rad: float = bounded(0.03, SETTLE_TILT_RAD)
    settle_hold_s: float = bounded(0.1, SETTLE_HOLD_S)
    settle_timeout_s: float = bounded(10.0, Interval(1.0, 120.0, unit="s"))
    hover_s: float = bounded(0.5, Interval(0.0, 60.0, unit="s"))
    return_time_s: float = bounded(2.5, Interval(0.5, 60.0, unit="s"))
    landing_timeout_s: float = bounded(6.0, Interval(1.0, 60.0, unit="s"))
    vehicle_mass_kg: float = bounded(0.752, _MASS)

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True, kw_only=True)
class Firmware:
    """How the SITL runs: its virtual gyro rate (= the state packet rate) and the watchdog.

    Attributes
    ----------
    gyro_rate_hz : 8000 like a real F7/H7 flight controller's gyro loop; 4000 runs twice as
        fast in wall time (docs/plants.md compares both).
    step_timeout_s : wall time a lockstep step may wait for the firmware before it is declared
        hung (killed; the trial is lost, the next one starts a fresh firmware).
    exchange : how the per-step packets travel: ``"shm"`` (shared memory,
        :mod:`aerobat.firmware.betaflight.shm`; 50-60× real time for the 3D triple flip on this
        project's 2-core machine) or ``"udp"`` (loopback sockets; 5-6×). The same flight bit for bit.
    spin_us : over shared memory, the longest the firmware and the driver each busy-wait for
        the other before sleeping on a futex (adaptive below it). With it an instance keeps two
        cores busy (:func:`instance_cores`: studies run ``cpu_count // 2`` at once); 0 sleeps at
        once, for as many instances as cores (docs/performance.md, issue 27).
    spin : whether the driver spins (up to ``spin_us``): ``"always"`` on every wait (the default);
        ``"measured"`` spins or sleeps at once, whichever its 25 ms epochs measure stepping faster.
        Measured at load 0, 1 and 2, the fixed spin is the faster default here (issue 46,
        docs/performance.md, "Betaflight on a shared machine").
    pin_cores : over spinning shared memory, hold a core each for the driver's thread and the
        firmware during a flight (:mod:`aerobat.plants.betaflight.cores`: a free pair of the
        allowed cores, none pinned when every pair is taken): beside a busy process the scheduler
        otherwise puts the two on one core, where they spin against each other (15× real time
        against 60× pinned).
    """

    gyro_rate_hz: int = bounded(8000, OneOf(GYRO_RATES_HZ, unit="Hz"))
    step_timeout_s: float = bounded(2.0, Interval(0.05, 60.0, unit="s"))
    exchange: Exchange = bounded(Exchange.SHM, OneOf(Exchange))
    spin_us: float = bounded(20.0, Interval(0.0, 1000.0, unit="µs"))
    spin: SpinPolicy = bounded(SpinPolicy.ALWAYS, OneOf(SpinPolicy))
    pin_cores: bool = True

    def __post_init__(self) -> None:
        validate(self)


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
    """A real quad's configuration applied on top of ``settings.toml``
    (:func:`aerobat.firmware.betaflight.tune.load_tune`); None: none."""

    def replace(self, **sections: Any) -> BetaflightParams:
        """Copy with whole sections or ``section__field=value`` changes."""
        changed: BetaflightParams = replace_sections(self, sections)
        return changed


def instance_cores(params: BetaflightParams) -> int:
    """The cores one flying instance keeps busy: 2 over spinning shared memory, else 1.

    With ``exchange = "shm"`` and ``spin_us > 0`` the firmware and the driver each wait for the
    other spinning on a core of their own; two such instances on two cores step fewer times a
    second together (180,000-200,000) than one alone (450,000-590,000), so a study runs
    ``cpu_count // 2`` of them (docs/performance.md, issue 27).
    """
    fw = params.firmware
    return 2 if fw.exchange is Exchange.SHM and fw.spin_us > 0 else 1


def load_betaflight(path: str | Path) -> BetaflightParams:
    """Read a Betaflight plant TOML file; :class:`~aerobat.errors.ConfigError` names the file, field and range."""
    path = as_path(path)
    return dataclass_from_table(BetaflightParams, read_toml(path), source=str(path))


def params_to_table(params: BetaflightParams) -> dict[str, Any]:
    """The settings' stored form (the plant spec's ``settings``); the tune only when there is one."""
    table = dataclass_to_table(params)
    if not params.airframe.props_out:  # props in, as every stored form before props_out existed
        table["airframe"].pop("props_out", None)
    for name in ("battery_reference_v", "battery_rest_v"):  # TOML has no null; stored forms before them had none
        if getattr(params.airframe, name) is None:
            table["airframe"].pop(name, None)
    if params.airframe.battery_sag_v == 0.0:  # no sag: as every stored form before the battery model
        table["airframe"].pop("battery_sag_v", None)
    if params.tune is None:
        del table["tune"]
    else:
        table["tune"]["lines"] = [list(entry) for entry in params.tune.lines]
        if not params.tune.changes:  # single --set changes (a what-if replay); stored forms before them had none
            table["tune"].pop("changes", None)
    return table


def save_betaflight(params: BetaflightParams, path: str | Path) -> None:
    check_type("params", params, BetaflightParams, "BetaflightParams")
    write_file(path, tomli_w.dumps(params_to_table(params)))
