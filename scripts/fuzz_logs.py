"""The logs phase of the fuzz campaign (issue 45): crafted flight logs, each read by one command in its own process.

Called by ``scripts/fuzz_campaign.py`` as ``run_logs_phase(fz, campaign, fx, n)`` (``n`` < 0: every case, else a
seeded sample of ``n`` spread over the kinds); ``python scripts/fuzz_logs.py`` runs this phase alone. The cases
are made from the real logs in ../shared/data/flight-logs, not only mutated at random:

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

Each case runs one command (``log info --json`` mostly; ``log export``, ``log plot``, ``identify --log``) as a
fresh ``python -m aerobat`` process, and is judged as the campaign judges (``fz.judge``: exit 0, 2 with one
``aerobat: error:`` line that names the header field where the case is bad by construction, or 1; anything else,
a traceback or exit 70 is *internal*). Besides:

- *hangs*: not finished within its budget (it is then sent SIGINT, as Ctrl-C would; one that ignores it too is
  killed after 10 s);
- *non_json*: a ``--json`` output that ``json.loads`` with ``parse_constant`` refusing NaN and Infinity does not
  read, or a CSV on standard output that does not start with its header line;
- *data_loss*: the input file changed; a file cut later read with fewer samples than one cut earlier; a Crazyflie
  file with one damaged timestamp losing more than one record, or cut after whole records losing one of them;
- *peak_memory*: each process's peak resident memory (``os.wait4``'s ``ru_maxrss``, taken by a small launcher
  between the campaign and the command) against 300 MB + 20 times the file's size; the worst case and every case
  over it.

Each finding carries ``reproduce``: the command that rebuilds its file (kept with ``--keep``) and runs it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import random
import re
import shlex
import shutil
import signal
import struct
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "flight-logs"
KINDS = ("bb-number", "bb-fields", "bb-names", "bb-defs", "bb-cut", "bb-bomb", "bb-bytes", "cf-header", "cf-time",
         "cf-cut", "cf-values", "ulog")
VALUES = ("0", "-1", "9" * 25, "abc", "", "nan")
# header fields the reader checks, and the integers it allows (the refusal must name the field)
CHECKED = {"I interval": (1, 32767), "minthrottle": (0, 65535), "vbatref": (0, 65535), "Data version": (1, 2),
           "acc_1G": (1, 65535), "motorOutput": (0, 65535), "P interval": (0, 32767)}
BUDGET_S = {"info": 30.0, "export": 30.0, "export-stdout": 30.0, "plot": 60.0, "identify": 120.0}
MEMORY_MB, MEMORY_PER_BYTE = 300.0, 20.0
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
        LogCase("bb-bomb", "bb-bomb:no-bytes", lambda: _header(from_reader, "9", "9", "6", "6") + b"I" * 100_000,
                bad=["main frame of"], why="frames of no bytes"),
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


def _no_constant(text: str) -> Any:
    raise ValueError(f"{text} is not JSON")


def _argv(case: LogCase, path: Path, work: Path) -> list[str]:
    file = str(path)
    index = ["--index", case.log] if case.log and case.command != "identify" else []
    return {"info": ["log", "info", file, *index, "--json"],
            "export": ["log", "export", file, *index, "--out", str(work / "csv"), "--json"],
            "export-stdout": ["log", "export", file, *index],
            "plot": ["log", "plot", file, *index, "--out", str(work / "figures"), "--json"],
            "identify": ["identify", "--log", file + case.log, "--output", str(work / "v.toml"), "--json"],
            }[case.command]


# Runs one command and writes its pid, then its exit status and peak memory [kB]. A process's peak counts what it
# held before exec, and a forked child holds its parent's pages: this small process (python -S) stands between
# the campaign's (hundreds of MB) and the command measured.
LAUNCHER = """
import os, sys
pid = os.posix_spawn(sys.argv[2], sys.argv[2:], os.environ)
with open(sys.argv[1], "w") as f:
    f.write(f"{pid}\\n")
_, status, usage = os.wait4(pid, 0)
with open(sys.argv[1], "a") as f:
    f.write(f"{os.waitstatus_to_exitcode(status)} {usage.ru_maxrss}\\n")
"""


@dataclasses.dataclass
class _Running:
    case: LogCase
    index: int
    path: Path
    work: Path
    argv: list[str]
    process: subprocess.Popen[bytes]
    started: float
    digest: str
    interrupted: float = 0.0
    killed: bool = False


def _launch(case: LogCase, index: int, root: Path, env: dict[str, str]) -> _Running:
    work = root / f"c{index}"
    work.mkdir(parents=True, exist_ok=True)
    path = work / ("log.ulg" if case.kind == "ulog" else "log" if case.kind.startswith("cf") else "log.bbl")
    data = case.make()
    path.write_bytes(data)
    argv = _argv(case, path, work)
    with open(work / "out", "wb") as out, open(work / "err", "wb") as err:
        process = subprocess.Popen([sys.executable, "-S", "-c", LAUNCHER, str(work / "status"), sys.executable, "-m",
                                    "aerobat", *argv], stdout=out, stderr=err, stdin=subprocess.DEVNULL, cwd=work,
                                   env=env, start_new_session=True)
    return _Running(case, index, path, work, argv, process, time.perf_counter(), hashlib.sha256(data).hexdigest())


def _samples(document: Any) -> int:
    """Gyro (else any) samples over the logs of a ``log info --json`` document."""
    total = 0
    for log in document.get("logs", []):
        signals = log.get("signals", {})
        series = signals.get("gyro") or next(iter(signals.values()), {"samples": 0})
        total += int(series["samples"])
    return total


def run_logs_phase(fz: Any, campaign: Any, fx: Any, n: int, *, workers: int = 2, only: str | None = None,
                   keep: bool = False) -> None:
    """Run the crafted-log cases (all if ``n`` < 0, else a seeded sample of ``n`` spread over the kinds), ``workers``
    processes at a time, into ``campaign.report["logs"]``.

    ``fx`` (the campaign's fixtures) is not needed: no log command opens the store. ``only``: the cases whose
    label holds it (or one of its comma-separated parts); ``keep``: leave each case's folder (its file, outputs
    and streams) under ``campaign.root / "logs"``.
    """
    import aerobat

    report: dict[str, Any] = {"requested": n, "kinds": list(KINDS), "cases": 0, "counts": Counter(), "by_kind": {},
                              "internal": [], "hangs": [], "data_loss": [], "non_json": [],
                              "peak_memory": {"worst_mb": 0.0, "bound_mb": 0.0, "worst_fraction_of_bound": 0.0,
                                              "case": None, "over_bound": [], "highest": []}}
    campaign.report["logs"] = report
    if not DATA.is_dir():
        report["skipped"] = f"the real flight logs are not here ({DATA} is absent)"
        campaign.say(f"fuzz: logs phase skipped: {report['skipped']}")
        return
    started = time.perf_counter()
    cases = [c for c in build_cases() if only is None or any(part in c.label for part in only.split(","))]
    if 0 <= n < len(cases):
        rng = random.Random(campaign.seed + 45)
        by_kind = {k: [c for c in cases if c.kind == k] for k in KINDS}
        picked: list[LogCase] = []
        while len(picked) < n:
            for kind in KINDS:
                if by_kind[kind] and len(picked) < n:
                    picked.append(by_kind[kind].pop(rng.randrange(len(by_kind[kind]))))
        cases = picked
    report["cases"] = len(cases)
    root = campaign.root / "logs"
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONPATH": os.pathsep.join(
        [str(Path(aerobat.__file__).resolve().parents[1]), *filter(None, [os.environ.get("PYTHONPATH")])])}
    cuts: dict[str, list[tuple[int, int, str]]] = {}
    pending, running, done = list(enumerate(cases)), [], 0
    while pending or running:
        while pending and len(running) < max(workers, 1):
            index, case = pending.pop(0)
            campaign.current = {"phase": "logs", "index": index, "case": case.label}
            running.append(_launch(case, index, root, env))
        time.sleep(0.02)
        for run in list(running):
            elapsed = time.perf_counter() - run.started
            if run.process.poll() is None:
                lines = (run.work / "status").read_text().split() if (run.work / "status").exists() else []
                if not run.interrupted and elapsed > BUDGET_S[run.case.command] and lines:
                    os.kill(int(lines[0]), signal.SIGINT)  # Ctrl-C, to the command
                    run.interrupted = elapsed
                elif run.interrupted and elapsed > run.interrupted + 10.0 and not run.killed:
                    os.killpg(run.process.pid, signal.SIGKILL)  # the launcher and the command
                    run.killed = True
                continue
            running.remove(run)
            status = (run.work / "status").read_text().split()
            code, peak_kb = (int(status[1]), int(status[2])) if len(status) == 3 else (-9, 0)
            _judge(fz, run, code, peak_kb / 1024.0, elapsed, report, cuts, campaign, keep)
            done += 1
            if done % 50 == 0 or done == len(cases):
                memory = report["peak_memory"]
                campaign.say(f"fuzz: logs {done}/{len(cases)}: " + " ".join(
                    f"{c}={v}" for c, v in sorted(report["counts"].items())) + f"  worst memory "
                    f"{memory['worst_mb']:.0f} MB ({memory['worst_fraction_of_bound']:.2f} of its bound)")
    for group, points in cuts.items():  # a file cut later keeps at least what one cut earlier kept
        points.sort()
        for (p0, s0, l0), (p1, s1, l1) in zip(points, points[1:], strict=False):
            if s1 < s0:
                report["data_loss"].append({"case": l1, "reason": f"{group}: cut at byte {p1} read {s1} samples, "
                                            f"fewer than the {s0} of the cut at byte {p0} ({l0})",
                                            "reproduce": _reproduce(l1)})
    report["wall_s"] = round(time.perf_counter() - started, 1)
    if not keep:
        shutil.rmtree(root, ignore_errors=True)


def _reproduce(label: str) -> str:
    return f"python scripts/fuzz_logs.py --case {shlex.quote(label)} --keep"


def _judge(fz: Any, run: _Running, code: int, peak_mb: float, seconds: float, report: dict[str, Any],
           cuts: dict[str, list[tuple[int, int, str]]], campaign: Any, keep: bool) -> None:
    case = run.case
    out = (run.work / "out").read_bytes()[:4_000_000].decode("utf-8", "replace")
    err = (run.work / "err").read_bytes()[-20_000:].decode("utf-8", "replace")
    entry = {"index": run.index, "kind": case.kind, "case": case.label, "argv": run.argv, "exit": code,
             "seconds": round(seconds, 2), "peak_mb": round(peak_mb, 1), "stderr": err[-1500:],
             "reproduce": _reproduce(case.label)}
    inv = fz.Invocation(run.argv, case.command, case.bad, case.why)
    if run.interrupted:
        klass = "HANG"
        entry["reason"] = (f"not finished within {BUDGET_S[case.command]:g} s; "
                           + ("it ignored Ctrl-C and was killed" if run.killed else f"Ctrl-C stopped it (exit {code})"))
        report["hangs"].append(entry)
    else:
        klass, entry["reason"] = fz.judge(inv, "returned", code, out, err, "", 0)
        if klass == "INTERNAL":
            report["internal"].append(entry)
    size = run.path.stat().st_size if run.path.exists() else 0
    bound = MEMORY_MB + MEMORY_PER_BYTE * size / 2**20
    memory = report["peak_memory"]
    if peak_mb / bound > memory["worst_fraction_of_bound"]:
        memory.update(worst_mb=round(peak_mb, 1), bound_mb=round(bound, 1),
                      worst_fraction_of_bound=round(peak_mb / bound, 3), case=case.label)
    if peak_mb > bound:
        memory["over_bound"].append({**entry, "bound_mb": round(bound, 1)})
    memory["highest"] = sorted([*memory["highest"], [round(peak_mb / bound, 3), round(peak_mb, 1), round(bound, 1),
                                                     case.label, case.command]], reverse=True)[:10]
    document = None
    if "--json" in run.argv and out.strip():
        try:
            document = json.loads(out, parse_constant=_no_constant)
        except ValueError as exc:
            report["non_json"].append({**entry, "reason": f"--json printed what is not JSON: {exc}"[:300],
                                       "stdout": out[:500]})
    elif case.command == "export-stdout" and code == 0 and not re.match(r"(time_s|signal),", out):
        report["non_json"].append({**entry, "reason": "the CSV on standard output does not start with its header",
                                   "stdout": out[:500]})
    lost = None
    if not run.path.exists() or hashlib.sha256(run.path.read_bytes()).hexdigest() != run.digest:
        lost = "the input file was changed"
    samples = _samples(document) if code == 0 and case.command == "info" and isinstance(document, dict) else 0
    if case.group and case.command == "info" and not run.interrupted and klass != "INTERNAL":
        cuts.setdefault(case.group, []).append((case.position, samples, case.label))
    if case.records >= 0 and case.command == "info" and samples < case.records:
        lost = f"read {samples} records where {case.records} are whole and in time order (exit {code})"
    if lost is not None:
        report["data_loss"].append({**entry, "reason": lost})
    report["counts"][klass] += 1
    report["by_kind"].setdefault(case.kind, Counter())[klass] += 1
    if klass in ("INTERNAL", "HANG") or lost is not None or peak_mb > bound:
        last = (err.strip().splitlines() or [""])[-1][:300]
        campaign.say(f"fuzz: logs {klass} {case.label}: {lost or entry['reason']} (peak {peak_mb:.0f} MB of "
                     f"{bound:.0f})\n  reproduce: {entry['reproduce']}\n  {last}")
    if not keep:
        shutil.rmtree(run.work, ignore_errors=True)


def findings(report: dict[str, Any]) -> int:
    """Internal errors, hangs, data loss, non-JSON outputs and cases over the memory bound, in all."""
    return (len(report["internal"]) + len(report["hangs"]) + len(report["data_loss"]) + len(report["non_json"])
            + len(report["peak_memory"]["over_bound"]))


def main(argv: list[str] | None = None) -> int:
    """Only the logs phase, in a scratch folder: ``python scripts/fuzz_logs.py [--logs N] [--report FILE]``."""
    import argparse
    import importlib.util
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--logs", type=int, default=-1, help="cases: -1 all, N a seeded sample spread over the kinds")
    parser.add_argument("--seed", type=int, default=0, help="seed of the sample")
    parser.add_argument("--workers", type=int, default=2, help="cases run side by side")
    parser.add_argument("--case", default=None,
                        help="only the cases whose label holds this text (or one of these, comma-separated)")
    parser.add_argument("--report", type=Path, default=None, help="write the JSON report here")
    parser.add_argument("--keep", action="store_true", help="keep the scratch folder and the cases' files")
    args = parser.parse_args(argv)
    spec = importlib.util.spec_from_file_location("fuzz_campaign", Path(__file__).with_name("fuzz_campaign.py"))
    assert spec is not None and spec.loader is not None
    fz = importlib.util.module_from_spec(spec)
    sys.modules["fuzz_campaign"] = fz
    spec.loader.exec_module(fz)
    root = Path(tempfile.mkdtemp(prefix="aerobat-fuzz-logs-"))
    campaign = fz.Campaign(seed=args.seed, budget_s=6.0, root=root, progress=lambda text: print(text, flush=True))
    campaign.report_path = args.report
    try:
        run_logs_phase(fz, campaign, None, args.logs, workers=args.workers, only=args.case, keep=args.keep)
    finally:
        campaign.alarm.close()
        if not args.keep:
            shutil.rmtree(root, ignore_errors=True)
    report = campaign.report["logs"]
    campaign.report["wall_s"] = report.get("wall_s", 0.0)
    campaign.write_report()
    memory = report["peak_memory"]
    print(f"fuzz: logs done in {report.get('wall_s', 0):.0f} s: {report['cases']} cases "
          + " ".join(f"{c}={v}" for c, v in sorted(report["counts"].items()))
          + f"; internal {len(report['internal'])}, hangs {len(report['hangs'])}, data loss "
          f"{len(report['data_loss'])}, non-JSON {len(report['non_json'])}; worst memory {memory['worst_mb']} MB "
          f"of {memory['bound_mb']} MB ({memory['case']}), {len(memory['over_bound'])} over"
          + (f"; kept in {root}" if args.keep else ""))
    return 1 if findings(report) else 0


if __name__ == "__main__":
    raise SystemExit(main())
