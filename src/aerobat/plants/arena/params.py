"""Arena configuration: every way the simulated testbed differs from the nominal model.

Each effect has its own table in the arena TOML file and an ``enabled`` switch;
:meth:`ArenaParams.ideal` turns everything off (then the arena flies the
nominal model, sampled at 800 Hz, with perfect sensing). Sources for the
aerodynamic magnitudes are listed in ``docs/plants.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomli_w

from aerobat.config import (
    ConfigError,
    as_path,
    check_range,
    check_type,
    dataclass_from_table,
    dataclass_to_table,
    read_toml,
    replace_sections,
    write_file,
)
from aerobat.plants.world_params import Aerodynamics, Disturbances, Drift, MotionCapture, Supervisor, Volume

__all__ = [
    "Aerodynamics",
    "ArenaParams",
    "Disturbances",
    "Drift",
    "Links",
    "MotionCapture",
    "Onboard",
    "Supervisor",
    "TrueVehicle",
    "Volume",
    "load_arena",
    "save_arena",
]


@dataclass(frozen=True, kw_only=True)
class TrueVehicle:
    """The real vehicle's constants relative to the nominal Table 1 model."""

    enabled: bool = True
    mass_scale: float = 1.03
    inertia_scale: tuple[float, float, float] = (1.12, 1.12, 1.20)
    drag_constant_scale: float = 1.15
    motor_rate_up_per_s: float = 70.0
    motor_rate_down_per_s: float = 45.0
    thrust_gains: tuple[float, float, float, float] = (1.00, 0.97, 1.02, 0.95)
    com_offset_m: tuple[float, float, float] = (0.005, -0.003, 0.0)

    def __post_init__(self) -> None:
        check_range("mass_scale", self.mass_scale, low=0.5, high=2.0)
        for i, s in enumerate(self.inertia_scale):
            check_range(f"inertia_scale[{i}]", s, low=0.2, high=5.0)
        check_range("drag_constant_scale", self.drag_constant_scale, low=0.2, high=5.0)
        check_range("motor_rate_up_per_s", self.motor_rate_up_per_s, low=1.0, high=1e4, unit="1/s")
        check_range("motor_rate_down_per_s", self.motor_rate_down_per_s, low=1.0, high=1e4, unit="1/s")
        for i, g in enumerate(self.thrust_gains):
            check_range(f"thrust_gains[{i}]", g, low=0.5, high=1.5)
        for i, c in enumerate(self.com_offset_m):
            check_range(f"com_offset_m[{i}]", c, low=-0.05, high=0.05, unit="m")


@dataclass(frozen=True, kw_only=True)
class Onboard:
    """The onboard loop: rate, gyro latency and gyro errors."""

    rate_hz: float = 800.0
    gyro_latency_samples: int = 1
    gyro_scale_error: tuple[float, float, float] = (0.01, -0.008, 0.005)
    gyro_bias_rad_s: tuple[float, float, float] = (0.004, -0.003, 0.002)

    def __post_init__(self) -> None:
        check_range("rate_hz", self.rate_hz, low=50.0, high=10000.0, unit="Hz")
        check_range("gyro_latency_samples", self.gyro_latency_samples, low=0, high=10)
        for i, s in enumerate(self.gyro_scale_error):
            check_range(f"gyro_scale_error[{i}]", s, low=-0.2, high=0.2)
        for i, b in enumerate(self.gyro_bias_rad_s):
            check_range(f"gyro_bias_rad_s[{i}]", b, low=-0.5, high=0.5, unit="rad/s")


@dataclass(frozen=True, kw_only=True)
class Links:
    """Radio links: 70 Hz command broadcast with drops; acknowledged program upload."""

    command_rate_hz: float = 70.0
    command_drop_probability: float = 0.05
    command_latency_s: float = 0.010
    upload_drop_probability: float = 0.05
    upload_timeout_s: float = 0.02
    upload_max_attempts: int = 10
    upload_switches_per_packet: int = 8
    upload_reference_samples_per_packet: int = 2

    def __post_init__(self) -> None:
        check_range("command_rate_hz", self.command_rate_hz, low=5.0, high=1000.0, unit="Hz")
        check_range("command_drop_probability", self.command_drop_probability, low=0.0, high=0.95)
        check_range("command_latency_s", self.command_latency_s, low=0.0, high=0.2, unit="s")
        check_range("upload_drop_probability", self.upload_drop_probability, low=0.0, high=0.95)
        check_range("upload_timeout_s", self.upload_timeout_s, low=0.001, high=1.0, unit="s")
        check_range("upload_max_attempts", self.upload_max_attempts, low=1, high=1000)
        check_range("upload_switches_per_packet", self.upload_switches_per_packet, low=1, high=1000)
        check_range("upload_reference_samples_per_packet", self.upload_reference_samples_per_packet, low=1,
                    high=1000)


@dataclass(frozen=True, kw_only=True)
class ArenaParams:
    """Everything about the simulated flying-machine arena."""

    true_vehicle: TrueVehicle = field(default_factory=TrueVehicle)
    aerodynamics: Aerodynamics = field(default_factory=Aerodynamics)
    onboard: Onboard = field(default_factory=Onboard)
    drift: Drift = field(default_factory=Drift)
    disturbances: Disturbances = field(default_factory=Disturbances)
    motion_capture: MotionCapture = field(default_factory=MotionCapture)
    links: Links = field(default_factory=Links)
    volume: Volume = field(default_factory=Volume)
    supervisor: Supervisor = field(default_factory=Supervisor)

    def __post_init__(self) -> None:
        sections = {"true_vehicle": TrueVehicle, "aerodynamics": Aerodynamics, "onboard": Onboard, "drift": Drift,
                    "disturbances": Disturbances, "motion_capture": MotionCapture, "links": Links, "volume": Volume,
                    "supervisor": Supervisor}
        for name, kind in sections.items():
            check_type(name, getattr(self, name), kind, f"a {kind.__name__}")
        # the radio delivers a command only if it arrives before the next one is sent (a newer
        # packet supersedes one still in flight): a longer latency would silently cut the link
        tick_s = 1.0 / self.onboard.rate_hz
        period_ticks = math.floor(1.0 / (self.links.command_rate_hz * tick_s) + 1e-9)
        delay_ticks = math.ceil(self.links.command_latency_s / tick_s - 1e-9)
        if delay_ticks > period_ticks:
            raise ConfigError(
                f"links.command_latency_s = {self.links.command_latency_s:g} s: allowed at most "
                f"{period_ticks * tick_s:.5g} s ({period_ticks} onboard ticks) with links.command_rate_hz = "
                f"{self.links.command_rate_hz:g} and onboard.rate_hz = {self.onboard.rate_hz:g}: the arena's radio "
                f"delivers a command only before the next one is sent; lower the rate or the latency")

    @classmethod
    def ideal(cls) -> ArenaParams:
        """Every effect off and every noise zero: the arena flies the nominal model (800 Hz ZOH)."""
        return cls(
            true_vehicle=TrueVehicle(enabled=False),
            aerodynamics=Aerodynamics(enabled=False),
            onboard=Onboard(gyro_latency_samples=0, gyro_scale_error=(0.0, 0.0, 0.0), gyro_bias_rad_s=(0.0, 0.0, 0.0)),
            drift=Drift(enabled=False),
            disturbances=Disturbances(enabled=False),
            motion_capture=MotionCapture(position_noise_m=0.0, attitude_noise_rad=0.0),
            links=Links(command_drop_probability=0.0, upload_drop_probability=0.0),
        )

    def replace(self, **sections: Any) -> ArenaParams:
        """Copy with whole sections or ``section__field=value`` changes."""
        changed: ArenaParams = replace_sections(self, sections)
        return changed


def load_arena(path: str | Path) -> ArenaParams:
    """Read an arena TOML file: one table per section, any field may be omitted (defaults)."""
    path = as_path(path)
    data = read_toml(path)
    return dataclass_from_table(ArenaParams, data, source=str(path))


def save_arena(params: ArenaParams, path: str | Path) -> None:
    check_type("params", params, ArenaParams, "ArenaParams")
    write_file(path, tomli_w.dumps(dataclass_to_table(params)))


