"""Which process owns a running session: ``host:pid:start`` tokens and whether that process still lives."""

from __future__ import annotations

import os
import socket

__all__ = ["owner_alive", "owner_token", "process_start"]


def process_start(pid: int) -> str:
    """The process's start time in clock ticks since boot (Linux), "" where unknown."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as handle:
            stat = handle.read().decode(errors="replace")
    except OSError:
        return ""
    fields = stat[stat.rfind(")") + 2 :].split()
    if fields and fields[0] in ("Z", "X"):  # a zombie is dead, whatever kill(pid, 0) says
        return "zombie"
    return fields[19] if len(fields) > 19 else ""


def owner_token() -> str:
    return f"{socket.gethostname()}:{os.getpid()}:{process_start(os.getpid())}"


def owner_alive(owner: str | None) -> bool | None:
    """Is the process named by ``owner`` (``host:pid:start``) still running?

    None when it ran on another host (cannot tell).
    """
    if not owner:
        return False
    host, _, rest = owner.partition(":")
    pid_text, _, start = rest.partition(":")
    if host != socket.gethostname():
        return None
    try:
        pid = int(pid_text)
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except (ValueError, OSError):
        return False
    now = process_start(pid)
    if now == "zombie":
        return False
    return not (start and now and now != start)  # a recycled pid is another process
