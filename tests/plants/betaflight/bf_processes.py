"""Finding lockstep SITL processes (for the lifetime tests)."""

from __future__ import annotations

import os
import time
from pathlib import Path

from aerobat.firmware.betaflight.build import BINARY_NAME


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


def running(pid: int) -> bool:
    """The process exists and is not a zombie."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def wait_gone(pid: int, timeout_s: float = 3.0) -> bool:
    """True once ``pid`` has ended (or is a zombie) within ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if not running(pid):
            return True
        time.sleep(0.02)
    return False
