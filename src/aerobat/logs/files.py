"""Opening a log file: what it is, and refusing what is not one before any library sees it."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from aerobat.config import as_path
from aerobat.errors import ConfigError
from aerobat.quadrotor.flightlog import LogFormat

__all__ = ["MAX_LOG_BYTES", "LogFormat", "check_log_file", "detect_format"]

#: Largest log file read [bytes]: a blackbox flash chip holds at most a few hundred MB, a ULog of
#: an hour's flight about 1 GB; anything larger is not read into memory.
MAX_LOG_BYTES = 1 << 30

_BLACKBOX_MAGIC = b"H Product:Blackbox flight data recorder"
_ULOG_MAGIC = b"ULog\x01\x12\x35"
_CRAZYFLIE_MAGIC = 0xBC


_SUFFIXES = {".bbl": LogFormat.BLACKBOX, ".bfl": LogFormat.BLACKBOX, ".txt": LogFormat.BLACKBOX,
             ".ulg": LogFormat.ULOG}


def check_log_file(path: str | os.PathLike[str]) -> Path:
    """``path`` as a Path if it is a readable, non-empty regular file of at most :data:`MAX_LOG_BYTES`."""
    path = as_path(path, "log file")
    try:
        info = path.stat()
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if stat.S_ISDIR(info.st_mode):
        raise ConfigError(f"{path}: is a directory, expected a flight log file")
    if not stat.S_ISREG(info.st_mode):
        raise ConfigError(f"{path}: not a regular file (a FIFO, device or socket), expected a flight log file")
    if info.st_size == 0:
        raise ConfigError(f"{path}: empty file, expected a flight log")
    if info.st_size > MAX_LOG_BYTES:
        raise ConfigError(f"{path}: {info.st_size / 2**20:.0f} MiB, larger than the {MAX_LOG_BYTES >> 20} MiB "
                          "a log may have")
    if not os.access(path, os.R_OK):
        raise ConfigError(f"{path}: permission denied")
    return path


def detect_format(path: Path) -> LogFormat:
    """The format of the log file at ``path`` (checked with :func:`check_log_file`), from its content."""
    try:
        with path.open("rb") as handle:
            head = handle.read(64)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if head.startswith(_BLACKBOX_MAGIC[: len(head)]) and head.startswith(b"H Product:"):
        return LogFormat.BLACKBOX
    if head.startswith(_ULOG_MAGIC):
        return LogFormat.ULOG
    if head[0] == _CRAZYFLIE_MAGIC and len(head) >= 5:
        return LogFormat.CRAZYFLIE
    expected = _SUFFIXES.get(path.suffix.lower())
    what = f"a {expected.value} log by its name, but it does not start like one" if expected else "not a flight log"
    raise ConfigError(f"{path}: {what} (expected a Betaflight blackbox .bbl/.bfl/.txt, a PX4 ULog .ulg or a "
                      "Crazyflie uSD log)")
