"""The cases of the fuzz campaign's logs phase (``scripts/fuzz_logs.py``): flight logs made from the real ones.

Each case is a file made from a log in ../shared/data/flight-logs (a zero-argument function gives its bytes, so
that only the cases run are made), the command that reads it, and what must come of it: the names a refusal must
use when the file is bad by construction, the cut group whose samples must not fall, the records that must be
read. The kinds:

- ``bb-number``: every numeric header field of a Betaflight log at 0, -1, a huge number, text, empty and nan;
- ``bb-fields``: main frames of 0 to 10,000 fields, and definition lists one entry short or long;
- ``bb-names``: a field named twice, an empty name, the first two fields swapped or renamed, motor[0] gone;
- ``bb-defs``: encodings, predictors and signedness out of Betaflight's range, huge or not numbers;
- ``bb-cut``: the file cut at every section boundary (the magic line, header lines, the header's end, the first
  frames, inside frames, the end-of-log event, the next log's start);
- ``bb-bomb``: frames that take no bytes, a megabyte of one-byte frames, events, slow and GPS frames, the slowest
  input known (every other byte a marker), a thousand logs, a megabyte header line;
- ``bb-bytes``: random bytes of the frames changed or zeroed;
- ``cf-header``: Crazyflie variables named twice, ``t`` and ``id``, bad types, event counts and ids, versions;
- ``cf-time``: each of the 64 bits of a timestamp flipped, at the first, a middle and the last record;
- ``cf-cut`` and ``cf-values``: Crazyflie files cut at each header boundary and inside records; NaN and inf;
- ``ulog``: ULogs cut, with bytes changed or zeroed, a damaged magic or version.
"""

from __future__ import annotations

import dataclasses
import math
import random
import re
import struct
from collections.abc import Callable
from pathlib import Path

__all__ = ["CHECKED", "DATA", "KINDS", "PRODUCT", "VALUES", "LogCase", "blackbox_cases", "build_cases",
           "crazyflie_cases", "ulog_cases"]

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "flight-logs"
KINDS = ("bb-number", "bb-fields", "bb-names", "bb-defs", "bb-cut", "bb-bomb", "bb-bytes", "cf-header", "cf-time",
         "cf-cut", "cf-values", "ulog")
VALUES = ("0", "-1", "9" * 25, "abc", "", "nan")
# header fields the reader checks, and the integers it allows (the refusal must name the field)
CHECKED = {"I interval": (1, 32767), "minthrottle": (0, 65535), "vbatref": (0, 65535), "Data version": (1, 2),
           "acc_1G": (1, 65535), "motorOutput": (0, 65535), "P interval": (0, 32767)}
PRODUCT = b"H Product:Blackbox flight data recorder by Nicholas Sherlock\n"


@dataclasses.dataclass
class LogCase:
    kind: str
    label: str  # unique: names the case in the report and with --case
    make: Callable[[], bytes]
    command: str = "info"  # info, export, export-stdout, plot, identify
    bad: list[str] = dataclasses.field(default_factory=list)  # names a refusal must use; empty: any clean outcome
    why: str = ""
    log: str = ""  # ":N" for identify, "N" for --index
    group: str = ""  # cuts of one file: samples must not fall as the cut moves later
    position: int = 0
    records: int = -1  # Crazyflie: at least this many records must be read (-1: no check)


def _ints(text: str) -> bool:
    return bool(re.fullmatch(r"\s*-?\d+\s*", text))


def _allowed(name: str, value: str) -> bool:
    """Does the reader accept ``value`` for the checked header field ``name``?"""
    low, high = CHECKED[name]
    if name == "P interval" and "/" in value:
        num, _, den = value.partition("/")
        return _ints(num) and _ints(den) and 1 <= int(num) <= high and 1 <= int(den) <= high
    return all(_ints(v) and low <= int(v) <= high for v in (value.split(",")[:2] if name == "motorOutput"
                                                               else value.split(",")[:1]))


def _header(names: list[str], enc_i: str = "1", enc_p: str = "0", pred_p: str = "1", pred_i: str = "0") -> bytes:
    """A header of main frames named ``names``: I frames of ``enc_i``/``pred_i``, P frames of ``enc_p``/``pred_p``
    after Betaflight's loopIteration (incremented) and time (a straight line)."""
    n = len(names)
    lines = ["Data version:2", "I interval:32", "P interval:1", "Field I name:" + ",".join(names),
             "Field I signed:" + ",".join(["0"] * n), "Field I predictor:" + ",".join([pred_i] * n),
             "Field I encoding:" + ",".join([enc_i] * n),
             "Field P predictor:" + ",".join((["6", "2"] + [pred_p] * (n - 2))[:n]),
             "Field P encoding:" + ",".join((["9", "0"] + [enc_p] * (n - 2))[:n])]
    return PRODUCT + "".join(f"H {x}\n" for x in lines).encode()


def _frames(n: int, count: int) -> bytes:
    """``count`` I frames of ``n`` unsigned fields (iteration and time counting up), each followed by 31 P frames."""
    out = bytearray()
    for k in range(count):
        it, t = 32 * k, 1000 + 32_000 * k
        out += b"I" + _vb(it) + _vb(t) + b"\x00" * max(n - 2, 0)
        out += (b"P" + b"\x02" + b"\x00" * max(n - 2, 0)) * 31  # time +1 µs on the straight line, the rest held
    return bytes(out)


def _vb(value: int) -> bytes:
    out = bytearray()
    while True:
        byte = value & 0x7F
        value >>= 7
        out.append(byte | (0x80 if value else 0))
        if not value:
            return bytes(out)


def _replace_value(data: bytes, name: str, value: str) -> bytes:
    return re.sub(rb"(?m)^H " + re.escape(name.encode()) + rb":[^\n]*$", b"H " + name.encode() + b":" +
                  value.encode(), data)


def _replace_list_item(data: bytes, key: str, index: int, value: str) -> bytes:
    def sub(match: re.Match[bytes]) -> bytes:
        items = match.group(2).split(b",")
        items[index % len(items)] = value.encode()
        return match.group(1) + b",".join(items)

    return re.sub(rb"(?m)^(H " + re.escape(key.encode()) + rb":)([^\n]*)$", sub, data)


def blackbox_cases(data: dict[str, bytes]) -> list[LogCase]:
    zeez, roma = data["zeez"], data["roma"]
    second = zeez.index(PRODUCT, 1)
    head = zeez[:zeez.index(b"\nI", 0) + 1]
    cases: list[LogCase] = []
    numeric = [m.group(1).decode() for m in re.finditer(rb"(?m)^H ([^:\n]+):\s*(-?\d+(\.\d+)?(,\s*-?\d+(\.\d+)?)*|"
                                                        rb"0x[0-9a-fA-F]+)$", head)
               if not m.group(1).startswith(b"Field ")]
    for i, name in enumerate(numeric):
        for value in VALUES:
            command = ("export", "plot", "info", "info", "info", "info")[(i + VALUES.index(value)) % 6]
            bad = [name] if name in CHECKED and not _allowed(name, value) else []
            cases.append(LogCase("bb-number", f"bb-number:{name}={value[:8]}",
                                 lambda name=name, value=value: _replace_value(zeez, name, value), command,
                                 bad, f"H {name}:{value}" if bad else "", log="1" if command == "plot" else ""))
    for name, value in (("acc_1G", "0"), ("acc_1G", "inf"), ("motorOutput", "0,0"), ("acc_lpf_hz", "abc")):
        cases.append(LogCase("bb-number", f"bb-number:identify:{name}={value}",
                             lambda name=name, value=value: _replace_value(zeez, name, value), "identify",
                             [name] if name in CHECKED and not _allowed(name, value) else [], log=":2"))
    for n in (0, 1, 2, 3, 16, 35, 64, 127, 128, 129, 200, 1000, 10_000):
        names = (["loopIteration", "time"] + [f"f{k}" for k in range(2, n)])[:n]
        bad = ["Field I name"] if n > 128 else (["first fields"] if n < 2 else [])
        cases.append(LogCase("bb-fields", f"bb-fields:{n}", lambda names=names, n=n: _header(names) + _frames(n, 300),
                             bad=bad, why=f"{n} fields" if bad else ""))
    for key in ("Field I encoding", "Field I predictor", "Field P encoding", "Field P predictor", "Field I signed"):
        for extra in (",0", ""):
            def make(key: str = key, extra: str = extra) -> bytes:
                line = re.search(rb"(?m)^H " + key.encode() + rb":([^\n]*)$", zeez)
                assert line is not None
                items = line.group(1) + extra.encode() if extra else line.group(1).rsplit(b",", 1)[0]
                return zeez.replace(line.group(0), b"H " + key.encode() + b":" + items)
            cases.append(LogCase("bb-fields", f"bb-fields:{key}{'+1' if extra else '-1'}", make, bad=[key],
                                 why=f"{key} one entry {'long' if extra else 'short'}"))
    for k in (1, 2, 5, 16, 25, 31, 34):
        cases.append(LogCase("bb-names", f"bb-names:twice{k}",
                             lambda k=k: _replace_list_item(zeez, "Field I name", k, "axisP[0]" if k != 2 else "time"),
                             bad=["Field I name", "first fields"], why="a name twice"))
    for label, change in (("empty", (5, "")), ("swap", (0, "time")), ("Time", (1, "Time")), ("long", (7, "x" * 10_000)),
                          ("unicode", (8, "é飞")), ("no-motor0", (31, "motorX")), ("spaces", (9, "  axisD[1]  "))):
        bad = ["first fields"] if label in ("swap", "Time") else (["motor[0]"] if label == "no-motor0" else [])
        if label == "swap":
            bad = ["Field I name", "first fields"]
        cases.append(LogCase("bb-names", f"bb-names:{label}",
                             lambda change=change: _replace_list_item(zeez, "Field I name", *change), bad=bad,
                             why=label if bad else ""))
    for k in (0, 1, 5, 21, 31):
        for key, values in (("Field I encoding", ("2", "4", "5", "11", "255", "-1", "9" * 25, "x", "")),
                            ("Field P encoding", ("2", "4", "5", "11", "255", "-1", "9" * 25, "x", "")),
                            ("Field I predictor", ("12", "13", "255", "256", "-1", "9" * 25, "x")),
                            ("Field P predictor", ("12", "13", "255", "256", "-1", "9" * 25, "x")),
                            ("Field I signed", ("2", "-1", "x"))):
            for value in values:
                cases.append(LogCase("bb-defs", f"bb-defs:{key}[{k}]={value[:8]}",
                                     lambda key=key, k=k, value=value: _replace_list_item(zeez, key, k, value),
                                     bad=[key], why=f"{key} entry {k} {value[:8]!r}"))
    cases += _cut_cases("zeez", zeez, [0, second]) + _cut_cases("roma", roma, _starts(roma))
    cases += _bombs(zeez, head)
    frames_at = len(head)
    for k in range(24):
        def make(k: int = k) -> bytes:
            local = random.Random(1000 + k)
            out = bytearray(zeez)
            if k % 3 == 0:
                at = local.randrange(frames_at, len(out) - 5000)
                out[at: at + local.choice([16, 300, 4000])] = bytes(1)
            else:
                for _ in range(local.choice([1, 10, 200])):
                    out[local.randrange(frames_at, len(out))] = local.randrange(256)
            return bytes(out)
        cases.append(LogCase("bb-bytes", f"bb-bytes:{k}", make, ("info", "export", "info", "plot")[k % 4],
                             log="1" if k % 4 == 3 else ""))
    return cases


def _starts(data: bytes) -> list[int]:
    return [m.start() for m in re.finditer(re.escape(PRODUCT), data)]


def _cut_cases(name: str, data: bytes, starts: list[int]) -> list[LogCase]:
    """Cuts at each log's start and magic line, at header lines, the header's end, its first frames, through its
    frames and at its end-of-log event; all in one group (samples must not fall as the cut moves later)."""
    points = {len(data)}
    ends = [*starts[1:], len(data)]
    for start, end in zip(starts, ends, strict=True):
        lines = [m.end() for m in re.finditer(rb"\n", data[start: data.index(b"\nI", start) + 1])]
        header = start + lines[-1]
        points |= {start, start + 1, start + len(PRODUCT) - 1, start + len(PRODUCT)}
        points |= {start + lines[i] for i in range(0, len(lines), 9)} | {header - 1, header, header + 1}
        points |= {header + k for k in (10, 37, 38, 60, 200)} | {end - k for k in (1, 6, 12, 13)}
        points |= {header + (end - header) * k // 7 for k in range(1, 7)}
    return [LogCase("bb-cut", f"bb-cut:{name}@{p}", lambda p=p: data[:p], group=f"bb-cut:{name}", position=p)
            for p in sorted(q for q in points if 0 < q <= len(data))]


def _bombs(zeez: bytes, head: bytes) -> list[LogCase]:
    many = ["loopIteration", "time"] + [f"f{k}" for k in range(2, 128)]
    from_reader = ["loopIteration", "time", *(f"gyroADC[{i}]" for i in range(3)), *(f"motor[{i}]" for i in range(4)),
                   *(f"accSmooth[{i}]" for i in range(3)), *(f"setpoint[{i}]" for i in range(4))]
    increment = _header(["loopIteration", "time"] + [f"f{k}" for k in range(2, 102)], "1", "9", "6", "6")
    gps = b"H Field G name:time,GPS_coord[0],GPS_coord[1]\nH Field G signed:0,1,1\nH Field G predictor:0,0,0\n" \
          b"H Field G encoding:9,9,9\n"
    one_log = zeez[: _starts(zeez)[1]]
    return [
        LogCase("bb-bomb", "bb-bomb:increment", lambda: increment + b"I" * 1_000_000),
        LogCase("bb-bomb", "bb-bomb:increment-plot", lambda: increment + b"I" * 1_000_000, "plot"),
        LogCase("bb-bomb", "bb-bomb:no-bytes", lambda: _header(from_reader, "9", "9", "6", "6") + b"I" + b"P" * 200_000,
                bad=["times the log"], why="frames of no bytes"),
        LogCase("bb-bomb", "bb-bomb:slowest", lambda: _header(many, "0", "0") + b"I\xff" * 500_000),
        LogCase("bb-bomb", "bb-bomb:tag8", lambda: _header(many, "6", "6") + b"P\xff" * 500_000),
        LogCase("bb-bomb", "bb-bomb:events", lambda: head + b"E" * 1_000_000),
        LogCase("bb-bomb", "bb-bomb:beeps", lambda: head + b"E\x00\x00" * 333_000, "export"),
        LogCase("bb-bomb", "bb-bomb:slow", lambda: head + b"S\x00\x00\x00" * 250_000),
        LogCase("bb-bomb", "bb-bomb:gps", lambda: head.replace(b"H Firmware type", gps + b"H Firmware type") +
                b"G" * 1_000_000),
        LogCase("bb-bomb", "bb-bomb:thousand-logs", lambda: one_log * 1000),
        LogCase("bb-bomb", "bb-bomb:megabyte-line", lambda: PRODUCT + b"H Craft name:" + b"x" * 1_000_000 + b"\n" +
                head[len(PRODUCT):] + zeez[len(head): len(head) + 20_000]),
        LogCase("bb-bomb", "bb-bomb:header-lines", lambda: PRODUCT + b"H a:1\n" * 200_000 + head[len(PRODUCT):] +
                zeez[len(head): len(head) + 20_000]),
        LogCase("bb-bomb", "bb-bomb:frames-of-I", lambda: head + b"I" * 1_000_000, "plot", log="1"),
    ]


def _cf_header(events: list[tuple[int, bytes, list[bytes]]], version: int = 2, count: int | None = None) -> bytes:
    out = b"\xbc" + struct.pack("<HH", version, len(events) if count is None else count)
    for eid, name, variables in events:
        out += struct.pack("<H", eid) + name + b"\x00" + struct.pack("<H", len(variables))
        out += b"".join(v + b"\x00" for v in variables)
    return out


def crazyflie_cases(cf: bytes) -> list[LogCase]:
    start = cf.index(b"motor.m4(I)\x00") + len(b"motor.m4(I)\x00")
    head, body = cf[:start], cf[start:]
    n = len(body) // 50
    variables = re.findall(rb"[a-z0-9.]+\([A-Za-z]\)", head)
    count_at = head.index(b"\x00", 7) + 1  # the variable count, after the event's name
    cases: list[LogCase] = []
    for label, header, bad in (
            ("twice", head.replace(b"acc.y(f)", b"acc.x(f)"), ["acc.x(f)"]),
            ("t", head.replace(b"acc.y(f)", b"t(f)"), []), ("id", head.replace(b"acc.y(f)", b"id(f)"), []),
            ("(event id)", head.replace(b"acc.y(f)", b"(event id)(f)"), ["variable"]),
            ("no-type", head.replace(b"acc.y(f)", b"acc.y"), ["variable"]),
            ("type-e", head.replace(b"acc.y(f)", b"acc.y(e)"), ["variable"]),
            ("type-x", head.replace(b"acc.y(f)", b"acc.y(x)"), ["variable"]),
            ("empty-type", head.replace(b"acc.y(f)", b"acc.y()"), ["variable"]),
            ("double", head.replace(b"acc.y(f)", b"acc.y(d)"), []),
            ("version1", _cf_header([(0xFFFF, b"fixedFrequency", variables)], version=1), ["version"]),
            ("count0", _cf_header([], count=0), ["event types"]),
            ("count65", _cf_header([(0xFFFF, b"fixedFrequency", variables)], count=65), ["event types"]),
            ("two-events", _cf_header([(0xFFFF, b"fixedFrequency", variables), (7, b"other", [b"x.y(B)"])]), []),
            ("same-id", _cf_header([(0xFFFF, b"fixedFrequency", variables), (0xFFFF, b"again", [])]), ["event id"]),
            ("no-variables", _cf_header([(0xFFFF, b"fixedFrequency", [])]), []),
            ("vars-65535", head[:count_at] + struct.pack("<H", 65535) + head[count_at + 2:], []),
            ("latin1", head.replace(b"acc.y(f)", b"acc.\xe9(f)"), ["not text"]),
            ("no-nul", head[:-1], [])):
        cases.append(LogCase("cf-header", f"cf-header:{label}", lambda header=header: header + body,
                             bad=bad, why=label if bad else ""))
    for record in (0, n // 2, n - 1):
        for bit in range(64):
            def make(record: int = record, bit: int = bit) -> bytes:
                out = bytearray(cf)
                out[start + 50 * record + 2 + bit // 8] ^= 1 << (bit % 8)
                return bytes(out)
            cases.append(LogCase("cf-time", f"cf-time:{record}:{bit}", make, records=n - 1))
    points = [1, 3, 5, 6, 7, 20, count_at, count_at + 2]
    points += [m.end() + 1 for m in re.finditer(rb"\([A-Za-z]\)", head)]
    points += [start + k for k in (0, 1, 2, 9, 10, 49, 50, 51, 5000, 25_007)] + [len(cf) - 1, len(cf)]
    for p in sorted(set(points)):
        whole = max((p - start) // 50, 0) if p >= start else -1
        cases.append(LogCase("cf-cut", f"cf-cut:@{p}", lambda p=p: cf[:p], records=whole if whole > 0 else -1))
    for label, column, value, command in (("nan-acc", 10, math.nan, "info"), ("inf-gyro", 22, math.inf, "export"),
                                          ("-inf-acc", 18, -math.inf, "plot"), ("nan-acc-identify", 18, math.nan,
                                                                                 "identify"),
                                          ("half-nan", 14, math.nan, "identify"), ("big-acc", 18, 1e30, "identify")):
        def make(column: int = column, value: float = value, label: str = label) -> bytes:
            out = bytearray(cf)
            rows = range(n // 2) if label == "half-nan" else range(n)
            packed = struct.pack("<f", value)
            for r in rows:
                at = start + 50 * r + column
                out[at: at + 4] = packed
            return bytes(out)
        cases.append(LogCase("cf-values", f"cf-values:{label}", make, command))
    return cases


def ulog_cases(ulog: bytes) -> list[LogCase]:
    cases: list[LogCase] = []
    for k, p in enumerate((7, 16, 100, 1000, 5000, 20_000, len(ulog) // 10, len(ulog) // 2, len(ulog) - 1)):
        cases.append(LogCase("ulog", f"ulog:cut@{p}", lambda p=p: ulog[:p], ("info", "export-stdout", "plot")[k % 3]))
    for k in range(24):
        def make(k: int = k) -> bytes:
            local = random.Random(2000 + k)
            out = bytearray(ulog)
            lo = 16 if k % 2 else 20_000  # the definitions, or the data
            for _ in range(local.choice([1, 5, 40])):
                out[local.randrange(lo, len(out) if k % 2 == 0 else 20_000)] = local.randrange(256)
            return bytes(out)
        cases.append(LogCase("ulog", f"ulog:bytes{k}", make, ("info", "export-stdout", "info", "plot")[k % 4]))
    for k, (at, size) in enumerate(((200_000, 60_000), (16, 2000), (len(ulog) - 100_000, 100_000))):
        cases.append(LogCase("ulog", f"ulog:zeroed@{at}", lambda at=at, size=size: ulog[:at] + bytes(size) +
                             ulog[at + size:], ("info", "export-stdout", "identify")[k]))
    for label, data in (("magic", b"ULog\x02" + ulog[5:]), ("version", ulog[:7] + b"\xff" + ulog[8:])):
        cases.append(LogCase("ulog", f"ulog:{label}", lambda data=data: data))
    return cases


def build_cases() -> list[LogCase]:
    data = {"zeez": (DATA / "betaflight" / "zeezf7-short.bbl").read_bytes(),
            "roma": (DATA / "betaflight" / "diatone-roma-f5.bbl").read_bytes()}
    return (blackbox_cases(data) + crazyflie_cases((DATA / "crazyflie" / "log16").read_bytes())
            + ulog_cases((DATA / "px4" / "auav-x21-quad.ulg").read_bytes()))


def main(argv: list[str] | None = None) -> int:
    """List the cases, kind by kind: ``python scripts/fuzz_log_cases.py [--labels]`` (needs ../shared/data)."""
    import argparse
    from collections import Counter

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--labels", action="store_true", help="every case's label and command, not only the counts")
    args = parser.parse_args(argv)
    if not DATA.is_dir():
        print(f"the real flight logs are not here ({DATA} is absent)")
        return 2
    cases = build_cases()
    if args.labels:
        for case in cases:
            print(f"{case.kind:10s} {case.command:14s} {case.label}")
    counts = Counter(case.kind for case in cases)
    print(", ".join(f"{kind} {counts.get(kind, 0)}" for kind in KINDS) + f"; {len(cases)} cases")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
