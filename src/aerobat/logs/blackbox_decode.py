"""aerobat's Betaflight blackbox decoder: the header in Python (:mod:`.blackbox_header`), the frames compiled
(:mod:`.blackbox_kernel`).

A blackbox file holds one log per arming, each a header of ``H name:value`` lines and then
binary frames: I frames (every field written whole), P frames (deltas on the frames before,
with predictors), S (slow: flight modes, failsafe), G and H (GPS and its home) and E (events:
disarm, flight mode, log end). The header says, per field, its encoding and predictor.

The kernel decodes a chunk of :data:`CHUNK_BYTES` at a time and returns to Python between
chunks, so a Ctrl-C stops the longest decode within milliseconds. Memory is bounded by the file:
the main table's rows are at most the log's bytes over the smallest frame its header allows, and
a log whose frames decode to more than 16 times its bytes (and 1 MB) is refused when it does
(:data:`.blackbox_header.MAX_DECODED_BYTES_PER_BYTE`); the table's untouched rows take no memory.

orangebox 0.4.0 (pure Python) read these files at about 70 µs a frame, ~90 % of
``aerobat log info`` on the 151 s Gecko log; it stays the tests' reference, and this decoder
must give its main-frame tables bit for bit on every shared log.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from aerobat.errors import ConfigError
from aerobat.logs.blackbox_header import KINDS, MAX_DECODED_BYTES_PER_BYTE, decoder_config, frame_defs, min_frame_bytes

__all__ = ["CHUNK_BYTES", "DECODED_FLOOR_BYTES", "BlackboxFrames", "decode_blackbox", "header_end", "log_starts",
           "warm_up"]

LOG_START = b"H Product:Blackbox flight data recorder"
#: Bytes the kernel decodes between returns to Python: ~13 ms of the slowest input known (every other byte a
#: frame marker whose frame runs 256 bytes and is dropped, 0.4 µs a byte; a real log takes 0.03 µs a byte),
#: so a Ctrl-C is raised within a tenth of a second even on a loaded machine.
CHUNK_BYTES = 1 << 15
#: Decoded bytes a log may take whatever its size (a short log's few frames), besides 16 times its bytes.
DECODED_FLOOR_BYTES = 1 << 20


@dataclasses.dataclass(frozen=True)
class BlackboxFrames:
    """One log's decoded frames: the main-frame fields kept, as written, and what was dropped.

    ``main`` is float64, which holds every value exactly (Betaflight's fields are 32-bit integers, the
    microsecond clock unwrapped past 32 bits stays below 2**53 for 285 years); ``slow``, ``gps`` and
    ``events`` are empty when :func:`decode_blackbox` only counted them.
    """

    names: tuple[str, ...]  # the main-frame fields kept, the columns of ``main``
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
    same_time_frames: int = 0  # main frames left out (drop_same_time): their time did not pass the last one kept

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
        if self.same_time_frames:
            notes.append(f"{self.same_time_frames} main frames left out: their time did not advance past the frame "
                         "before")
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


def _grown(table: np.ndarray) -> np.ndarray:
    """``table`` with twice the rows (the rows after its own zero)."""
    bigger = np.zeros((2 * table.shape[0], table.shape[1]), dtype=table.dtype)
    bigger[: table.shape[0]] = table
    return bigger


def decode_blackbox(data: bytes, start: int, end: int, headers: dict[str, str], where: str, *,
                    fields: Sequence[str] | None = None, other_frames: bool = True,
                    drop_same_time: bool = False) -> BlackboxFrames:
    """Decode the log whose header starts at ``data[start]`` and whose bytes end before ``end``.

    Parameters
    ----------
    data, start, end : the file's bytes and the log's span in them.
    headers : its ``H`` lines (:func:`aerobat.logs.betaflight.raw_headers`).
    where : names the log in errors (a :class:`~aerobat.errors.ConfigError`: a header this decoder cannot
        follow, or a value out of the range Betaflight writes).
    fields : the main-frame fields to keep, in this order (those the log lacks are left out); default all,
        in the header's order.
    other_frames : keep the slow and GPS frames and the events (default); else only count them.
    drop_same_time : leave out of the table a main frame whose time does not pass the last one kept
        (it stays the history of the P frames after it), counted in ``same_time_frames``.

    Returns
    -------
    BlackboxFrames
    """
    from aerobat.logs import blackbox_kernel as k

    names, defs, counts = frame_defs(headers, where)
    cfg = decoder_config(headers, names, defs, where)
    cfg[k.CFG_DROP_SAME_TIME] = int(drop_same_time)
    main_names = names["I"]
    kept = list(main_names) if fields is None else [f for f in fields if f in main_names]
    columns = np.array([main_names.index(f) for f in kept], dtype=np.int64)
    first = header_end(data, start)
    size = max(end - first, 0)
    buffer = np.frombuffer(data, dtype=np.uint8)
    # every main frame takes at least ``smallest`` bytes: rows enough for all (rows never written cost nothing),
    # but no more than the log may decode to: only a log that would decode to more fills them, and is refused
    smallest = min(min_frame_bytes(defs, counts, KINDS.index("I")), min_frame_bytes(defs, counts, KINDS.index("P")))
    allowed = (MAX_DECODED_BYTES_PER_BYTE * size + DECODED_FLOOR_BYTES) // (8 * len(kept)) + 1
    main = np.empty((min(size // smallest + 1, allowed), len(kept)), dtype=np.float64)
    rows = 16 if other_frames else 0
    slow = np.zeros((rows, counts[k.S_FRAME] + 1), dtype=np.int64)
    gps = np.zeros((rows, counts[k.G_FRAME] + 1), dtype=np.int64)
    events = np.zeros((rows, 4), dtype=np.int64)
    state, stats = k.new_state(first), np.zeros(k.ST_SIZE, dtype=np.int64)
    history = np.zeros((5, max(int(counts.max()), 1)), dtype=np.int64)
    home = np.zeros(history.shape[1], dtype=np.int64)
    values, event_row = np.zeros(8, dtype=np.int64), np.zeros(4, dtype=np.int64)
    stop = first
    while True:  # a chunk at a time: Python runs between chunks, so a Ctrl-C is raised here
        stop = min(max(stop, int(state[k.S_POS])) + CHUNK_BYTES, end)
        outcome = k.ChunkEnd(k.decode_chunk(buffer, stop, end, defs, counts, cfg, columns, state, stats, history,
                                            home, values, event_row, main, slow, gps, events))
        if outcome is k.ChunkEnd.FINISHED:
            break
        if outcome is k.ChunkEnd.MAIN_FULL:  # the log's frames outgrow what it may decode to
            read = int(state[k.S_POS]) - first
            raise ConfigError(f"{where}: {main.shape[0]:,} main frames of {len(kept)} fields in its first {read:,} "
                              f"bytes (one every {read / main.shape[0]:.1f} bytes) would decode to more than "
                              f"{MAX_DECODED_BYTES_PER_BYTE} times the log's {size:,} bytes; allowed frames of "
                              f"{8 * len(kept) / MAX_DECODED_BYTES_PER_BYTE:.0f} bytes or more on average "
                              "(Betaflight's: 20-30)")
        if outcome is k.ChunkEnd.SLOW_FULL:
            slow = _grown(slow)
        elif outcome is k.ChunkEnd.GPS_FULL:
            gps = _grown(gps)
        elif outcome is k.ChunkEnd.EVENTS_FULL:
            events = _grown(events)
    n = int(stats[k.ST_MAIN])
    return BlackboxFrames(
        names=tuple(kept), main=main[:n],
        slow_names=tuple(names.get("S", [])), slow=slow[: int(stats[k.ST_SLOW])],
        gps_names=tuple(names.get("G", [])), gps=gps[: int(stats[k.ST_GPS])],
        events=events[: int(stats[k.ST_EVENTS])],
        i_frames=int(stats[k.ST_I]), p_frames=int(stats[k.ST_P]), corrupt_frames=int(stats[k.ST_CORRUPT]),
        truncated=bool(stats[k.ST_TRUNCATED]), rejected_frames=int(stats[k.ST_REJECTED]),
        withheld_frames=int(stats[k.ST_WITHHELD]), garbage_bytes=int(stats[k.ST_GARBAGE]),
        unknown_events=int(stats[k.ST_UNKNOWN_EVENTS]), log_end=bool(stats[k.ST_LOG_END]),
        same_time_frames=int(stats[k.ST_SAME_TIME]),
    )


def warm_up() -> BlackboxFrames:
    """Decode a three-frame log made here (I, P, log end), compiling the kernel or loading it from the cache."""
    lines = ["Product:Blackbox flight data recorder by Nicholas Sherlock", "Data version:2", "I interval:32",
             "P interval:1", "Field I name:loopIteration,time", "Field I signed:0,0", "Field I predictor:0,0",
             "Field I encoding:1,1", "Field P predictor:6,2", "Field P encoding:9,0"]
    data = "".join(f"H {line}\n" for line in lines).encode() + b"I\x07\x90\x4e" + b"P\x00" + b"E\xffEnd of log\x00"
    return decode_blackbox(data, 0, len(data), {k: v for k, _, v in (x.partition(":") for x in lines)}, "warm-up")
