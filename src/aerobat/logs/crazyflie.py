"""The Crazyflie uSD-card logger's binary format (version 2).

Byte 0xBC, uint16 version, uint16 number of event types; per type a uint16 id, a NUL-terminated
name, a uint16 variable count and NUL-terminated ``name(type)`` strings; then records of uint16
event id, uint64 timestamp [µs since boot] and the variables packed little-endian by type
(``struct`` letters: ``f`` float32, ``I`` uint32, ``i`` int32, ``H``/``h`` 16 bit, ``B``/``b`` 8 bit).

No library on the package index reads it, so this one does, with NumPy structured arrays: a
50 s log at 1 kHz reads in milliseconds.

Units and frames in the log: ``acc.*`` in g, ``gyro.*`` in deg/s, both in the Crazyflie's body
frame, which is FLU (x forward, y left, z up); ``motor.m1..m4`` the PWM command, 0..65535.
Motors (Crazyflie 2.x): M1 front right, M2 rear right, M3 rear left, M4 front left; M1 and M3
turn counter-clockwise, M2 and M4 clockwise, seen from above (bitcraze/crazyflie-simulation's
model.sdf ``turningDirection``; the firmware's mixer gives M1 a −z reaction torque).
"""

from __future__ import annotations

import bisect
import re
import struct
from pathlib import Path

import numpy as np

from aerobat.errors import ConfigError
from aerobat.quadrotor.flightlog import Channel, FlightLog, LogFormat, LogMetadata, MotorLayout, Signal

__all__ = ["CRAZYFLIE_LAYOUT", "read_crazyflie"]

G_M_S2 = 9.81  # the Crazyflie firmware's gravity (GRAVITY_MAGNITUDE 9.81f)
PWM_FULL = 65535.0

CRAZYFLIE_LAYOUT = MotorLayout(
    names=("m1", "m2", "m3", "m4"),
    directions=((1.0, -1.0), (-1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)),
    spins=(1, -1, 1, -1),
    mixer="Crazyflie 2.x X (M1 front right, counter-clockwise)",
)

_TYPES = {"f": "<f4", "d": "<f8", "I": "<u4", "i": "<i4", "H": "<u2", "h": "<i2", "B": "u1", "b": "i1",
          "Q": "<u8", "q": "<i8"}
_FLOAT_TYPES = frozenset("fd")
_VARIABLE = re.compile(r"^(?P<name>[^()]+)\((?P<type>[A-Za-z])\)$")
# a record's own columns, named with parentheses, which no variable's name has: a variable may be called "t"
_ID, _TIME = "(event id)", "(timestamp)"
#: Records whose timestamps run backwards or jump ahead by this much or more [µs] are left out, as the Betaflight
#: reader leaves out such frames: the logger writes continuously (a 1 kHz event every millisecond); one flipped
#: bit in a timestamp made a 46.7 s log last 1,099,558 s.
MAX_TIME_JUMP_US = 10_000_000


def _parse_header(path: Path, data: bytes) -> tuple[int, dict[int, tuple[str, list[tuple[str, str]]]]]:
    def need(n: int, at: int, what: str) -> None:
        if at + n > len(data):
            raise ConfigError(f"{path}: truncated Crazyflie log header ({what} at byte {at})")

    def cstring(at: int, what: str) -> tuple[str, int]:
        end = data.find(b"\x00", at)
        if end < 0:
            raise ConfigError(f"{path}: truncated Crazyflie log header ({what} at byte {at})")
        try:
            return data[at:end].decode("ascii"), end + 1
        except UnicodeDecodeError:
            raise ConfigError(f"{path}: corrupted Crazyflie log header ({what} at byte {at} is not text)") from None

    need(5, 0, "version")
    version, count = struct.unpack_from("<HH", data, 1)
    if version != 2:
        raise ConfigError(f"{path}: Crazyflie log format version {version}; this reader knows version 2")
    if not 1 <= count <= 64:
        raise ConfigError(f"{path}: corrupted Crazyflie log header ({count} event types)")
    at = 5
    types: dict[int, tuple[str, list[tuple[str, str]]]] = {}
    for _ in range(count):
        need(2, at, "event id")
        (event_id,) = struct.unpack_from("<H", data, at)
        if event_id in types:
            raise ConfigError(f"{path}: header field 'event id' {event_id} (byte {at}) is declared twice: allowed "
                              "each event id once")
        name, at = cstring(at + 2, "event name")
        need(2, at, "variable count")
        (n_vars,) = struct.unpack_from("<H", data, at)
        at += 2
        variables = []
        seen: set[str] = set()
        for _ in range(n_vars):
            text, at = cstring(at, "variable")
            match = _VARIABLE.match(text)
            if match is None or match["type"] not in _TYPES:
                raise ConfigError(f"{path}: corrupted Crazyflie log header (variable {text!r})")
            if match["name"] in seen:
                raise ConfigError(f"{path}: header field {text!r} of event {name!r} is declared twice: allowed each "
                                  "variable name once")
            seen.add(match["name"])
            variables.append((match["name"], match["type"]))
        types[event_id] = (name, variables)
    return at, types


def _longest_in_order(stamps: list[int]) -> np.ndarray:
    """The indices of a longest non-decreasing run of ``stamps`` (not necessarily adjacent), by patience sorting:
    the fewest records left out to put the rest in time order."""
    tails: list[int] = []  # tails[k]: the smallest last timestamp of an ordered run of k + 1 records so far
    ends: list[int] = []  # the index of that last record
    before = np.full(len(stamps), -1, dtype=np.int64)
    for i, stamp in enumerate(stamps):
        k = bisect.bisect_right(tails, stamp)
        if k == len(tails):
            tails.append(stamp)
            ends.append(i)
        else:
            tails[k], ends[k] = stamp, i
        before[i] = ends[k - 1] if k else -1
    chain = []
    i = ends[-1]
    while i >= 0:
        chain.append(i)
        i = int(before[i])
    return np.array(chain[::-1], dtype=np.int64)


def _lone_outliers(t: np.ndarray) -> np.ndarray:
    """Records out of step with a neighbour whose neighbours are in step with each other (one damaged timestamp
    between good ones), and a first or last record out of step with both records next to it."""
    tf = t.astype(np.float64)  # uint64 timestamps, a flipped top bit included

    def in_step(gap: int) -> np.ndarray:
        d = tf[gap:] - tf[:-gap]
        return (d >= 0) & (d < MAX_TIME_JUMP_US)

    out = np.zeros(t.shape, dtype=bool)
    if len(t) < 3:
        return out
    step, skip = in_step(1), in_step(2)
    out[1:-1] = (~step[:-1] | ~step[1:]) & skip
    out[0] = not step[0] and not skip[0]
    out[-1] = not step[-1] and not skip[-1]
    # two such records side by side: either may be the damaged one, so neither is taken for it here
    pair = out[:-1] & out[1:]  # records j and j + 1 both
    either = np.zeros(t.shape, dtype=bool)
    either[:-1] |= pair
    either[1:] |= pair
    return out & ~either


def _in_time_order(t: np.ndarray, notes: list[str]) -> np.ndarray:
    """Which records to keep: all but lone records out of step (:func:`_lone_outliers`); then the fewest left out
    so that the rest run forwards in time, and, if they still jump ahead by :data:`MAX_TIME_JUMP_US` or more
    somewhere, the longest stretch between such jumps. A note names the records left out."""
    steps = np.diff(t.astype(np.float64))
    if not ((steps < 0) | (steps >= MAX_TIME_JUMP_US)).any():
        return np.ones(t.shape, dtype=bool)
    stamps = t.tolist()  # Python integers: exact whatever a damaged timestamp holds
    candidates = np.flatnonzero(~_lone_outliers(t))
    kept = candidates[_longest_in_order([stamps[i] for i in candidates])] if candidates.size else candidates
    jumps = np.flatnonzero(np.diff(t[kept].astype(np.float64)) >= MAX_TIME_JUMP_US) + 1
    stretches = np.split(kept, jumps)
    keep = np.zeros(t.shape, dtype=bool)
    keep[max(stretches, key=len)] = True
    dropped = np.flatnonzero(~keep)
    plural = "s" if dropped.size != 1 else ""
    named = ", ".join(f"{int(i)} at {stamps[i] * 1e-6:.6g} s" for i in dropped[:3])
    notes.append(f"{dropped.size} record{plural} left out: the timestamp runs backwards or jumps by "
                 f"{MAX_TIME_JUMP_US * 1e-6:g} s or more (record{plural} {named}{', …' if dropped.size > 3 else ''}; "
                 "numbered from 0)")
    return keep


def _count_non_finite(rec: np.ndarray, variables: list[tuple[str, str]], notes: list[str]) -> None:
    """A note per float variable holding NaN or infinite values (kept as read)."""
    for name, letter in variables:
        if letter in _FLOAT_TYPES:
            bad = int(np.count_nonzero(~np.isfinite(rec[name])))
            if bad:
                notes.append(f"{name} holds {bad} of {len(rec)} values NaN or infinite (kept as read)")


def read_crazyflie(path: Path) -> list[FlightLog]:
    """The one log of a Crazyflie uSD file (its ``fixedFrequency`` event, or the largest one)."""
    data = path.read_bytes()
    start, types = _parse_header(path, data)
    dtypes = {eid: np.dtype([(_ID, "<u2"), (_TIME, "<u8")] + [(n, _TYPES[t]) for n, t in variables])
              for eid, (_, variables) in types.items()}
    body = memoryview(data)[start:]
    notes: list[str] = []
    if len(dtypes) == 1:
        ((eid, dtype),) = dtypes.items()
        whole = len(body) // dtype.itemsize
        if len(body) % dtype.itemsize:
            notes.append(f"the last record is incomplete ({len(body) % dtype.itemsize} bytes), left out")
        records = {eid: np.frombuffer(body[: whole * dtype.itemsize], dtype=dtype)}
        bad = records[eid][_ID] != eid
        if bad.any():  # records are all one size: a damaged id costs its own record only
            which = np.flatnonzero(bad)
            notes.append(f"{which.size} record{'s' if which.size != 1 else ''} with an unknown event id left out "
                         f"(record {', '.join(str(int(i)) for i in which[:3])}{', …' if which.size > 3 else ''}; "
                         "numbered from 0)")
            records[eid] = records[eid][~bad]
    else:  # several event types: walk the records
        records = _walk(path, body, dtypes, notes)
    eid = max(records, key=lambda e: (types[e][0] == "fixedFrequency", len(records[e])))
    rec = records[eid]
    if len(rec) == 0:
        raise ConfigError(f"{path}: the Crazyflie log holds no records")
    names = {n for n, _ in types[eid][1]}
    keep = _in_time_order(rec[_TIME], notes)
    if not keep.all():
        rec = rec[keep]
    if len(rec) == 0:
        raise ConfigError(f"{path}: the Crazyflie log holds no record in time order ({'; '.join(notes)})")
    _count_non_finite(rec, types[eid][1], notes)
    t_us = rec[_TIME].astype(np.int64)
    t = (t_us - t_us[0]) * 1e-6
    signals: dict[Channel, Signal] = {}

    def vec(prefix: str, parts: tuple[str, ...]) -> np.ndarray | None:
        fields = [f"{prefix}.{p}" for p in parts]
        if not all(f in names for f in fields):
            return None
        return np.column_stack([rec[f].astype(float) for f in fields])

    acc = vec("acc", ("x", "y", "z"))
    if acc is not None:
        signals[Channel.SPECIFIC_FORCE] = Signal(Channel.SPECIFIC_FORCE, t, acc * G_M_S2, ("x", "y", "z"), "m/s²",
                                                 ("acc.x", "acc.y", "acc.z"))
    gyro = vec("gyro", ("x", "y", "z"))
    if gyro is not None:
        signals[Channel.GYRO] = Signal(Channel.GYRO, t, np.radians(gyro), ("x", "y", "z"), "rad/s",
                                       ("gyro.x", "gyro.y", "gyro.z"))
    motors = vec("motor", ("m1", "m2", "m3", "m4"))
    if motors is not None:
        signals[Channel.MOTOR_COMMAND] = Signal(Channel.MOTOR_COMMAND, t, motors / PWM_FULL,
                                                ("m1", "m2", "m3", "m4"), "fraction",
                                                tuple(f"motor.m{i}" for i in range(1, 5)))
    bat = [f for f in ("pm.vbat", "pm.vbatMV") if f in names]
    if bat:
        scale = 1e-3 if bat[0].endswith("MV") else 1.0
        signals[Channel.BATTERY_VOLTAGE] = Signal(Channel.BATTERY_VOLTAGE, t, rec[bat[0]] * scale, ("v",), "V",
                                                  (bat[0],))
    metadata = LogMetadata(
        firmware="Crazyflie", firmware_version="", board="Crazyflie 2.x", craft_name="",
        vehicle_type="multirotor",
        parameters={"event": types[eid][0], "variables": ",".join(f"{n}({t})" for n, t in types[eid][1]),
                    "format_version": "2", "boot_time_s": f"{t_us[0] * 1e-6:.6f}"},
    )
    return [FlightLog(path=path, index=1, logs_in_file=1, source=LogFormat.CRAZYFLIE, metadata=metadata,
                      signals=signals, motor_layout=CRAZYFLIE_LAYOUT if motors is not None else None,
                      notes=tuple(notes))]


def _walk(path: Path, body: memoryview, dtypes: dict[int, np.dtype], notes: list[str]) -> dict[int, np.ndarray]:
    rows: dict[int, list[bytes]] = {e: [] for e in dtypes}
    at = 0
    while at + 2 <= len(body):
        (eid,) = struct.unpack_from("<H", body, at)
        dtype = dtypes.get(eid)
        if dtype is None:
            notes.append(f"unknown event id {eid} at byte {at}; the rest left out")
            break
        if at + dtype.itemsize > len(body):
            notes.append("the last record is incomplete, left out")
            break
        rows[eid].append(bytes(body[at: at + dtype.itemsize]))
        at += dtype.itemsize
    return {e: np.frombuffer(b"".join(r), dtype=dtypes[e]) for e, r in rows.items()}
