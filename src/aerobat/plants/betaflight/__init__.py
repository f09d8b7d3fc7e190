"""Betaflight 4.6 firmware in the loop: a lockstep SITL driven by aerobat's physics.

* :mod:`.build` builds the patched SITL binary once (``ensure_sitl``).
* :mod:`.configure` applies ``settings.toml`` through the CLI and keeps the
  eeprom (``ensure_eeprom``).
* :mod:`.sitl` runs one SITL process and steps it in lockstep (``SitlProcess``).
* :mod:`.link` talks MSP/CLI to a flight controller (simulated or real);
  :mod:`.rc` encodes RC channels; :mod:`.packets` the SITL's UDP packets.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .errors import (
    BetaflightError,
    ConfigureFailed,
    FirmwareExited,
    FirmwareNotResponding,
    FirmwareUnavailable,
    LinkClosed,
    LinkError,
    LinkTimeout,
    MspError,
)
from .link import FirmwareLink
from .packets import MOTOR_POSITIONS_FRD, MOTOR_SPIN_CCW, SitlState
from .rc import RADIO_LOST_US, RcCommand
from .settings import BetaflightSettings, load_settings
from .sitl import SitlPorts, SitlProcess

__all__ = [
    "MOTOR_POSITIONS_FRD",
    "MOTOR_SPIN_CCW",
    "RADIO_LOST_US",
    "BetaflightError",
    "BetaflightSettings",
    "ConfigureFailed",
    "FirmwareExited",
    "FirmwareLink",
    "FirmwareNotResponding",
    "FirmwareUnavailable",
    "LinkClosed",
    "LinkError",
    "LinkTimeout",
    "MspError",
    "RcCommand",
    "SitlPorts",
    "SitlProcess",
    "SitlState",
    "ensure_eeprom",
    "ensure_sitl",
    "load_settings",
]


if TYPE_CHECKING:
    from .build import ensure_sitl
    from .configure import ensure_eeprom


def __getattr__(name: str) -> Any:
    # Lazy, so that `python -m aerobat.plants.betaflight.build` does not import the module twice.
    if name == "ensure_sitl":
        from .build import ensure_sitl

        return ensure_sitl
    if name == "ensure_eeprom":
        from .configure import ensure_eeprom

        return ensure_eeprom
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
