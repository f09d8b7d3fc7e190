"""Finding lockstep SITL processes (for the lifetime tests)."""

from __future__ import annotations

import os
from pathlib import Path

from aerobat.plants.betaflight.build import BINARY_NAME


def sitl_processes(parent: int | None = None) -> list[int]:
    """Pids of live lockstep SITL processes (children of ``parent`` if given)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if Path(os.readlink(entry / "exe")).name != BINARY_NAME:
                continue
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if fields[0] == "Z":
            continue
        if parent is None or int(fields[1]) == parent:
            found.append(int(entry.name))
    return found
