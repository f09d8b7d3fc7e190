"""Betaflight blackbox logs (``.bbl``, ``.bfl``, ``.txt``), decoded by aerobat (:mod:`.blackbox_decode`).

A file often holds several logs (one per arming); each is a header of ``H name:value`` lines
(the firmware, the board, the craft and the whole tune) and delta-encoded frames.
aerobat's compiled decoder reads the frames (orangebox 0.4.0, which read them before at
~70 µs a frame, is the tests' reference); the raw header text is kept as written, so the tune
can be applied to the firmware as the pilot had it (:mod:`aerobat.firmware.betaflight.tune`).

Units (Betaflight 4.x, data version 2): ``time`` µs; ``gyroADC`` and ``setpoint[0..2]``
deg/s; with ``debug_mode`` GYRO_SCALED (6 in 4.x), ``debug[0..2]`` is the gyro before the firmware's
filters in deg/s (:attr:`~aerobat.quadrotor.flightlog.Channel.GYRO_UNFILTERED`); ``accSmooth`` in
units of the header's ``acc_1G``; ``motor`` in the header's
``motorOutput`` range (DShot 48..2047 is the full range, the low end of ``motorOutput`` is
the idle); ``setpoint[3]`` throttle 0..1000; ``rcCommand[0..2]`` ±500 (after the deadband);
``rcCommand[3]`` 1000..2000 us (after the throttle curve); ``vbatLatest`` 0.01 V.

Axes: Betaflight's gyro and accelerometer are body FLU (roll right, pitch nose down, yaw nose
left positive; z up at rest), and so are its rate set points; sticks and PID terms keep the
firmware's units and signs (``rcCommand`` yaw is the negated stick).

Props in or out: 4.2 headers do not record ``yaw_motors_reversed``, but the log shows it. The
mixer raises M1 and M4 for a positive yaw PID term with props in and M2 and M3 with props out,
so the sign of the correlation between the logged yaw PID sum and M1 + M4 − M2 − M3 in flight
tells which (both shared 5-inch logs: −0.78 and −0.995, props out); the notes say so.

Motors: the QUADX mixer (M1 rear right, M2 front right, M3 rear left, M4 front left); with the
default ``yaw_motors_reversed = OFF`` ("props in"), M1 and M4 turn clockwise and M2 and M3
counter-clockwise seen from above. The headers of 4.2 do not record the mixer, so this layout
is assumed and said in the log's notes.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import logging
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from aerobat.errors import ConfigError
from aerobat.logs import blackbox_header
from aerobat.quadrotor.flightlog import Channel, FlightLog, LogFormat, LogMetadata, MotorLayout, Signal

__all__ = ["FIELDS", "QUADX_LAYOUT", "props_out", "quiet_orangebox", "raw_headers", "read_blackbox"]

G_M_S2 = 9.80665
DSHOT_MIN, DSHOT_MAX = 48.0, 2047.0

QUADX_LAYOUT = MotorLayout(
    names=("M1", "M2", "M3", "M4"),
    directions=((-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)),
    spins=(-1, 1, 1, -1),
    mixer="QUADX (props in)",
)
_REVERSED_LAYOUT = MotorLayout(names=QUADX_LAYOUT.names, directions=QUADX_LAYOUT.directions,
                               spins=tuple(-s for s in QUADX_LAYOUT.spins), mixer="QUADX (props out)")
_VERSION = re.compile(r"Betaflight\s+(\d+\.\d+(?:\.\d+)?)")


@contextlib.contextmanager
def quiet_orangebox() -> Iterator[list[str]]:
    """orangebox (the tests' and benchmark's reference decoder) logs warnings and prints; keep them."""
    records: list[str] = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            if len(records) < 20:
                records.append(record.getMessage())

    logger = logging.getLogger("orangebox")
    handler = Keep(level=logging.WARNING)
    old_level, old_propagate = logger.level, logger.propagate
    logger.addHandler(handler)
    logger.setLevel(logging.WARNING)
    logger.propagate = False
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            yield records
    finally:
        logger.removeHandler(handler)
        logger.setLevel(old_level)
        logger.propagate = old_propagate


def raw_headers(data: bytes, start: int) -> dict[str, str]:
    """The ``H name:value`` lines of the log starting at byte ``start``, as text."""
    headers: dict[str, str] = {}
    at = start
    while data.startswith(b"H ", at):
        end = data.find(b"\n", at)
        if end < 0:
            end = len(data)
        line = data[at + 2: end].decode("latin-1").rstrip("\r")
        name, sep, value = line.partition(":")
        if sep:
            headers[name.strip()] = value.strip()
        at = end + 1
    return headers


#: The main-frame fields the reader makes series of, in the order their table keeps them: each series's
#: fields side by side, so that every series is a view of the one table, scaled in place.
FIELDS = ("time", *(f"gyroADC[{i}]" for i in range(3)), *(f"accSmooth[{i}]" for i in range(3)),
          *(f"setpoint[{i}]" for i in range(4)), *(f"rcCommand[{i}]" for i in range(4)),
          *(f"motor[{i}]" for i in range(8)), *(f"axis{x}[{i}]" for x in "PIDF" for i in range(3)), "vbatLatest")


_GYRO_SCALED = "6"  # Betaflight 4.x's debug mode GYRO_SCALED: debug[0..2] = the gyro before its filters [deg/s]
#: kept besides :data:`FIELDS` when the log's debug mode is GYRO_SCALED (the unfiltered gyro)
GYRO_SCALED_FIELDS = tuple(f"debug[{i}]" for i in range(3))


def _debug_is_gyro_scaled(headers: dict[str, str]) -> bool:
    """Whether the log's ``debug[0..2]`` hold the unfiltered gyro (Betaflight 4.x with ``debug_mode`` GYRO_SCALED).

    The debug modes are numbered per version (3.x numbered 6 otherwise), so only a 4.x header counts."""
    version = _VERSION.search(headers.get("Firmware revision", ""))
    return (headers.get("debug_mode", "").strip() == _GYRO_SCALED and version is not None
            and version.group(1).split(".")[0] == "4")


def props_out(layout: MotorLayout | None) -> bool:
    """True when ``layout`` is Betaflight's QUADX with the propellers turned out (every spin reversed)."""
    return (layout is not None and layout.mixer.startswith("QUADX")
            and tuple(layout.spins) == tuple(-s for s in QUADX_LAYOUT.spins))


def _layout(headers: dict[str, str], motors: np.ndarray, table: np.ndarray, columns: dict[str, int]
            ) -> tuple[MotorLayout, str]:
    """The QUADX layout with props in or out: from the header if it says, else from the yaw mixing."""
    raw = headers.get("yaw_motors_reversed")
    if raw is not None:
        reversed_ = raw.strip() in ("1", "ON")
        return (_REVERSED_LAYOUT if reversed_ else QUADX_LAYOUT), f"mixer QUADX, yaw_motors_reversed = {raw}"
    terms = [f"axis{x}[2]" for x in "PIF" if f"axis{x}[2]" in columns]
    flying = np.all(motors > np.nanmin(motors, axis=0) + 40.0, axis=1)
    if not terms or flying.sum() < 100:
        return QUADX_LAYOUT, "the header does not record the mixer: QUADX with props in (Betaflight's default) assumed"
    yaw_sum = sum(table[flying, columns[t]] for t in terms)
    diff = motors[flying, 0] + motors[flying, 3] - motors[flying, 1] - motors[flying, 2]
    with np.errstate(invalid="ignore", divide="ignore"):  # a constant series has no correlation: said below
        corr = float(np.corrcoef(yaw_sum, diff)[0, 1])
    if not np.isfinite(corr) or abs(corr) < 0.3:
        return QUADX_LAYOUT, (f"the header does not record the mixer and the yaw mixing does not show it "
                              f"(correlation {corr:.2f}): QUADX with props in (Betaflight's default) assumed")
    layout = QUADX_LAYOUT if corr > 0 else _REVERSED_LAYOUT
    return layout, (f"mixer QUADX with props {'in' if corr > 0 else 'out'}: the header does not record "
                    f"yaw_motors_reversed, the yaw PID term and M1 + M4 − M2 − M3 correlate at {corr:+.2f}")


def read_blackbox(path: Path) -> list[FlightLog]:
    """Every log in a blackbox file, in order (decoded by :mod:`aerobat.logs.blackbox_decode`)."""
    from aerobat.logs.blackbox_decode import header_end, log_starts

    data = path.read_bytes()
    starts = log_starts(data)
    if not starts:
        raise ConfigError(f"{path}: no blackbox log in the file (no 'H Product:Blackbox flight data recorder' line)")
    ends = [*starts[1:], len(data)]
    # A file that ends in the last log's header or before its first whole frame: the recording stopped there. The
    # logs before it are whole, and read, with a note; only a file of that one log is refused ("holds no frames").
    logs: list[FlightLog | None] = []
    for i, (start, end) in enumerate(zip(starts, ends, strict=True)):
        cut_short = 0 < i == len(starts) - 1
        if cut_short and header_end(data, start) >= len(data):
            logs.append(None)
        else:
            logs.append(_read_one(path, data, i + 1, len(starts), start, end, cut_short=cut_short))
    last = logs[-1]
    if last is not None:
        return [log for log in logs if log is not None]
    whole = [dataclasses.replace(log, logs_in_file=len(starts) - 1) for log in logs[:-1] if log is not None]
    where = "header" if header_end(data, starts[-1]) >= len(data) else "first frame"
    whole[-1] = dataclasses.replace(whole[-1], notes=(*whole[-1].notes, f"the file ends in the {where} of a log after "
                                                      f"this one (log {len(starts)}, at byte {starts[-1]}): the "
                                                      "recording stopped there; not read"))
    return whole


def _read_one(path: Path, data: bytes, index: int, count: int, start: int, end: int, *,
              cut_short: bool = False) -> FlightLog | None:
    """Log ``index`` of the file; one without frames is refused, or, if it may be ``cut_short`` (the file's last
    log of several: the file ends in its first frame), None."""
    from aerobat.logs.blackbox_decode import decode_blackbox

    headers = raw_headers(data, start)
    where = f"{path}: log {index}"
    one_g = blackbox_header.one_g(headers, where)
    kept = FIELDS + GYRO_SCALED_FIELDS if _debug_is_gyro_scaled(headers) else FIELDS
    frames = decode_blackbox(data, start, end, headers, where, fields=kept, other_frames=False, drop_same_time=True)
    notes = frames.notes()
    if not len(frames.main):
        if cut_short:
            return None
        raise ConfigError(f"{where}: the log holds no frames" + (f" ({'; '.join(notes)})" if notes else ""))
    table = frames.main  # float64; every series below is a view of it, scaled in place (no copy of the log)
    columns = {name: i for i, name in enumerate(frames.names)}

    def have(*fields: str) -> bool:
        return all(f in columns for f in fields)

    def block(fields: list[str] | tuple[str, ...]) -> np.ndarray:
        """The columns of ``fields`` (next to each other in the table, see FIELDS) as one view."""
        first = columns[fields[0]]
        return table[:, first: first + len(fields)]

    t = table[:, columns["time"]]
    t -= t[0]
    t *= 1e-6
    signals: dict[Channel, Signal] = {}

    def vector(prefix: str, n: int) -> tuple[np.ndarray, tuple[str, ...]]:
        fields = tuple(f"{prefix}[{i}]" for i in range(n))
        return block(fields), fields

    xyz = ("x", "y", "z")
    motor_fields = [f"motor[{i}]" for i in range(8) if f"motor[{i}]" in columns]
    layout = None
    if len(motor_fields) == 4:  # before the motors are scaled: the layout reads DShot units
        layout, note = _layout(headers, block(motor_fields), table, columns)
        notes.append(note)
    if have("gyroADC[0]", "gyroADC[1]", "gyroADC[2]"):
        v, f = vector("gyroADC", 3)
        signals[Channel.GYRO] = Signal(Channel.GYRO, t, np.radians(v, out=v), xyz, "rad/s", f)
    if _debug_is_gyro_scaled(headers) and have("debug[0]", "debug[1]", "debug[2]"):
        v, f = vector("debug", 3)
        signals[Channel.GYRO_UNFILTERED] = Signal(Channel.GYRO_UNFILTERED, t, np.radians(v, out=v), xyz, "rad/s", f)
    if have("accSmooth[0]", "accSmooth[1]", "accSmooth[2]"):
        v, f = vector("accSmooth", 3)
        v *= G_M_S2 / one_g
        signals[Channel.SPECIFIC_FORCE] = Signal(Channel.SPECIFIC_FORCE, t, v, xyz, "m/s²", f)
    if have("setpoint[0]", "setpoint[1]", "setpoint[2]"):
        v, f = vector("setpoint", 3)
        signals[Channel.RATE_SETPOINT] = Signal(Channel.RATE_SETPOINT, t, np.radians(v, out=v), xyz, "rad/s", f)
    if have("setpoint[3]"):
        v = block(["setpoint[3]"])
        v /= 1000.0
        signals[Channel.THROTTLE] = Signal(Channel.THROTTLE, t, v, ("throttle",), "fraction", ("setpoint[3]",))
    if have("rcCommand[0]", "rcCommand[1]", "rcCommand[2]"):
        v, f = vector("rcCommand", 3)
        v /= 500.0
        signals[Channel.STICKS] = Signal(Channel.STICKS, t, v, ("roll", "pitch", "yaw"), "fraction", f)
    if have("rcCommand[3]"):
        v = block(["rcCommand[3]"])
        v -= 1000.0
        v /= 1000.0
        signals[Channel.THROTTLE_STICK] = Signal(Channel.THROTTLE_STICK, t, v, ("throttle",), "fraction",
                                                 ("rcCommand[3]",))
    if motor_fields:
        v = block(motor_fields)
        v -= DSHOT_MIN
        v /= DSHOT_MAX - DSHOT_MIN
        signals[Channel.MOTOR_COMMAND] = Signal(Channel.MOTOR_COMMAND, t, v,
                                                tuple(f"M{i + 1}" for i in range(len(motor_fields))), "fraction",
                                                tuple(motor_fields))
    for channel, prefix, n in ((Channel.PID_P, "axisP", 3), (Channel.PID_I, "axisI", 3), (Channel.PID_D, "axisD", 2),
                               (Channel.PID_F, "axisF", 3)):
        fields = [f"{prefix}[{i}]" for i in range(n) if f"{prefix}[{i}]" in columns]
        if fields:
            signals[channel] = Signal(channel, t, block(fields), ("roll", "pitch", "yaw")[: len(fields)],
                                      "firmware units", tuple(fields))
    if have("vbatLatest"):
        v = block(["vbatLatest"])
        v *= 0.01
        signals[Channel.BATTERY_VOLTAGE] = Signal(Channel.BATTERY_VOLTAGE, t, v, ("v",), "V", ("vbatLatest",))
    revision = headers.get("Firmware revision", "")
    version = _VERSION.search(revision)
    motors = len(motor_fields)
    metadata = LogMetadata(
        firmware=revision.split(" ")[0] if revision else headers.get("Firmware type", "Betaflight"),
        firmware_version=version.group(1) if version else "",
        board=headers.get("Board information", ""),
        craft_name=headers.get("Craft name", ""),
        vehicle_type="multirotor" if motors >= 3 or not motors else f"{motors}-motor vehicle (not a multirotor)",
        parameters=headers,
        start_time=headers.get("Log start datetime", ""),
    )
    return FlightLog(path=path, index=index, logs_in_file=count, source=LogFormat.BLACKBOX, metadata=metadata,
                     signals=signals, motor_layout=layout, notes=tuple(notes))
