"""The physical world and the lab around a vehicle: settings shared by the arena, RotorPy and Betaflight.

Air (drag, wind, gusts), slow drifts of the vehicle, per-trial disturbances, the motion-capture
system, the flight volume and the supervisor's loop. Each plant's settings file has one table per
section (docs/plants.md gives the sources of the magnitudes); the arena's own sections (its true
vehicle, onboard loop and radio links) stay in :mod:`aerobat.plants.arena.params`.
"""

from __future__ import annotations

from dataclasses import dataclass

from aerobat.config import check_range

__all__ = ["Aerodynamics", "Disturbances", "Drift", "MotionCapture", "Supervisor", "Volume"]


@dataclass(frozen=True, kw_only=True)
class Aerodynamics:
    """Body drag, rotor (induced) drag and rotational damping (see docs/plants.md for sources)."""

    enabled: bool = True
    body_drag_n_s2_m2: float = 5e-3
    rotor_drag_s_m: float = 0.0455
    rotational_damping_n_m_s: tuple[float, float, float] = (2.0e-3, 2.0e-3, 2.0e-3)

    def __post_init__(self) -> None:
        check_range("body_drag_n_s2_m2", self.body_drag_n_s2_m2, low=0.0, high=1.0, unit="N s²/m²")
        check_range("rotor_drag_s_m", self.rotor_drag_s_m, low=0.0, high=1.0, unit="s/m")
        for i, c in enumerate(self.rotational_damping_n_m_s):
            check_range(f"rotational_damping_n_m_s[{i}]", c, low=0.0, high=0.1, unit="N m s/rad")

@dataclass(frozen=True, kw_only=True)
class Drift:
    """Slow loss of thrust capacity from trial to trial (battery, propeller wear)."""

    enabled: bool = True
    thrust_loss_per_trial: float = 2e-4

    def __post_init__(self) -> None:
        check_range("thrust_loss_per_trial", self.thrust_loss_per_trial, low=0.0, high=0.01)

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
    wind_std_m_s: float = 0.03
    gust_amplitude_std_m_s: float = 0.03
    gust_frequency_hz: float = 1.5
    thrust_gain_jitter: float = 0.0035
    motor_gain_jitter: float = 0.001
    start_velocity_std_m_s: float = 0.015
    start_tilt_std_rad: float = 0.003

    def __post_init__(self) -> None:
        check_range("wind_std_m_s", self.wind_std_m_s, low=0.0, high=5.0, unit="m/s")
        check_range("gust_amplitude_std_m_s", self.gust_amplitude_std_m_s, low=0.0, high=5.0, unit="m/s")
        check_range("gust_frequency_hz", self.gust_frequency_hz, low=0.0, high=50.0, unit="Hz")
        check_range("thrust_gain_jitter", self.thrust_gain_jitter, low=0.0, high=0.1)
        check_range("motor_gain_jitter", self.motor_gain_jitter, low=0.0, high=0.1)
        check_range("start_velocity_std_m_s", self.start_velocity_std_m_s, low=0.0, high=1.0, unit="m/s")
        check_range("start_tilt_std_rad", self.start_tilt_std_rad, low=0.0, high=0.2, unit="rad")

@dataclass(frozen=True, kw_only=True)
class MotionCapture:
    """Motion capture: rate, noise and latency (Sect. 10.1: 200 Hz, mm and sub-degree)."""

    rate_hz: float = 200.0
    position_noise_m: float = 0.001
    attitude_noise_rad: float = 0.002
    latency_s: float = 0.005

    def __post_init__(self) -> None:
        check_range("rate_hz", self.rate_hz, low=10.0, high=2000.0, unit="Hz")
        check_range("position_noise_m", self.position_noise_m, low=0.0, high=0.1, unit="m")
        check_range("attitude_noise_rad", self.attitude_noise_rad, low=0.0, high=0.2, unit="rad")
        check_range("latency_s", self.latency_s, low=0.0, high=0.2, unit="s")

@dataclass(frozen=True, kw_only=True)
class Volume:
    """The flyable volume relative to the maneuver start (floor, walls, ceiling) [m]."""

    x_m: tuple[float, float] = (-8.0, 8.0)
    y_m: tuple[float, float] = (-8.0, 8.0)
    z_m: tuple[float, float] = (-2.5, 6.0)

    def __post_init__(self) -> None:
        for name in ("x_m", "y_m", "z_m"):
            lo, hi = getattr(self, name)
            check_range(f"{name}[0]", lo, high=0.0, high_inclusive=False, unit="m")
            check_range(f"{name}[1]", hi, low=0.0, low_inclusive=False, unit="m")

@dataclass(frozen=True, kw_only=True)
class Supervisor:
    """The offboard supervisor's cascaded PD hover controller and its timing rules."""

    position_gain_per_s2: float = 6.0
    velocity_gain_per_s: float = 4.0
    attitude_gain_per_s: float = 10.0
    yaw_gain_per_s: float = 4.0
    settle_position_m: float = 0.02
    settle_velocity_m_s: float = 0.05
    settle_tilt_rad: float = 0.015
    settle_hold_s: float = 0.1
    settle_timeout_s: float = 8.0
    trigger_timeout_s: float = 0.15
    return_time_s: float = 2.5

    def __post_init__(self) -> None:
        for name in ("position_gain_per_s2", "velocity_gain_per_s", "attitude_gain_per_s", "yaw_gain_per_s"):
            check_range(name, getattr(self, name), low=0.0, high=1000.0, low_inclusive=False)
        check_range("settle_position_m", self.settle_position_m, low=0.001, high=1.0, unit="m")
        check_range("settle_velocity_m_s", self.settle_velocity_m_s, low=0.001, high=1.0, unit="m/s")
        check_range("settle_tilt_rad", self.settle_tilt_rad, low=0.001, high=0.5, unit="rad")
        check_range("settle_hold_s", self.settle_hold_s, low=0.0, high=10.0, unit="s")
        check_range("settle_timeout_s", self.settle_timeout_s, low=0.1, high=120.0, unit="s")
        check_range("trigger_timeout_s", self.trigger_timeout_s, low=0.02, high=5.0, unit="s")
        check_range("return_time_s", self.return_time_s, low=0.1, high=60.0, unit="s")
