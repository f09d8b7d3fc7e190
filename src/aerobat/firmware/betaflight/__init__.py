"""Betaflight 4.6 as a library: protocols, settings, tunes and the SITL, under both Betaflight plants.

The lockstep plant (:mod:`aerobat.plants.betaflight`) and the wall-clock flight controller
(:mod:`aerobat.plants.fc`) fly the firmware through this package; nothing here knows a plant, a
vehicle's physics or the Fig. 8 supervisor. The modules, by what they are about:

The firmware process (the SITL)

* :mod:`.build` — builds the patched SITL binary once and caches it (``ensure_sitl``; ``python -m
  aerobat.firmware.betaflight.build``).
* :mod:`.configure` — applies ``settings.toml`` through the firmware's CLI once and keeps the
  eeprom (``ensure_eeprom``).
* :mod:`.sitl` — runs one SITL process and steps it in lockstep (``SitlProcess``, ``SitlPorts``).
* :mod:`.ports` — the ports of one instance (``SitlPorts``, ``allocate_ports``).
* :mod:`.shm` — the shared-memory exchange's region and its C helper (``ShmRegion``).
* :mod:`.packets` — the SITL's packet formats (``SitlState``, the motor layout, the exchange).
* :mod:`.rc` — RC channels as a receiver hands them to the firmware (``RcCommand``).

Talking to a flight controller (simulated or real)

* :mod:`.link` — one byte link with an MSP and a CLI client on it (``FirmwareLink``).
* :mod:`.transport` — byte transports to the MSP/CLI port (TCP to the SITL's UART1).
* :mod:`.msp` — the MSP v1/v2 client (MultiWii Serial Protocol).
* :mod:`.cli` — the client of the firmware's CLI, its text console: enter, command, save.
* :mod:`.cli_grammar` — what a CLI line may hold, and how a refused one is shown.

The firmware's settings and real quads' tunes

* :mod:`.settings` — the versioned CLI settings ``settings.toml`` and what follows from them: modes
  on AUX channels, stick to rate (``BetaflightSettings``, ``load_settings``).
* :mod:`.sitl_table` — the settings this SITL build accepts (``sitl_settings.json``).
* :mod:`.table_reader` — reads that table from the firmware's own CLI (writes ``sitl_settings.json``).
* :mod:`.tune` — a real quad's configuration from a CLI ``diff``/``dump`` or a blackbox header.
* :mod:`.translate` — a tune as Betaflight 4.6 SITL commands, and what became of each setting.

* :mod:`.errors` — the firmware's exceptions, inside aerobat's one hierarchy (``BetaflightError``, ...).
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
    # Lazy, so that `python -m aerobat.firmware.betaflight.build` does not import the module twice.
    if name == "ensure_sitl":
        from .build import ensure_sitl

        return ensure_sitl
    if name == "ensure_eeprom":
        from .configure import ensure_eeprom

        return ensure_eeprom
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
