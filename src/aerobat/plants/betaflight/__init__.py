"""Betaflight 4.6 firmware in the loop: a lockstep SITL driven by aerobat's physics.

The package's modules, by what they are about:

The plant (``--plant betaflight``)

* :mod:`.plant` — :class:`~.plant.BetaflightPlant`: one iteration of Fig. 8 flown through the firmware.
* :mod:`.params` — the plant's own settings (``--betaflight FILE.toml``): vehicle, airframe, arena.
* :mod:`.flight` — one flight: a firmware process, the physical world, the radio and motion capture.
* :mod:`.physics` — the world around the firmware: one compiled step of rigid body and rotors.
* :mod:`.lockstep` — the lockstep exchange and the physics in one compiled loop (many steps per call).
* :mod:`.lockstep_shm` — the same loop over the shared-memory exchange (``firmware.exchange = "shm"``).
* :mod:`.pilot` — the sticks a pilot gives: ANGLE-mode position hold, ACRO rates for a maneuver.
* :mod:`.replay` — a recorded flight's sticks replayed into the SITL (``aerobat log replay``).

The firmware process

* :mod:`.build` — builds the patched SITL binary once and caches it (``ensure_sitl``).
* :mod:`.configure` — applies ``settings.toml`` through the firmware's CLI once and keeps the
  eeprom (``ensure_eeprom``).
* :mod:`.sitl` — runs one SITL process and steps it in lockstep (``SitlProcess``, ``SitlPorts``).
* :mod:`.ports` — the ports of one instance (``SitlPorts``, ``allocate_ports``).
* :mod:`.shm` — the shared-memory exchange's region and its C helper (``ShmRegion``).
* :mod:`.packets` — the SITL's UDP packet formats (``SitlState``, the motor layout).
* :mod:`.rc` — RC channels as a receiver hands them to the firmware (``RcCommand``).

Talking to a flight controller (simulated or real)

* :mod:`.link` — one byte link with an MSP and a CLI client on it (``FirmwareLink``).
* :mod:`.transport` — byte transports to the MSP/CLI port (TCP to the SITL's UART1).
* :mod:`.msp` — the MSP v1/v2 client (MultiWii Serial Protocol).
* :mod:`.firmware_cli` — the client of the firmware's CLI, its text console: enter, command, save.

The firmware's settings and real quads' tunes

* :mod:`.firmware_settings` — the versioned CLI settings ``settings.toml`` and what follows from
  them: modes on AUX channels, stick to rate (``BetaflightSettings``, ``load_settings``).
* :mod:`.sitl_table` — the settings this SITL build accepts (``sitl_settings.json``).
* :mod:`.table_reader` — reads that table from the firmware's own CLI (writes ``sitl_settings.json``).
* :mod:`.tune` — a real quad's configuration from a CLI ``diff``/``dump`` or a blackbox header.
* :mod:`.translate` — a tune as Betaflight 4.6 SITL commands, and what became of each setting.

* :mod:`.errors` — the plant's exceptions, inside aerobat's one hierarchy (``BetaflightError``, ...).
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
from .firmware_settings import BetaflightSettings, load_settings
from .link import FirmwareLink
from .packets import MOTOR_POSITIONS_FRD, MOTOR_SPIN_CCW, SitlState
from .rc import RADIO_LOST_US, RcCommand
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
