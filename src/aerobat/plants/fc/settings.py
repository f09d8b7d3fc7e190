"""``--plant fc``'s settings file: which flight controller, which motion capture, which limits.

::

    [link]
    kind = "rehearsal"        # or "serial": a real board
    port = "/dev/ttyACM0"     # kind = "serial"
    baudrate_bd = 115200      # ignored over USB
    dry_run = false           # true: everything but spinning motors (each trial ends after the pre-flight
                              # and the program's frames streamed disarmed)

    [mocap]                   # kind = "serial": the room's motion-capture system (libmotioncapture)
    system = "vicon"
    hostname = "192.168.1.10"
    body = "aerobat"
    latency_s = 0.005

    [limits]                  # kind = "serial": the room (a rehearsal's fence is its flight volume)
    fence_x_m = [-2.0, 2.0]
    ...

    [betaflight.pilot]        # the Betaflight plant's sections: the supervisor, the pilot, the radio
    settle_timeout_s = 15.0   # rate; a rehearsal's world also takes its airframe, sensors, disturbances

A rehearsal flies the real firmware in real time (:class:`~.plant.RehearsalConnection`) with the
fence just outside ``[betaflight.volume]`` and :data:`~.plant.REHEARSAL_TIMEOUTS`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from enum import StrEnum
from pathlib import Path
from typing import Any

from aerobat.config import as_path, dataclass_from_table, dataclass_to_table, read_toml
from aerobat.core.bounds import Integer, Interval, Items, OneOf, bounded, validate
from aerobat.errors import ConfigError
from aerobat.plants.fpv.params import BetaflightParams, Pilot, params_to_table

from .pose_source import MOTION_CAPTURE_SYSTEMS
from .safety import SafetyLimits

__all__ = [
    "FC_SETTLE_TIMEOUT_S",
    "FcSettings",
    "LinkKind",
    "LinkSettings",
    "MocapSettings",
    "fc_params",
    "fc_settings_from_table",
    "fc_settings_to_table",
    "load_fc",
]


FC_SETTLE_TIMEOUT_S = 20.0
"""How long the pilot may take to settle at the start on the wall clock (lockstep's default: 10 s). In
real time the hover settles more slowly than in lockstep (measured in the rehearsal: 6–7 s after arming on
a quiet machine, beyond 10 s at times under load), and a settle that times out ends the session."""


def fc_params(**sections: Any) -> BetaflightParams:
    """The Betaflight plant's settings as ``--plant fc`` flies them: lockstep's, with the pilot given
    :data:`FC_SETTLE_TIMEOUT_S` to settle; ``sections`` replace whole sections (``radio=Radio(...)``)."""
    params = BetaflightParams(pilot=replace(Pilot(), settle_timeout_s=FC_SETTLE_TIMEOUT_S))
    return replace(params, **sections)


class LinkKind(StrEnum):
    """What the plant flies: the real firmware rehearsed in real time, or a board on a serial port."""

    REHEARSAL = "rehearsal"
    SERIAL = "serial"


@dataclass(frozen=True, kw_only=True)
class LinkSettings:
    """``[link]``: the flight controller's MSP port."""

    kind: LinkKind = bounded(LinkKind.REHEARSAL, OneOf(LinkKind))
    port: str = ""
    baudrate_bd: int = bounded(115_200, Integer(9_600, 4_000_000))
    dry_run: bool = False
    """Everything but spinning motors: connect, pre-flight, then the program's frames streamed disarmed."""

    def __post_init__(self) -> None:
        validate(self)
        if self.kind is LinkKind.SERIAL and not self.port.strip():
            raise ConfigError("port = '': required with kind = 'serial' (the board's device, e.g. /dev/ttyACM0)")


@dataclass(frozen=True, kw_only=True)
class MocapSettings:
    """``[mocap]``: the room's motion-capture system (a real board only)."""

    system: str = bounded("vicon", OneOf(MOTION_CAPTURE_SYSTEMS))
    hostname: str = ""
    body: str = "aerobat"
    latency_s: float = bounded(0.005, Interval(0.0, 0.2, unit="s"))

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True, kw_only=True)
class FcSettings:
    """``--fc FILE``: the link, the motion capture, the safety limits and the Betaflight plant's settings.

    ``start_m`` is where the maneuver starts, in the motion-capture frame (a real board only; the
    vehicle stands on the floor below it, ``[betaflight.volume] z_m``'s low side below it: with the
    default volume, 2.5 m above a floor at z = 0).
    """

    start_m: tuple[float, float, float] = bounded((0.0, 0.0, 2.5), Items.each(
        Interval(-50.0, 50.0, unit="m"), ("x", "y", "z"), "(x, y, z) in metres"))
    link: LinkSettings = field(default_factory=LinkSettings)
    mocap: MocapSettings = field(default_factory=MocapSettings)
    limits: SafetyLimits = field(default_factory=SafetyLimits)
    betaflight: BetaflightParams = field(default_factory=lambda: fc_params())

    def __post_init__(self) -> None:
        validate(self)


def fc_settings_from_table(table: Any, source: str) -> FcSettings:
    """The settings from a TOML table (errors name ``source``, the table and the field).

    A ``[betaflight.pilot]`` table that does not set ``settle_timeout_s`` keeps
    :data:`FC_SETTLE_TIMEOUT_S`, as when there is no ``[betaflight]`` table at all (the Betaflight
    plant's sections are read with lockstep's defaults otherwise).
    """
    betaflight = table.get("betaflight") if isinstance(table, Mapping) else None
    if isinstance(betaflight, Mapping):
        pilot = betaflight.get("pilot", {})
        if isinstance(pilot, Mapping) and "settle_timeout_s" not in pilot:
            betaflight = {**betaflight, "pilot": {**pilot, "settle_timeout_s": FC_SETTLE_TIMEOUT_S}}
            table = {**table, "betaflight": betaflight}
    return dataclass_from_table(FcSettings, table, source=source)


def fc_settings_to_table(settings: FcSettings) -> dict[str, Any]:
    """The settings' stored form (what a stored session keeps to rebuild the plant)."""
    table: dict[str, Any] = {"start_m": list(settings.start_m)}
    table.update({name: dataclass_to_table(getattr(settings, name)) for name in ("link", "mocap", "limits")})
    table["betaflight"] = params_to_table(settings.betaflight)
    return table


def load_fc(path: str | Path) -> FcSettings:
    """Read a ``--fc`` TOML file; :class:`ConfigError` names the file, field and range."""
    path = as_path(path)
    return fc_settings_from_table(read_toml(path), str(path))

