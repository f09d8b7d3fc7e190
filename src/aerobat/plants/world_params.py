"""The physical world and the lab around a vehicle: settings shared by the arena, RotorPy and Betaflight.

Air (drag, wind, gusts), slow drifts of the vehicle, per-trial disturbances, the motion-capture
system, the flight volume and the supervisor's loop. Each plant's settings file has one table per
section (docs/plants.md gives the sources of the magnitudes); the arena's own sections (its true
vehicle, onboard loop and radio links) stay in :mod:`aerobat.plants.arena.params`.
"""

from __future__ import annotations

from dataclasses import dataclass

from aerobat.core.bounds import Interval, Items, bounded, validate

__all__ = ["SETTLE_HOLD_S", "SETTLE_POSITION_M", "SETTLE_TILT_RAD", "SETTLE_VELOCITY_M_S", "Aerodynamics",
           "Disturbances", "Drift", "MotionCapture", "Supervisor", "Volume"]

_SIDES = Items((Interval(high=0.0, closed="left", unit="m"), Interval(low=0.0, closed="right", unit="m")))
"""A side of the flight volume: (low, high) with low < 0 < high [m]."""
_GAIN = Interval(0.0, 1000.0, closed="right")
"""A supervisor gain, in (0, 1000]."""

# what every plant's settle at the start may ask (the arena's and RotorPy's supervisor, the Betaflight pilot):
# within SETTLE_POSITION_M of the start, slower than SETTLE_VELOCITY_M_S, tilted less than SETTLE_TILT_RAD,
# for SETTLE_HOLD_S (aerobat.plants.lab_kernels.settled)
SETTLE_POSITION_M = Interval(0.001, 1.0, unit="m")
SETTLE_VELOCITY_M_S = Interval(0.001, 1.0, unit="m/s")
SETTLE_TILT_RAD = Interval(0.001, 0.5, unit="rad")
SETTLE_HOLD_S = Interval(0.0, 10.0, unit="s")


@dataclass(frozen=True, kw_only=True)
class Aerodynamics:
    """Body drag, rotor (induced) drag and rotational damping (see docs/plants.md for sources)."""

    enabled: bool = True
    body_drag_n_s2_m2: float = bounded(5e-3, Interval(0.0, 1.0, unit="N s²/m²"))
    rotor_drag_s_m: float = bounded(0.0455, Interval(0.0, 1.0, unit="s/m"))
    rotational_damping_n_m_s: tuple[float, float, float] = bounded(
        (2.0e-3, 2.0e-3, 2.0e-3), Items.each(Interval(0.0, 0.1, unit="N m s/rad"), 3))

    def __post_init__(self) -> None:
        validate(self)

@dataclass(frozen=True, kw_only=True)
class Drift:
    """Slow loss of thrust capacity from trial to trial (battery, propeller wear)."""

    enabled: bool = True
    thrust_loss_per_trial: float = bounded(2e-4, Interval(0.0, 0.01))

    def __post_init__(self) -> None:
        validate(self)

@dataclass(frozen=True, kw_only=True)
class Disturbances:
    """Per-trial random effects (the start-state error comes from the real hover loop).

    Attributes
    ----------
    wind_std_m_s : std of a constant wind per trial, per axis [m/s].
    gust_amplitude_std_m_s, gust_frequency_hz : a sinusoidal gust per trial, random amplitude and phase.
    thrust_gain_jitter : std of a common-mode thrust gain change per trial (battery voltage, temperature).
    motor_gain_jitter : std of an independent per-motor thrust gain change per trial.
    start_velocity_std_m_s, start_tilt_std_rad : hover residual at the trigger beyond what the
        simulated hover loop leaves (prop-wash turbulence, ground effect of a real arena): a random
        velocity per axis and a random roll/pitch error, applied to the true state when the trigger
        is sent. The supervisor does not know them; it measures them like any start error.
    """

    enabled: bool = True
    wind_std_m_s: float = bounded(0.03, Interval(0.0, 5.0, unit="m/s"))
    gust_amplitude_std_m_s: float = bounded(0.03, Interval(0.0, 5.0, unit="m/s"))
    gust_frequency_hz: float = bounded(1.5, Interval(0.0, 50.0, unit="Hz"))
    thrust_gain_jitter: float = bounded(0.0035, Interval(0.0, 0.1))
    motor_gain_jitter: float = bounded(0.001, Interval(0.0, 0.1))
    start_velocity_std_m_s: float = bounded(0.015, Interval(0.0, 1.0, unit="m/s"))
    start_tilt_std_rad: float = bounded(0.003, Interval(0.0, 0.2, unit="rad"))

    def __post_init__(self) -> None:
        validate(self)

@dataclass(frozen=True, kw_only=True)
class MotionCapture:
    """Motion capture: rate, noise and latency (Sect. 10.1: 200 Hz, mm and sub-degree)."""

    rate_hz: float = bounded(200.0, Interval(10.0, 2000.0, unit="Hz"))
    position_noise_m: float = bounded(0.001, Interval(0.0, 0.1, unit="m"))
    attitude_noise_rad: float = bounded(0.002, Interval(0.0, 0.2, unit="rad"))
    latency_s: float = bounded(0.005, Interval(0.0, 0.2, unit="s"))

    def __post_init__(self) -> None:
        validate(self)

@dataclass(frozen=True, kw_only=True)
class Volume:
    """The flyable volume relative to the maneuver start (floor, walls, ceiling) [m]."""

    x_m: tuple[float, float] = bounded((-8.0, 8.0), _SIDES)
    y_m: tuple[float, float] = bounded((-8.0, 8.0), _SIDES)
    z_m: tuple[float, float] = bounded((-2.5, 6.0), _SIDES)

    def __post_init__(self) -> None:
        validate(self)

@dataclass(frozen=True, kw_only=True)
class Supervisor:
    """The offboard supervisor's cascaded PD hover controller and its timing rules."""

    position_gain_per_s2: float = bounded(6.0, _GAIN)
    velocity_gain_per_s: float = bounded(4.0, _GAIN)
    attitude_gain_per_s: float = bounded(10.0, _GAIN)
    yaw_gain_per_s: float = bounded(4.0, _GAIN)
    settle_position_m: float = bounded(0.02, SETTLE_POSITION_M)
    settle_velocity_m_s: float = bounded(0.05, SETTLE_VELOCITY_M_S)
    settle_tilt_rad: float = bounded(0.015, SETTLE_TILT_RAD)
    settle_hold_s: float = bounded(0.1, SETTLE_HOLD_S)
    settle_timeout_s: float = bounded(8.0, Interval(0.1, 120.0, unit="s"))
    trigger_timeout_s: float = bounded(0.15, Interval(0.02, 5.0, unit="s"))
    return_time_s: float = bounded(2.5, Interval(0.1, 60.0, unit="s"))

    def __post_init__(self) -> None:
        validate(self)
