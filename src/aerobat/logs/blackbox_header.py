"""A blackbox log's header, checked: the field definitions and the numbers the frame decoder uses.

Every number the decoder (:mod:`.blackbox_kernel`) or the reader (:mod:`.betaflight`) takes from
an ``H name:value`` line is checked against the range Betaflight can write, before any of it
reaches a fixed-width table: a value outside is refused with one line naming the file, the log,
the header field, what it holds and what is allowed (a :class:`~aerobat.errors.ConfigError`).
The ranges come from Betaflight's ``blackbox.c`` (the types it keeps them in and how it computes
them) and from its own decoder, blackbox-tools (``parser.h``: ``FLIGHT_LOG_MAX_FIELDS 128``).
"""

from __future__ import annotations

import numpy as np

from aerobat.errors import ConfigError

__all__ = ["DEFAULTS", "ENCODINGS", "HOME_COORD", "HOME_COORD_1", "INCREMENT", "KINDS", "MAX_DECODED_BYTES_PER_BYTE",
           "MAX_FIELDS", "MAX_INTERVAL", "MOTOR_0", "PREDICTORS", "decoder_config", "frame_defs",
           "header_error", "header_int", "min_frame_bytes", "one_g"]

KINDS = "IPSGH"
ENCODINGS = {0: "signed VB", 1: "unsigned VB", 3: "negative 14-bit", 6: "tag8_8svb", 7: "tag2_3s32",
             8: "tag8_4s16", 9: "null", 10: "tag2_3svariable"}
_GROUP = {6: 1, 7: 3, 8: 4, 10: 3}  # encodings that write several fields together: fields per group (6: up to 8)
PREDICTORS = range(12)
MOTOR_0, HOME_COORD, HOME_COORD_1, INCREMENT = 5, 7, 256, 6
# Betaflight's decoders' defaults for headers a log leaves out
DEFAULTS = {"I interval": 32, "minthrottle": 1150, "vbatref": 4095, "Data version": 1, "acc_1G": 2048}

#: Fields per frame: Betaflight's own decoder (blackbox-tools, FLIGHT_LOG_MAX_FIELDS) reads at most 128;
#: Betaflight 4 logs 35-110 (the shared logs: 34 and 35).
MAX_FIELDS = 128
#: Largest I or P interval [loop iterations]: blackbox.c keeps the I interval in an int16_t (it writes
#: 32000 / the PID loop time in µs: 128 at 4 kHz, 256 at 8 kHz, 1032 at the 32 kHz of Betaflight 3) and the
#: P interval is at most the I interval (1 << sample_rate, 0 when that would exceed it).
MAX_INTERVAL = 32767
#: A decoded main frame takes 8 bytes (float64) for each field kept: a log whose frames decode to more than 16
#: times its bytes (and 1 MB) is refused (:func:`.blackbox_decode.decode_blackbox`). The shared logs decode to
#: 9-10 times theirs (34-35 fields in 28 bytes a frame on average); 16 times is a frame of 31 fields in 16 bytes
#: all through a log, while a file of frames without bytes (the increment predictor) decoded to 800 times its size.
MAX_DECODED_BYTES_PER_BYTE = 16
_UINT16 = (0, 65535)


def header_error(where: str, name: str, raw: str, allowed: str, detail: str = "") -> ConfigError:
    """The one-line refusal of header field ``name`` holding ``raw`` (``detail``: which part is wrong): what is
    allowed."""
    shown = raw if len(raw) <= 40 else raw[:40] + "…"
    return ConfigError(f"{where}: header field 'H {name}' is {shown!r}{f' ({detail})' if detail else ''}: "
                       f"allowed {allowed}")


def _integer(where: str, name: str, text: str, low: int, high: int, allowed: str) -> int:
    try:
        value = int(text.strip())
    except ValueError:
        raise header_error(where, name, text, allowed) from None
    if not low <= value <= high:
        raise header_error(where, name, text, allowed)
    return value


def header_int(headers: dict[str, str], name: str, where: str, low: int, high: int, what: str = "") -> int:
    """The integer in header ``name`` (its first one, for a comma-separated list), within ``low``–``high``.

    A header the log leaves out gives Betaflight's decoders' default (:data:`DEFAULTS`).
    """
    raw = headers.get(name)
    if raw is None:
        return DEFAULTS[name]
    allowed = f"an integer from {low} to {high}" + (f" ({what})" if what else "")
    return _integer(where, name, raw.split(",")[0], low, high, allowed)


def _ints(headers: dict[str, str], name: str, where: str, fields: list[str], allowed_values: range | dict[int, str],
          allowed: str) -> list[int]:
    """Header ``name`` as a comma-separated list of integers, each one of ``allowed_values`` (one per field of
    ``fields``, which name the wrong one)."""
    raw = headers[name]
    values = []
    for i, item in enumerate(raw.split(",")):
        try:
            value = int(item.strip())
        except ValueError:
            value = None
        if value is None or value not in allowed_values:
            field = f"field {fields[i]!r}" if i < len(fields) else f"entry {i + 1}"
            shown = item.strip() if len(item.strip()) <= 20 else item.strip()[:20] + "…"
            raise header_error(where, name, raw, allowed, f"{field}: {shown!r}")
        values.append(value)
    return values


def one_g(headers: dict[str, str], where: str) -> float:
    """The accelerometer's reading at 1 g (``acc_1G``; Betaflight writes the sensor's uint16 scale)."""
    return float(header_int(headers, "acc_1G", where, 1, 65535, "the accelerometer's reading at 1 g"))


def frame_defs(headers: dict[str, str], where: str) -> tuple[dict[str, list[str]], np.ndarray, np.ndarray]:
    """The field names per frame kind and the (kind, encoding/predictor/signed, field) table, checked."""
    names: dict[str, list[str]] = {}
    for kind in "ISGH":
        key = f"Field {kind} name"
        if key in headers:
            names[kind] = [n.strip() for n in headers[key].split(",")]
            if len(names[kind]) > MAX_FIELDS:
                raise header_error(where, key, headers[key], f"at most {MAX_FIELDS} fields (the {len(names[kind])} "
                                   "named are more than Betaflight's decoder reads; Betaflight logs 35-110)")
            seen: set[str] = set()
            for field in names[kind]:
                if field in seen:
                    raise header_error(where, key, headers[key], f"each name once ({field!r} is named twice)")
                seen.add(field)
    if "I" not in names:
        raise ConfigError(f"{where}: the header has no field definitions (a damaged or truncated header)")
    names["P"] = names["I"]
    if names["I"][:2] != ["loopIteration", "time"]:
        raise ConfigError(f"{where}: the main frame's first fields are {names['I'][:2]}, expected "
                          "['loopIteration', 'time'] (not a Betaflight log)")
    width = max(len(v) for v in names.values())
    defs = np.zeros((len(KINDS), 3, width), dtype=np.int64)
    counts = np.zeros(len(KINDS), dtype=np.int64)
    choices: dict[str, tuple[range | dict[int, str], str]] = {
        "encoding": (ENCODINGS, "a list of encodings, each one of " + ", ".join(f"{c} ({s})"
                                                                              for c, s in ENCODINGS.items())),
        "predictor": (PREDICTORS, "a list of predictors, each from 0 to 11 (Betaflight's)"),
        "signed": (range(2), "a list of 0 (unsigned) and 1 (signed)"),
    }
    for k, kind in enumerate(KINDS):
        if kind not in names:
            continue
        n = len(names[kind])
        counts[k] = n
        for row, prop in enumerate(("encoding", "predictor", "signed")):
            key = f"Field {kind} {prop}"
            source = f"Field {'I' if prop == 'signed' and kind == 'P' else kind} {prop}"
            if source not in headers:
                if prop == "signed":
                    continue
                raise ConfigError(f"{where}: the header has no 'H {key}' line (a damaged or truncated header)")
            values = _ints(headers, source, where, names[kind], *choices[prop])
            if len(values) != n:
                raise header_error(where, source, headers[source],
                                   f"one entry for each of the {n} fields of the {kind} frame ({len(values)} given)")
            defs[k, row, :n] = values
        # GPS coordinates come in pairs with one predictor id: the second is the home's second coordinate
        for i in range(1, n):
            if defs[k, 1, i - 1] == HOME_COORD and defs[k, 1, i] == HOME_COORD:
                defs[k, 1, i] = HOME_COORD_1
    return names, defs, counts


def min_frame_bytes(defs: np.ndarray, counts: np.ndarray, k: int) -> int:
    """The fewest bytes a frame of kind ``k`` can take, its marker included."""
    size, i, n = 1, 0, int(counts[k])
    while i < n:
        enc, pred = int(defs[k, 0, i]), int(defs[k, 1, i])
        if pred == INCREMENT or enc == 9:
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


def _p_interval(headers: dict[str, str], where: str) -> tuple[int, int]:
    """(num, denom): a P frame is logged at iterations whose index within the I interval, plus num - 1, modulo
    denom is below num. Betaflight 4 writes ``N`` (one P frame every N iterations; 0: I frames only), older
    firmware ``num/denom``."""
    raw = headers.get("P interval", "1").strip()
    num, slash, denom = raw.partition("/")
    top = MAX_INTERVAL
    if slash:
        allowed = f"N/M with N and M integers from 1 to {top}"
        return (_integer(where, "P interval", num, 1, top, allowed),
                _integer(where, "P interval", denom, 1, top, allowed))
    every = _integer(where, "P interval", raw, 0, top,
                     f"N/M, or N: an integer from 0 to {top} (one P frame every N iterations; 0: I frames only)")
    return 1, max(every, 1)


def decoder_config(headers: dict[str, str], names: dict[str, list[str]], defs: np.ndarray, where: str) -> np.ndarray:
    """The kernel's configuration vector (:data:`.blackbox_kernel.CFG_SIZE` entries) from the checked header."""
    from aerobat.logs import blackbox_kernel as k

    cfg = np.zeros(k.CFG_SIZE, dtype=np.int64)
    cfg[k.CFG_I_INTERVAL] = header_int(headers, "I interval", where, 1, MAX_INTERVAL,
                                       "loop iterations between I frames; Betaflight writes 32000 / its PID loop "
                                       "time in µs, 256 at 8 kHz")
    cfg[k.CFG_P_NUM], cfg[k.CFG_P_DENOM] = _p_interval(headers, where)
    cfg[k.CFG_MINTHROTTLE] = header_int(headers, "minthrottle", where, *_UINT16)
    cfg[k.CFG_VBATREF] = header_int(headers, "vbatref", where, *_UINT16)
    if "motorOutput" in headers:
        raw = headers["motorOutput"]
        allowed = "one or two integers from 0 to 65535 (the motor output range, low first)"
        parts = raw.split(",")
        if len(parts) > 2:
            raise header_error(where, "motorOutput", raw, allowed)
        low = [_integer(where, "motorOutput", p, *_UINT16, allowed) for p in parts][0]
        cfg[k.CFG_MOTOR_LOW] = low
    else:
        cfg[k.CFG_MOTOR_LOW] = cfg[k.CFG_MINTHROTTLE]
    cfg[k.CFG_DATA_VERSION] = header_int(headers, "Data version", where, 1, 2,
                                         "the blackbox format versions Betaflight has written")
    main = names["I"]
    cfg[k.CFG_MOTOR0] = main.index("motor[0]") if "motor[0]" in main else -1
    if cfg[k.CFG_MOTOR0] < 0 and (defs[:2, 1] == MOTOR_0).any():
        raise ConfigError(f"{where}: a field is predicted from motor[0], but the log has no motor[0] field")
    home = names.get("H", [])
    cfg[k.CFG_HOME0] = home.index("GPS_home[0]") if "GPS_home[0]" in home else -1
    cfg[k.CFG_HOME1] = home.index("GPS_home[1]") if "GPS_home[1]" in home else -1
    return cfg
