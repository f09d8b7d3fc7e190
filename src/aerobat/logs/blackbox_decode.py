"""aerobat's Betaflight blackbox decoder: the header in Python, the frames compiled (:mod:`.blackbox_kernel`).

A blackbox file holds one log per arming, each a header of ``H name:value`` lines and then
binary frames: I frames (every field written whole), P frames (deltas on the frames before,
with predictors), S (slow: flight modes, failsafe), G and H (GPS and its home) and E (events:
disarm, flight mode, log end). The header says, per field, its encoding and predictor.

orangebox 0.4.0 (pure Python) read these files at about 70 µs a frame, ~90 % of
``aerobat log info`` on the 151 s Gecko log; it stays the tests' reference, and this decoder
must give its main-frame tables bit for bit on every shared log.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from aerobat.errors import ConfigError

__all__ = ["BlackboxFrames", "decode_blackbox", "log_starts", "warm_up"]

LOG_START = b"H Product:Blackbox flight data recorder"
_KINDS = "IPSGH"
_ENCODINGS = {0: "signed VB", 1: "unsigned VB", 3: "negative 14-bit", 6: "tag8_8svb", 7: "tag2_3s32",
              8: "tag8_4s16", 9: "null", 10: "tag2_3svariable"}
_GROUP = {6: 1, 7: 3, 8: 4, 10: 3}  # encodings that write several fields together: fields per group (6: up to 8)
_PREDICTORS = range(12)
_MOTOR_0, _HOME_COORD, _HOME_COORD_1, _INCREMENT = 5, 7, 256, 6
# Betaflight's decoders' defaults for headers a log leaves out
_DEFAULTS = {"I interval": 32, "minthrottle": 1150, "vbatref": 4095, "Data version": 1}


@dataclasses.dataclass(frozen=True)
class BlackboxFrames:
    """One log's decoded frames: main-frame fields as written (int64), and what was dropped."""

    names: tuple[str, ...]
    main: np.ndarray  # (frames, fields): the I and P frames in order
    slow_names: tuple[str, ...]
    slow: np.ndarray  # (frames, 1 + fields): the main row each S frame precedes, then its fields
    gps_names: tuple[str, ...]
    gps: np.ndarray  # (frames, 1 + fields), as ``slow``
    events: np.ndarray  # (events, 4): main row, event type, two values (see blackbox_kernel._event)
    i_frames: int
    p_frames: int
    corrupt_frames: int  # dropped: the next byte starts no frame, longer than 256 bytes, or cut off
    truncated: bool  # the last frame was cut off by the end of the data
    rejected_frames: int  # main frames whose iteration or time ran backwards or jumped too far
    withheld_frames: int  # P frames after a corrupt or rejected frame, before the next I frame
    garbage_bytes: int  # bytes between frames that start none
    unknown_events: int
    log_end: bool  # Betaflight's "End of log" event was found

    def notes(self) -> list[str]:
        """What was skipped or corrupt, one line each (nothing when the log decoded cleanly)."""
        notes = []
        if self.corrupt_frames:
            cut = " (the last one cut off by the end of the data)" if self.truncated else ""
            notes.append(f"{self.corrupt_frames} corrupt frame{'s' if self.corrupt_frames != 1 else ''} "
                         f"skipped{cut}; decoding resumed at the next frame")
        if self.rejected_frames:
            notes.append(f"{self.rejected_frames} main frames left out: their iteration or time ran backwards or "
                         "jumped by 5,000 iterations / 10 s or more")
        if self.withheld_frames:
            notes.append(f"{self.withheld_frames} P frames left out after a corrupt or rejected frame (a P frame "
                         "is a delta on the frames before; decoding resumed at the next I frame)")
        if self.garbage_bytes:
            notes.append(f"{self.garbage_bytes} bytes between frames skipped")
        if self.unknown_events:
            notes.append(f"{self.unknown_events} events of unknown type skipped")
        if not self.log_end:
            notes.append("the log has no end-of-log event (recording stopped or the file is truncated)")
        return notes


def log_starts(data: bytes) -> list[int]:
    """Where each log in a blackbox file starts (its first header line)."""
    starts = []
    at = data.find(LOG_START)
    while at >= 0:
        starts.append(at)
        at = data.find(LOG_START, at + len(LOG_START))
    return starts


def header_end(data: bytes, start: int) -> int:
    """The first byte after the ``H`` lines of the log starting at ``start``."""
    at = start
    while data.startswith(b"H ", at):
        end = data.find(b"\n", at)
        if end < 0:
            return len(data)
        at = end + 1
    return at


def _ints(headers: dict[str, str], key: str, where: str) -> list[int]:
    try:
        return [int(x) for x in headers[key].split(",")]
    except ValueError:
        raise ConfigError(f"{where}: header 'H {key}' is not a list of integers: {headers[key][:60]!r}") from None


def _header_int(headers: dict[str, str], key: str, where: str) -> int:
    raw = headers.get(key)
    if raw is None:
        return _DEFAULTS[key]
    try:
        return int(raw.split(",")[0])
    except ValueError:
        raise ConfigError(f"{where}: header 'H {key}' is not an integer: {raw[:40]!r}") from None


def _frame_defs(headers: dict[str, str], where: str) -> tuple[dict[str, list[str]], np.ndarray, np.ndarray]:
    """The field names per frame kind and the (kind, encoding/predictor/signed, field) table."""
    names: dict[str, list[str]] = {}
    for kind in "ISGH":
        if f"Field {kind} name" in headers:
            names[kind] = [n.strip() for n in headers[f"Field {kind} name"].split(",")]
    if "I" not in names:
        raise ConfigError(f"{where}: the header has no field definitions (a damaged or truncated header)")
    names["P"] = names["I"]
    if names["I"][:2] != ["loopIteration", "time"]:
        raise ConfigError(f"{where}: the main frame's first fields are {names['I'][:2]}, expected "
                          "['loopIteration', 'time'] (not a Betaflight log)")
    width = max(len(v) for v in names.values())
    defs = np.zeros((len(_KINDS), 3, width), dtype=np.int64)
    counts = np.zeros(len(_KINDS), dtype=np.int64)
    for k, kind in enumerate(_KINDS):
        if kind not in names:
            continue
        n = len(names[kind])
        counts[k] = n
        for row, prop in enumerate(("encoding", "predictor", "signed")):
            key = f"Field {kind} {prop}"
            source = "I" if prop == "signed" and kind == "P" else kind
            if f"Field {source} {prop}" not in headers:
                if prop == "signed":
                    continue
                raise ConfigError(f"{where}: the header has no 'H {key}' line (a damaged or truncated header)")
            values = _ints(headers, f"Field {source} {prop}", where)
            if len(values) != n:
                raise ConfigError(f"{where}: 'H {key}' has {len(values)} entries for the {n} fields of the "
                                  f"{kind} frame")
            defs[k, row, :n] = values
        for i in range(n):
            enc, pred = int(defs[k, 0, i]), int(defs[k, 1, i])
            if enc not in _ENCODINGS and pred != _INCREMENT:
                raise ConfigError(f"{where}: field {names[kind][i]!r} of the {kind} frame has encoding {enc}; "
                                  f"this decoder reads {', '.join(f'{c} ({s})' for c, s in _ENCODINGS.items())}")
            if pred not in _PREDICTORS:
                raise ConfigError(f"{where}: field {names[kind][i]!r} of the {kind} frame has predictor {pred}; "
                                  "Betaflight's are 0–11")
        # GPS coordinates come in pairs with one predictor id: the second is the home's second coordinate
        for i in range(1, n):
            if defs[k, 1, i - 1] == _HOME_COORD and defs[k, 1, i] == _HOME_COORD:
                defs[k, 1, i] = _HOME_COORD_1
    return names, defs, counts


def _min_frame_bytes(defs: np.ndarray, counts: np.ndarray, k: int) -> int:
    """The fewest bytes a frame of kind ``k`` can take, its marker included."""
    size, i, n = 1, 0, int(counts[k])
    while i < n:
        enc, pred = int(defs[k, 0, i]), int(defs[k, 1, i])
        if pred == _INCREMENT or enc == 9:
            i += 1
            continue
        size += 1
        if enc == 6:
            j = i + 1
            while j < min(i + 8, n) and defs[k, 0, j] == 6:
                j += 1
            i = j
        else:
            i += _GROUP.get(enc, 1)
    return size


def _config(headers: dict[str, str], names: dict[str, list[str]], defs: np.ndarray, where: str) -> np.ndarray:
    from aerobat.logs import blackbox_kernel as k

    cfg = np.zeros(k.CFG_SIZE, dtype=np.int64)
    cfg[k.CFG_I_INTERVAL] = max(_header_int(headers, "I interval", where), 1)
    p_interval = headers.get("P interval", "1/1").strip()
    try:
        num, _, denom = p_interval.partition("/")
        # "1/2" in older firmware; Betaflight 4 writes one P frame every N iterations as "N"
        p_num, p_denom = (int(num), int(denom)) if denom else (1, int(num))
    except ValueError:
        raise ConfigError(f"{where}: header 'H P interval' is {p_interval!r}, expected N or N/M") from None
    cfg[k.CFG_P_NUM], cfg[k.CFG_P_DENOM] = max(p_num, 1), max(p_denom, 1)
    cfg[k.CFG_MINTHROTTLE] = _header_int(headers, "minthrottle", where)
    cfg[k.CFG_VBATREF] = _header_int(headers, "vbatref", where)
    cfg[k.CFG_MOTOR_LOW] = (_ints(headers, "motorOutput", where)[0] if "motorOutput" in headers
                            else cfg[k.CFG_MINTHROTTLE])
    cfg[k.CFG_DATA_VERSION] = _header_int(headers, "Data version", where)
    main = names["I"]
    cfg[k.CFG_MOTOR0] = main.index("motor[0]") if "motor[0]" in main else -1
    if cfg[k.CFG_MOTOR0] < 0 and (defs[:2, 1] == _MOTOR_0).any():
        raise ConfigError(f"{where}: a field is predicted from motor[0], but the log has no motor[0] field")
    home = names.get("H", [])
    cfg[k.CFG_HOME0] = home.index("GPS_home[0]") if "GPS_home[0]" in home else -1
    cfg[k.CFG_HOME1] = home.index("GPS_home[1]") if "GPS_home[1]" in home else -1
    gps = names.get("G", [])
    cfg[k.CFG_GPS_TIME] = gps.index("time") if "time" in gps else -1
    return cfg


def decode_blackbox(data: bytes, start: int, end: int, headers: dict[str, str],
                    where: str) -> BlackboxFrames:
    """Decode the log whose header starts at ``data[start]`` and whose bytes end before ``end``.

    ``headers`` are its ``H`` lines (:func:`aerobat.logs.betaflight.raw_headers`); ``where`` names
    the log in errors (a :class:`ConfigError`: a header this decoder cannot follow).
    """
    from aerobat.logs import blackbox_kernel as k

    names, defs, counts = _frame_defs(headers, where)
    cfg = _config(headers, names, defs, where)
    first = header_end(data, start)
    buffer = np.frombuffer(data, dtype=np.uint8)
    smallest = min(_min_frame_bytes(defs, counts, k.I_FRAME), _min_frame_bytes(defs, counts, k.P_FRAME))
    capacity = max(end - first, 0) // max(smallest, 1) + 1
    main = np.empty((capacity, int(counts[k.I_FRAME])), dtype=np.int64)
    stats, slow, gps, events = k.decode_frames(buffer, first, end, defs, counts, cfg, main)
    n = int(stats[k.ST_MAIN])
    return BlackboxFrames(
        names=tuple(names["I"]), main=main[:n].copy(),
        slow_names=tuple(names.get("S", [])), slow=slow[: int(stats[k.ST_SLOW])].copy(),
        gps_names=tuple(names.get("G", [])), gps=gps[: int(stats[k.ST_GPS])].copy(),
        events=events[: int(stats[k.ST_EVENTS])].copy(),
        i_frames=int(stats[k.ST_I]), p_frames=int(stats[k.ST_P]), corrupt_frames=int(stats[k.ST_CORRUPT]),
        truncated=bool(stats[k.ST_TRUNCATED]), rejected_frames=int(stats[k.ST_REJECTED]),
        withheld_frames=int(stats[k.ST_WITHHELD]), garbage_bytes=int(stats[k.ST_GARBAGE]),
        unknown_events=int(stats[k.ST_UNKNOWN_EVENTS]), log_end=bool(stats[k.ST_LOG_END]),
    )


def warm_up() -> BlackboxFrames:
    """Decode a three-frame log made here (I, P, log end), compiling the kernel or loading it from the cache."""
    lines = ["Product:Blackbox flight data recorder by Nicholas Sherlock", "Data version:2", "I interval:32",
             "P interval:1", "Field I name:loopIteration,time", "Field I signed:0,0", "Field I predictor:0,0",
             "Field I encoding:1,1", "Field P predictor:6,2", "Field P encoding:9,0"]
    data = "".join(f"H {line}\n" for line in lines).encode() + b"I\x07\x90\x4e" + b"P\x00" + b"E\xffEnd of log\x00"
    return decode_blackbox(data, 0, len(data), {k: v for k, _, v in (x.partition(":") for x in lines)}, "warm-up")
