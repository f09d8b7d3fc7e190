"""The settings this SITL build accepts, read from the firmware itself (``sitl_settings.json``).

Betaflight's setting table (``src/main/cli/settings.c``) depends on the build's ``#define``\\ s:
the SITL has no OSD, VTX, ESC telemetry, ... so the authoritative list of what *this* binary
accepts is what its CLI reports. :func:`.table_reader.read_table` starts a SITL from a blank eeprom, takes the
names and their section (master, PID profile, rate profile) from ``dump all`` and each one's range
or allowed values and default from ``get NAME``. The result is shipped as ``sitl_settings.json``
(so parsing a tune needs no firmware); ``python -m aerobat.plants.betaflight.table_reader``
regenerates it (:mod:`.table_reader`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

__all__ = ["SITL_TABLE_PATH", "SettingRange", "SitlTable", "load_table"]

SITL_TABLE_PATH = Path(__file__).with_name("sitl_settings.json")


@dataclass(frozen=True)
class SettingRange:
    """What one setting accepts.

    Attributes
    ----------
    name : the 4.6 CLI name.
    section : ``"master"``, ``"profile"`` (PID profile) or ``"rateprofile"``.
    low, high : integer range (None for a lookup or a string).
    values : allowed lookup names (empty for a number).
    default : the firmware's default, as the CLI prints it.
    array : the value is a comma-separated array (``Array length``), length given.
    """

    name: str
    section: str
    low: float | None
    high: float | None
    values: tuple[str, ...]
    default: str
    array: int = 0
    string: bool = False

    def check(self, value: str) -> str | None:
        """None if ``value`` is accepted, else why not (range or allowed values)."""
        text = value.strip()
        if self.values:
            if text.upper() not in self.values:
                return f"allowed {', '.join(self.values)}"
            return None
        if self.string:
            return None
        parts = text.split(",") if self.array else [text]
        if self.array and len(parts) != self.array:
            return f"expected {self.array} comma-separated values"
        for part in parts:
            try:
                number = float(part)
            except ValueError:
                return f"expected a number in {self.low:g}..{self.high:g}"
            if self.low is not None and self.high is not None and not self.low <= number <= self.high:
                return f"out of range, allowed {self.low:g}..{self.high:g}"
        return None


@dataclass(frozen=True)
class SitlTable:
    """Every setting of the SITL build, by name."""

    firmware: str
    settings: dict[str, SettingRange]
    features: tuple[str, ...]
    all_names: frozenset[str]

    def get(self, name: str) -> SettingRange | None:
        return self.settings.get(name.lower())


@lru_cache(maxsize=1)
def load_table(path: Path | None = None) -> SitlTable:
    """The shipped table (``sitl_settings.json``)."""
    data = json.loads((path or SITL_TABLE_PATH).read_text())
    settings = {
        name: SettingRange(name, e["section"], e["low"], e["high"], tuple(e["values"]), e["default"],
                           int(e["array"]), bool(e["string"]))
        for name, e in data["settings"].items()
    }
    return SitlTable(data["firmware"], settings, tuple(data["features"]), frozenset(data["all_4_6_names"]))
