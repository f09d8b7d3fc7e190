"""The compiled frame decoder for Betaflight blackbox logs (numba; see :mod:`.blackbox_decode`).

One pass over a log's frame bytes decodes every frame into preallocated int64 tables: main
frames (I and P) into a table whose capacity is an upper bound on their number (the file's
length over the smallest main frame the field definitions allow), slow (S), GPS (G) frames
and events into tables that double when full (rare: a few hundred rows). Nothing is allocated
per frame.

The format and the resynchronisation follow Betaflight's own decoders (blackbox-tools and the
blackbox log viewer): a frame counts only if the byte after it starts another frame (or the log
ends cleanly) and it is at most 256 bytes long; a corrupt frame is dropped, the search for the
next frame starts at the byte after its marker, and main frames are withheld until the next
I frame, since every P frame is a delta on the frames before it. A main frame whose iteration
or time runs backwards, or jumps by 5,000 iterations or 10 s or more, is rejected the same way.
"""

from __future__ import annotations

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
CFG_DATA_VERSION, CFG_MOTOR0, CFG_HOME0, CFG_HOME1, CFG_GPS_TIME, CFG_SIZE = 6, 7, 8, 9, 10, 11
# the statistics vector
(ST_MAIN, ST_I, ST_P, ST_SLOW, ST_GPS, ST_HOME, ST_EVENTS, ST_CORRUPT, ST_REJECTED, ST_WITHHELD, ST_GARBAGE,
 ST_LOG_END, ST_END, ST_TRUNCATED, ST_UNKNOWN_EVENTS, ST_SIZE) = range(16)

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
    i = 0
    while i < n:
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
                rows[out, i] = _predict(defs[kind, 1, i], values[k], rows[prev, i], rows[prev2, i], has_prev, motor0,
                                        last_time, home0, home1, minthrottle, vbatref, motor_low)
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
        v = _predict(predictor, v, rows[prev, i], rows[prev2, i], has_prev, motor0, last_time, home0, home1,
                     minthrottle, vbatref, motor_low)
        # a field is a 32-bit integer: signed or unsigned as its header says
        v &= 0xFFFFFFFF
        if defs[kind, 2, i] and v >= 0x80000000:
            v -= 0x100000000
        rows[out, i] = v
        i += 1
    return pos


@njit(cache=True)
def _should_have_frame(index, cfg):
    return (index % cfg[CFG_I_INTERVAL] + cfg[CFG_P_NUM] - 1) % cfg[CFG_P_DENOM] < cfg[CFG_P_NUM]


@njit(cache=True)
def _grow(table, n):
    """``table`` with room for row ``n``: twice the rows when full (slow, GPS and event tables only)."""
    if n < table.shape[0]:
        return table
    bigger = np.zeros((2 * table.shape[0], table.shape[1]), dtype=np.int64)
    bigger[: table.shape[0]] = table
    return bigger


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


@njit(cache=True)
def decode_frames(data, start, end, defs, counts, cfg, main):
    """Decode the frames in ``data[start:end]``; main frames go to ``main`` (rows enough for all).

    Returns (statistics, slow, gps, events): ``slow`` rows are (main row they precede, fields…),
    ``gps`` rows the same with the G fields, ``events`` rows (main row, type, value, value); only
    their first ``statistics[ST_SLOW]``, ``[ST_GPS]`` and ``[ST_EVENTS]`` rows are filled.
    """
    stats = np.zeros(ST_SIZE, dtype=np.int64)
    # rows 0-2: the main-frame history (current, previous, the one before), 3: S or G frame, 4: H frame
    rows = np.zeros((5, max(counts.max(), 1)), dtype=np.int64)
    home = np.zeros(rows.shape[1], dtype=np.int64)
    values = np.zeros(8, dtype=np.int64)
    slow = np.zeros((16, counts[S_FRAME] + 1), dtype=np.int64)
    gps = np.zeros((16, counts[G_FRAME] + 1), dtype=np.int64)
    events = np.zeros((16, 4), dtype=np.int64)
    event_row = np.zeros(4, dtype=np.int64)
    cur, prev, prev2 = 0, 1, 2
    has_prev = False
    valid = False  # the main stream is in step: a P frame may be delivered
    last_iter = np.int64(-1)
    last_time = np.int64(-1)
    rollover = np.int64(0)
    n_main = 0
    pos = start
    while pos < end:
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
                    index = last_iter + 1
                    while not _should_have_frame(index, cfg):
                        index += 1
                    skipped = index - last_iter - 1
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
            main[n_main, :] = rows[cur, : counts[I_FRAME]]
            n_main += 1
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
            slow = _grow(slow, stats[ST_SLOW])
            slow[stats[ST_SLOW], 0] = n_main
            slow[stats[ST_SLOW], 1:] = rows[3, : counts[S_FRAME]]
            stats[ST_SLOW] += 1
        elif mark == G_FRAME:
            gps = _grow(gps, stats[ST_GPS])
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
            events = _grow(events, stats[ST_EVENTS])
            event_row[0] = n_main
            events[stats[ST_EVENTS], :] = event_row
            stats[ST_EVENTS] += 1
            if event_row[1] == EV_LOGGING_RESUME:
                last_iter = event_row[2]  # the jump to the resumed iteration and time is expected
                last_time = event_row[3] + rollover
            if log_end:
                stats[ST_LOG_END] = 1
                break
    stats[ST_MAIN] = n_main
    stats[ST_END] = pos
    return stats, slow, gps, events
