"""Real flight logs in: Betaflight blackbox, PX4 ULog and Crazyflie uSD files.

Every reader returns :class:`~aerobat.quadrotor.flightlog.FlightLog` objects, one per log in
the file, in SI units and aerobat's frames (body FLU, world z up). This package is an edge
(file formats, third-party readers); what is made of a log lives with the vehicle
(:mod:`aerobat.quadrotor.identification.logdata`, :mod:`aerobat.quadrotor.identification.logfit`).

>>> from aerobat.logs import read_logs
>>> logs = read_logs("diatone-roma-f5.bbl")          # doctest: +SKIP
>>> logs[0].duration_s, logs[0].signal(Channel.GYRO).rate_hz   # doctest: +SKIP

ULog is read with the field's library, pyulog (the ``logs`` extra); Betaflight blackbox files
are decoded here (:mod:`.blackbox_decode`, compiled; orangebox 0.4.0 is the tests' reference)
and so is the Crazyflie format (:mod:`.crazyflie`).
"""

from __future__ import annotations

import os
from pathlib import Path

from aerobat.config import check_int
from aerobat.errors import ConfigError
from aerobat.logs.files import MAX_LOG_BYTES, LogFormat, check_log_file, detect_format
from aerobat.logs.refs import LogRef, parse_log_ref
from aerobat.quadrotor.flightlog import Channel, FlightLog, LogMetadata, MotorLayout, Signal

__all__ = [
    "MAX_LOG_BYTES",
    "Channel",
    "FlightLog",
    "LogFormat",
    "LogMetadata",
    "LogRef",
    "MotorLayout",
    "Signal",
    "detect_format",
    "parse_log_ref",
    "read_log",
    "read_logs",
]


def read_logs(path: str | os.PathLike[str]) -> list[FlightLog]:
    """Every log in the file at ``path``, in order (index 1 first)."""
    path = check_log_file(path)
    fmt = detect_format(path)
    if fmt is LogFormat.BLACKBOX:
        from aerobat.logs.betaflight import read_blackbox

        return read_blackbox(path)
    if fmt is LogFormat.ULOG:
        from aerobat.logs.px4 import read_ulog

        return read_ulog(path)
    from aerobat.logs.crazyflie import read_crazyflie

    return read_crazyflie(path)


def read_log(path: str | os.PathLike[str], index: int = 1) -> FlightLog:
    """Log number ``index`` (from 1) of the file at ``path``."""
    index = check_int("log index", index, low=1)
    logs = read_logs(path)
    if index > len(logs):
        raise ConfigError(f"{Path(path)}: log {index} does not exist; the file holds {len(logs)} "
                          f"log{'s' if len(logs) != 1 else ''} (1–{len(logs)})")
    return logs[index - 1]
