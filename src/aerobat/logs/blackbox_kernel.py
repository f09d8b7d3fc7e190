"""The compiled frame decoder for Betaflight blackbox logs (numba; see :mod:`.blackbox_decode`).

:func:`decode_chunk` decodes a log's frames from where the last call stopped to a byte
position, into tables the caller allocated: main frames (I and P) into a table of float64 rows
(the fields the caller keeps, exact: Betaflight's fields are 32-bit integers), slow (S), GPS (G)
frames and events into tables of int64 rows (or only counted, when a table has no rows). It
allocates nothing, and returns to Python after every chunk of bytes, so a Ctrl-C is raised
between chunks, and whenever a table is full: the caller grows the slow, GPS and event tables,
and refuses a log whose main frames fill theirs (more than the log may decode to).

The format and the resynchronisation follow Betaflight's own decoders (blackbox-tools and the
blackbox log viewer): a frame counts only if the byte after it starts another frame (or the log
ends cleanly) and it is at most 256 bytes long; a corrupt frame is dropped, the search for the
next frame starts at the byte after its marker, and main frames are withheld until the next
I frame, since every P frame is a delta on the frames before it. A main frame whose iteration
or time runs backwards, or jumps by 5,000 iterations or 10 s or more, is rejected the same way.
"""

from __future__ import annotations

import enum

import numpy as np
from numba import njit

# frame kinds, as the rows of the definition tables
I_FRAME, P_FRAME, S_FRAME, G_FRAME, H_FRAME = 0, 1, 2, 3, 4
# encodings
SIGNED_VB, UNSIGNED_VB, NEG_14BIT, TAG8_8SVB, TAG2_3S32, TAG8_4S16, NULL, TAG2_3SVARIABLE = 0, 1, 3, 6, 7, 8, 9, 10
# predictors
ZERO, PREVIOUS, STRAIGHT_LINE, AVERAGE_2, MINTHROTTLE, MOTOR_0, INCREMENT = 0, 1, 2, 3, 4, 5, 6
HOME_COORD, P1500, VBATREF, LAST_MAIN_FRAME_TIME, MINMOTOR, HOME_COORD_1 = 7, 8, 9, 10, 11, 256
# events
EV_SYNC_BEEP, EV_INFLIGHT_ADJUSTMENT, EV_LOGGING_RESUME, EV_DISARM, EV_FLIGHT_MODE, EV_LOG_END = 0, 13, 14, 15, 30, 255
# the configuration vector
CFG_I_INTERVAL, CFG_P_NUM, CFG_P_DENOM, CFG_MINTHROTTLE, CFG_VBATREF, CFG_MOTOR_LOW = 0, 1, 2, 3, 4, 5
CFG_DATA_VERSION, CFG_MOTOR0, CFG_HOME0, CFG_HOME1, CFG_DROP_SAME_TIME, CFG_SIZE = 6, 7, 8, 9, 10, 11
# the statistics vector
(ST_MAIN, ST_I, ST_P, ST_SLOW, ST_GPS, ST_HOME, ST_EVENTS, ST_CORRUPT, ST_REJECTED, ST_WITHHELD, ST_GARBAGE,
 ST_LOG_END, ST_END, ST_TRUNCATED, ST_UNKNOWN_EVENTS, ST_SAME_TIME, ST_SIZE) = range(17)
# the decoder's state between calls: where it is, the main-frame history (rows of ``rows``), the stream's step
(S_POS, S_CUR, S_PREV, S_PREV2, S_HAS_PREV, S_VALID, S_LAST_ITER, S_LAST_TIME, S_ROLLOVER, S_LAST_KEPT_TIME,
 S_SIZE) = range(11)


class ChunkEnd(enum.IntEnum):
    """Why :func:`decode_chunk` returned."""

    STOP = 0         # it reached the stop position: call again
    FINISHED = 1     # the log's end or its end-of-log event
    MAIN_FULL = 2    # the table named has no room for the next frame: grow it and call again
    SLOW_FULL = 3
    GPS_FULL = 4
    EVENTS_FULL = 5


_STOP, _FINISHED, _MAIN_FULL, _SLOW_FULL, _GPS_FULL, _EVENTS_FULL = (int(e) for e in ChunkEnd)

MAX_FRAME_BYTES = 256
MAX_ITERATION_JUMP = 5000
MAX_TIME_JUMP_US = 10_000_000
_END_OF_LOG = np.frombuffer(b"End of log\x00", dtype=np.uint8).copy()
_MARKERS = np.zeros(256, dtype=np.int64) - 1
for _kind, _marker in enumerate(b"IPSGH"):
    _MARKERS[_marker] = _kind
_MARKERS[ord("E")] = 5
EVENT_MARK = 5


@njit(cache=True, inline="always")
def _byte(data, pos, end):
    """The byte at ``pos`` (0 past ``end``: the caller sees ``pos > end`` and drops the frame)."""
    if pos < end:
        return np.int64(data[pos]), pos + 1
    return np.int64(0), pos + 1


@njit(cache=True, inline="always")
def _unsigned_vb(data, pos, end):
    result = np.int64(0)
    shift = 0
    for _ in range(5):
        b, pos = _byte(data, pos, end)
        result |= (b & 0x7F) << shift
        if b < 128:
            return result & 0xFFFFFFFF, pos
        shift += 7
    return np.int64(0), pos  # longer than 32 bits: not a value Betaflight writes


@njit(cache=True, inline="always")
def _signed_vb(data, pos, end):
    u, pos = _unsigned_vb(data, pos, end)
    return (u >> 1) ^ -(u & 1), pos  # zig-zag


@njit(cache=True, inline="always")
def _sign_extend(value, bits):
    value &= (np.int64(1) << bits) - 1
    if value & (np.int64(1) << (bits - 1)):
        value -= np.int64(1) << bits
    return value


@njit(cache=True)
def _tag2_3s32_wide(data, pos, end, lead, values):
    """Three fields of 8, 16, 24 or 32 bits (little-endian), their widths in ``lead``'s low six bits."""
    for i in range(3):
        width = lead & 0x03
        v = np.int64(0)
        for k in range(width + 1):
            b, pos = _byte(data, pos, end)
            v |= b << (8 * k)
        values[i] = _sign_extend(v, 8 * (width + 1))
        lead >>= 2
    return pos


@njit(cache=True)
def _tag2_3s32(data, pos, end, values):
    lead, pos = _byte(data, pos, end)
    kind = lead >> 6
    if kind == 0:
        values[0] = _sign_extend(lead >> 4, 2)
        values[1] = _sign_extend(lead >> 2, 2)
        values[2] = _sign_extend(lead, 2)
    elif kind == 1:
        values[0] = _sign_extend(lead, 4)
        b, pos = _byte(data, pos, end)
        values[1] = _sign_extend(b >> 4, 4)
        values[2] = _sign_extend(b, 4)
    elif kind == 2:
        values[0] = _sign_extend(lead, 6)
        b, pos = _byte(data, pos, end)
        values[1] = _sign_extend(b, 6)
        b, pos = _byte(data, pos, end)
        values[2] = _sign_extend(b, 6)
    else:
        pos = _tag2_3s32_wide(data, pos, end, lead, values)
    return pos


@njit(cache=True)
def _tag2_3svariable(data, pos, end, values):
    lead, pos = _byte(data, pos, end)
    kind = lead >> 6
    if kind == 0:  # 2, 2, 2 bits
        values[0] = _sign_extend(lead >> 4, 2)
        values[1] = _sign_extend(lead >> 2, 2)
        values[2] = _sign_extend(lead, 2)
    elif kind == 1:  # 5, 5, 4 bits
        b, pos = _byte(data, pos, end)
        values[0] = _sign_extend(lead >> 1, 5)
        values[1] = _sign_extend(((lead & 0x01) << 4) | (b >> 4), 5)
        values[2] = _sign_extend(b, 4)
    elif kind == 2:  # 8, 7, 7 bits
        b2, pos = _byte(data, pos, end)
        b3, pos = _byte(data, pos, end)
        values[0] = _sign_extend(((lead & 0x3F) << 2) | (b2 >> 6), 8)
        values[1] = _sign_extend(((b2 & 0x3F) << 1) | (b3 >> 7), 7)
        values[2] = _sign_extend(b3, 7)
    else:
        pos = _tag2_3s32_wide(data, pos, end, lead, values)
    return pos


@njit(cache=True)
def _tag8_4s16(data, pos, end, values, version):
    """Four fields of 0, 4, 8 or 16 bits; data version 2 packs them by nibbles, high first."""
    selector, pos = _byte(data, pos, end)
    if version < 2:
        i = 0
        while i < 4:
            kind = selector & 0x03
            if kind == 0:
                values[i] = 0
            elif kind == 1:  # two 4-bit fields in one byte, low nibble first
                b, pos = _byte(data, pos, end)
                values[i] = _sign_extend(b, 4)
                if i + 1 < 4:
                    i += 1
                    selector >>= 2
                    values[i] = _sign_extend(b >> 4, 4)
            elif kind == 2:
                b, pos = _byte(data, pos, end)
                values[i] = _sign_extend(b, 8)
            else:
                b1, pos = _byte(data, pos, end)
                b2, pos = _byte(data, pos, end)
                values[i] = _sign_extend(b1 | (b2 << 8), 16)
            selector >>= 2
            i += 1
        return pos
    half = False  # a low nibble of ``buffer`` is still unread
    buffer = np.int64(0)
    for i in range(4):
        kind = selector & 0x03
        if kind == 0:
            values[i] = 0
        elif kind == 1:
            if not half:
                buffer, pos = _byte(data, pos, end)
                values[i] = _sign_extend(buffer >> 4, 4)
            else:
                values[i] = _sign_extend(buffer, 4)
            half = not half
        elif kind == 2:
            if not half:
                b, pos = _byte(data, pos, end)
                values[i] = _sign_extend(b, 8)
            else:
                hi = (buffer & 0x0F) << 4
                buffer, pos = _byte(data, pos, end)
                values[i] = _sign_extend(hi | (buffer >> 4), 8)
        else:
            b1, pos = _byte(data, pos, end)
            b2, pos = _byte(data, pos, end)
            if not half:
                values[i] = _sign_extend((b1 << 8) | b2, 16)
            else:
                values[i] = _sign_extend(((buffer & 0x0F) << 12) | (b1 << 4) | (b2 >> 4), 16)
                buffer = b2
        selector >>= 2
    return pos


@njit(cache=True)
def _predict(predictor, value, prev, prev2, has_prev, motor0, last_time, home0, home1, minthrottle, vbatref,
             motor_low):
    """``value`` plus its predictor's prediction (scalars only: no array is reference-counted per field)."""
    if predictor == ZERO:
        return value
    if predictor == PREVIOUS:
        return value + prev if has_prev else value
    if predictor == STRAIGHT_LINE:
        return value + 2 * prev - prev2 if has_prev else value
    if predictor == AVERAGE_2:
        if not has_prev:
            return value
        s = prev + prev2
        return value + (s // 2 if s >= 0 else -((-s) // 2))  # rounds toward zero, as C does
    if predictor == MINTHROTTLE:
        return value + minthrottle
    if predictor == MOTOR_0:
        return value + motor0
    if predictor == P1500:
        return value + 1500
    if predictor == VBATREF:
        return value + vbatref
    if predictor == LAST_MAIN_FRAME_TIME:
        return value + last_time if last_time >= 0 else value
    if predictor == MINMOTOR:
        return value + motor_low
    if predictor == HOME_COORD:
        return value + home0
    if predictor == HOME_COORD_1:
        return value + home1
    return value


@njit(cache=True)
def _parse_frame(data, pos, end, kind, defs, counts, rows, out, prev, prev2, has_prev, skipped, cfg, last_time,
                 home0, home1, values):
    """Decode one frame of ``kind`` into ``rows[out]`` (predicting from rows ``prev`` and ``prev2``);
    returns the position after it (> ``end``: the frame was cut off)."""
    n = counts[kind]
    motor_index = cfg[CFG_MOTOR0]
    minthrottle, vbatref, motor_low = cfg[CFG_MINTHROTTLE], cfg[CFG_VBATREF], cfg[CFG_MOTOR_LOW]
    version = cfg[CFG_DATA_VERSION]
    limit = pos + MAX_FRAME_BYTES  # past it the frame is corrupt whatever follows: stop reading
    i = 0
    while i < n:
        if pos > limit:
            return pos
        predictor = defs[kind, 1, i]
        if predictor == INCREMENT:
            rows[out, i] = skipped + 1 + (rows[prev, i] if has_prev else 0)
            i += 1
            continue
        e = defs[kind, 0, i]
        group = 0
        if e == TAG8_4S16:
            pos = _tag8_4s16(data, pos, end, values, version)
            group = 4
        elif e == TAG2_3S32:
            pos = _tag2_3s32(data, pos, end, values)
            group = 3
        elif e == TAG2_3SVARIABLE:
            pos = _tag2_3svariable(data, pos, end, values)
            group = 3
        elif e == TAG8_8SVB:
            j = i + 1
            while j < i + 8 and j < n and defs[kind, 0, j] == TAG8_8SVB:
                j += 1
            group = j - i
            if group == 1:
                v, pos = _signed_vb(data, pos, end)
                values[0] = v
            else:
                header, pos = _byte(data, pos, end)
                for k in range(group):
                    if header & 1:
                        v, pos = _signed_vb(data, pos, end)
                        values[k] = v
                    else:
                        values[k] = 0
                    header >>= 1
        if group:
            for k in range(min(group, n - i)):
                motor0 = rows[out, motor_index] if motor_index >= 0 else 0
                rows[out, i] = _field(_predict(defs[kind, 1, i], values[k], rows[prev, i], rows[prev2, i], has_prev,
                                               motor0, last_time, home0, home1, minthrottle, vbatref, motor_low),
                                      defs[kind, 2, i])
                i += 1
            continue
        if e == SIGNED_VB:
            v, pos = _signed_vb(data, pos, end)
        elif e == UNSIGNED_VB:
            v, pos = _unsigned_vb(data, pos, end)
        elif e == NEG_14BIT:
            u, pos = _unsigned_vb(data, pos, end)
            u &= 0xFFFF  # Betaflight sign-extends the low 16 bits from bit 13
            v = -(u - 0x4000 - (u & 0xC000) if u & 0x2000 else u)
        else:  # NULL (the header check refuses encodings Betaflight does not write)
            v = np.int64(0)
        motor0 = rows[out, motor_index] if motor_index >= 0 else 0
        rows[out, i] = _field(_predict(predictor, v, rows[prev, i], rows[prev2, i], has_prev, motor0, last_time,
                                       home0, home1, minthrottle, vbatref, motor_low), defs[kind, 2, i])
        i += 1
    return pos


@njit(cache=True, inline="always")
def _field(v, signed):
    """A field is a 32-bit integer: signed or unsigned as its header says."""
    v &= 0xFFFFFFFF
    if signed and v >= 0x80000000:
        v -= 0x100000000
    return v


@njit(cache=True)
def skipped_iterations(last_iter, interval, num, denom):
    """Loop iterations without a logged frame between ``last_iter`` and the next P frame, in closed form.

    Betaflight's decoders step ``index`` from ``last_iter + 1`` until ``shouldHaveFrame(index)``:
    ``(index % interval + num - 1) % denom < num``; that loop ran once per iteration (up to ``denom``
    times a frame). With ``r`` the next index within the I interval and ``j = (r + num - 1) % denom``:
    no skip if ``j < num``; else the next logged index is ``denom - j`` on, unless that passes the next
    I frame's index (always logged), ``interval - r`` on.
    """
    r = (last_iter + 1) % interval
    j = (r + num - 1) % denom
    if j < num:
        return np.int64(0)
    ahead = denom - j
    return ahead if r + ahead < interval else interval - r


@njit(cache=True)
def _event(data, pos, end, row):
    """Decode an event frame's body into ``row`` (type, value, value); returns (pos, known, log end)."""
    kind, pos = _byte(data, pos, end)
    row[1] = kind
    row[2] = 0
    row[3] = 0
    if kind == EV_SYNC_BEEP or kind == EV_DISARM:
        v, pos = _unsigned_vb(data, pos, end)
        row[2] = v
    elif kind == EV_LOGGING_RESUME or kind == EV_FLIGHT_MODE:
        v, pos = _unsigned_vb(data, pos, end)
        row[2] = v
        v, pos = _unsigned_vb(data, pos, end)
        row[3] = v
    elif kind == EV_INFLIGHT_ADJUSTMENT:
        function, pos = _byte(data, pos, end)
        row[2] = function
        if function > 127:  # a raw 32-bit float, kept as its bits
            v = np.int64(0)
            for k in range(4):
                b, pos = _byte(data, pos, end)
                v |= b << (8 * k)
            row[3] = v
        else:
            v, pos = _signed_vb(data, pos, end)
            row[3] = v
    elif kind == EV_LOG_END:
        for k in range(_END_OF_LOG.shape[0]):
            b, pos = _byte(data, pos, end)
            if b != _END_OF_LOG[k]:
                return pos, False, False
        return pos, True, True
    else:
        return pos, False, False
    return pos, True, False


def new_state(start):
    """The decoder's state at byte ``start`` of a log: no history, the stream not yet in step."""
    state = np.zeros(S_SIZE, dtype=np.int64)
    state[S_POS] = start
    state[S_CUR], state[S_PREV], state[S_PREV2] = 0, 1, 2
    state[S_LAST_ITER] = state[S_LAST_TIME] = state[S_LAST_KEPT_TIME] = -1
    return state


@njit(cache=True)
def decode_chunk(data, stop, end, defs, counts, cfg, columns, state, stats, rows, home, values, event_row, main, slow,
                 gps, events):
    """Decode frames from ``state[S_POS]`` until ``stop`` (a frame begun before it is finished) or ``end``.

    Main frames go to ``main`` (float64; column ``j`` is field ``columns[j]``), slow and GPS frames to
    ``slow`` and ``gps`` (the main row they precede, then their fields) and events to ``events`` (main
    row, type, value, value); a table without rows only counts. ``rows`` (5 rows: the main-frame
    history, an S or G frame, an H frame), ``home``, ``values`` and ``event_row`` are scratch the caller
    keeps between calls with ``state`` and ``stats``. Returns a :class:`ChunkEnd` value; on a full
    table ``state[S_POS]`` is the frame that did not fit, decoded again by the next call.
    """
    cur, prev, prev2 = state[S_CUR], state[S_PREV], state[S_PREV2]
    has_prev = state[S_HAS_PREV] != 0
    valid = state[S_VALID] != 0  # the main stream is in step: a P frame may be delivered
    last_iter, last_time, rollover = state[S_LAST_ITER], state[S_LAST_TIME], state[S_ROLLOVER]
    last_kept = state[S_LAST_KEPT_TIME]
    drop_same_time = cfg[CFG_DROP_SAME_TIME] != 0
    n_main = stats[ST_MAIN]
    pos = state[S_POS]
    outcome = _STOP
    while True:
        if pos >= end:
            outcome = _FINISHED
            break
        if pos >= stop:
            break
        mark = _MARKERS[data[pos]]
        if mark < 0:
            valid = False
            stats[ST_GARBAGE] += 1
            pos += 1
            continue
        frame_start = pos
        pos += 1
        skipped = 0
        known = True
        log_end = False
        if mark == EVENT_MARK:
            pos, known, log_end = _event(data, pos, end, event_row)
        else:
            out, p1, p2, predict = cur, prev, prev2, False
            if mark == P_FRAME:
                predict = has_prev
                if last_iter >= 0:
                    skipped = skipped_iterations(last_iter, cfg[CFG_I_INTERVAL], cfg[CFG_P_NUM], cfg[CFG_P_DENOM])
            elif mark != I_FRAME:
                out = 4 if mark == H_FRAME else 3
                p1, p2 = out, out
            home0 = home[cfg[CFG_HOME0]] if cfg[CFG_HOME0] >= 0 else 0
            home1 = home[cfg[CFG_HOME1]] if cfg[CFG_HOME1] >= 0 else 0
            pos = _parse_frame(data, pos, end, mark, defs, counts, rows, out, p1, p2, predict, skipped, cfg,
                               last_time if has_prev else np.int64(-1), home0, home1, values)
        size = pos - frame_start - 1
        complete = pos < end and _MARKERS[data[pos]] >= 0 or pos == end or log_end
        if pos > end or size > MAX_FRAME_BYTES or not complete:
            # corrupt: look for the next frame from the byte after this one's marker
            stats[ST_CORRUPT] += 1
            if pos > end:
                stats[ST_TRUNCATED] += 1
            valid = False
            has_prev = False
            pos = frame_start + 1
            continue
        # no room for what the frame adds: return before anything changes, so the next call decodes it again
        full = _STOP
        if (mark == I_FRAME or mark == P_FRAME) and n_main >= main.shape[0]:
            full = _MAIN_FULL
        elif mark == S_FRAME and 0 < slow.shape[0] <= stats[ST_SLOW]:
            full = _SLOW_FULL
        elif mark == G_FRAME and 0 < gps.shape[0] <= stats[ST_GPS]:
            full = _GPS_FULL
        elif mark == EVENT_MARK and known and 0 < events.shape[0] <= stats[ST_EVENTS]:
            full = _EVENTS_FULL
        if full != _STOP:
            pos = frame_start
            outcome = full
            break
        if mark == I_FRAME or mark == P_FRAME:
            t32 = rows[cur, 1] & 0xFFFFFFFF
            wrapped = last_time >= 0 and t32 < (last_time & 0xFFFFFFFF)
            if wrapped and ((t32 - last_time) & 0xFFFFFFFF) < MAX_TIME_JUMP_US:
                rollover += np.int64(1) << 32  # the 32-bit microsecond clock wrapped
            t = t32 + rollover
            rows[cur, 1] = t
            if mark == P_FRAME and not valid:
                stats[ST_WITHHELD] += 1
                continue
            iteration = rows[cur, 0] & 0xFFFFFFFF
            in_step = last_iter < 0 or (last_iter <= iteration < last_iter + MAX_ITERATION_JUMP
                                        and last_time <= t < last_time + MAX_TIME_JUMP_US)
            if not in_step:
                stats[ST_REJECTED] += 1
                valid = False
                has_prev = False
                continue
            valid = True
            last_iter = iteration
            last_time = t
            if drop_same_time and t <= last_kept:
                stats[ST_SAME_TIME] += 1  # kept as history for the P frames after it, left out of the table
            else:
                for j in range(columns.shape[0]):
                    main[n_main, j] = rows[cur, columns[j]]
                n_main += 1
                last_kept = t
            if mark == I_FRAME:
                stats[ST_I] += 1
                prev = cur
                prev2 = cur
                cur = (cur + 1) % 3
            else:
                stats[ST_P] += 1
                prev2 = prev
                prev = cur
                cur = 3 - prev - prev2 if prev != prev2 else (prev + 1) % 3
            has_prev = True
        elif mark == S_FRAME:
            if slow.shape[0]:
                slow[stats[ST_SLOW], 0] = n_main
                slow[stats[ST_SLOW], 1:] = rows[3, : counts[S_FRAME]]
            stats[ST_SLOW] += 1
        elif mark == G_FRAME:
            if gps.shape[0]:
                gps[stats[ST_GPS], 0] = n_main
                gps[stats[ST_GPS], 1:] = rows[3, : counts[G_FRAME]]
            stats[ST_GPS] += 1
        elif mark == H_FRAME:
            home[:] = rows[4]
            stats[ST_HOME] += 1
        else:
            if not known:
                stats[ST_UNKNOWN_EVENTS] += 1
                continue
            event_row[0] = n_main
            if events.shape[0]:
                events[stats[ST_EVENTS], :] = event_row
            stats[ST_EVENTS] += 1
            if event_row[1] == EV_LOGGING_RESUME:
                last_iter = event_row[2]  # the jump to the resumed iteration and time is expected
                last_time = event_row[3] + rollover
            if log_end:
                stats[ST_LOG_END] = 1
                outcome = _FINISHED
                break
    stats[ST_MAIN] = n_main
    stats[ST_END] = pos
    state[S_POS] = pos
    state[S_CUR], state[S_PREV], state[S_PREV2] = cur, prev, prev2
    state[S_HAS_PREV], state[S_VALID] = 1 if has_prev else 0, 1 if valid else 0
    state[S_LAST_ITER], state[S_LAST_TIME], state[S_ROLLOVER], state[S_LAST_KEPT_TIME] = (last_iter, last_time,
                                                                                            rollover, last_kept)
    return outcome
