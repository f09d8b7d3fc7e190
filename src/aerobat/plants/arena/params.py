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
    check_type,
    dataclass_from_table,
    dataclass_to_table,
    read_toml,
    replace_sections,
    write_file,
)
from aerobat.core.bounds import Interval, Items, bounded, validate
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

_XYZ = "three numbers (x, y, z)"
_SCALE = Interval(0.2, 5.0)
"""A scale factor of a true constant relative to the nominal one."""
_MOTOR_RATE = Interval(1.0, 1e4, unit="1/s")
_PROBABILITY = Interval(0.0, 0.95)
"""A drop probability of a radio link."""
_COUNT = Interval(1, 1000)
"""A count of attempts or of items per packet (an int; checked as a number, as before)."""


@dataclass(frozen=True, kw_only=True)
class TrueVehicle:
    """The real vehicle's constants relative to the nominal Table 1 model."""

    enabled: bool = True
    mass_scale: float = bounded(1.03, Interval(0.5, 2.0))
    inertia_scale: tuple[float, float, float] = bounded((1.12, 1.12, 1.20), Items.each(_SCALE, 3, _XYZ))
    drag_constant_scale: float = bounded(1.15, _SCALE)
    motor_rate_up_per_s: float = bounded(70.0, _MOTOR_RATE)
    motor_rate_down_per_s: float = bounded(45.0, _MOTOR_RATE)
    thrust_gains: tuple[float, float, float, float] = bounded(
        (1.00, 0.97, 1.02, 0.95), Items.each(Interval(0.5, 1.5), 4, "four numbers (motors 1-4)"))
    com_offset_m: tuple[float, float, float] = bounded(
        (0.005, -0.003, 0.0), Items.each(Interval(-0.05, 0.05, unit="m"), 3, _XYZ))

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True, kw_only=True)
class Onboard:
    """The onboard loop: rate, gyro latency and gyro errors."""

    rate_hz: float = bounded(800.0, Interval(50.0, 10000.0, unit="Hz"))
    gyro_latency_samples: int = bounded(1, Interval(0, 10))
    gyro_scale_error: tuple[float, float, float] = bounded(
        (0.01, -0.008, 0.005), Items.each(Interval(-0.2, 0.2), 3, _XYZ))
    gyro_bias_rad_s: tuple[float, float, float] = bounded(
        (0.004, -0.003, 0.002), Items.each(Interval(-0.5, 0.5, unit="rad/s"), 3, _XYZ))

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True, kw_only=True)
class Links:
    """Radio links: 70 Hz command broadcast with drops; acknowledged program upload."""

    command_rate_hz: float = bounded(70.0, Interval(5.0, 1000.0, unit="Hz"))
    command_drop_probability: float = bounded(0.05, _PROBABILITY)
    command_latency_s: float = bounded(0.010, Interval(0.0, 0.2, unit="s"))
    upload_drop_probability: float = bounded(0.05, _PROBABILITY)
    upload_timeout_s: float = bounded(0.02, Interval(0.001, 1.0, unit="s"))
    upload_max_attempts: int = bounded(10, _COUNT)
    upload_switches_per_packet: int = bounded(8, _COUNT)
    upload_reference_samples_per_packet: int = bounded(2, _COUNT)

    def __post_init__(self) -> None:
        validate(self)


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


