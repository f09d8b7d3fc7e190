"""The tunes phase of the fuzz campaign (issue 45): crafted Betaflight tunes, read without flying.

Called by ``scripts/fuzz_campaign.py`` as ``run_tunes_phase(fz, campaign, fx, n)`` (-1: every
enumerated case and as many random ones, N: a seeded sample spread over the classes), or alone:
``python scripts/fuzz_tunes.py --cases 600 --report out/fuzz-tunes.json``. Every case writes a
tune file with something wrong in it and runs ``aerobat tune FILE --json``, which reads, translates
and checks the tune exactly as ``--tune FILE`` does before the firmware is configured. The files
start from real ones when ``../shared/data`` holds them (the Kakute H7 4.3.1 diff and the header
of the ROMA F5 blackbox log), else from built-in ones of the same shape.

Classes: ``control`` (NUL, TAB, CR, LF, ESC, Ctrl-C/D, backspace, DEL, 19 DELs and a command),
``non-ascii``, ``huge`` (values of 255 characters to 1 MB, a 16 MB diff), ``number-grammar``
(``1e2``, ``45.9``, ``4_5``, ``0x2d``, ``٤٥``, ``+045`` ...), ``out-of-range``, ``lookup``,
``unknown-name``, ``duplicate``, ``other-firmware`` (INAV, EmuFlight, Cleanflight, Rotorflight),
``structure`` (BOM, CRLF, no version line, empty, log index) and ``random`` (seeded byte and
line mutations). A case known bad by construction must be refused with exit 2 in one line
naming the file and the setting or header field; a case known good must exit 0.

On exit 0 an oracle written here, independent of aerobat's own checks, reads the JSON: every
command must be one line the firmware's interactive CLI runs as written (printable ASCII, no
``#`` or ``?``, at most 255 characters) and every ``set`` value one the build's table
(``sitl_settings.json``) takes, written as the firmware prints it back, each setting once.
Findings: ``internal`` (exit 70, a traceback, not one line, bad input accepted, a good tune
refused, an unsafe command), ``hangs`` (stopped by the time budget) and ``data_loss`` (the tune
file or the store changed). Each carries ``reproduce``.
"""

from __future__ import annotations

import argparse
import base64
import contextlib
import dataclasses
import hashlib
import json
import os
import random
import re
import shlex
import shutil
import sys
import tempfile
import time
from collections import Counter
from enum import StrEnum
from pathlib import Path
from typing import Any

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
REAL_DIFF = DATA / "betaflight-configs" / "tii-racing-kakuteh7-4.3.1-diff.txt"
REAL_LOG = DATA / "flight-logs" / "betaflight" / "diatone-roma-f5.bbl"
CLASSES = ("control", "non-ascii", "huge", "number-grammar", "out-of-range", "lookup", "unknown-name", "duplicate",
           "other-firmware", "structure", "random")
V431 = b"# Betaflight / STM32H743 (SH74) 4.3.1 MSP API: 1.44"
V460 = b"# Betaflight / STM32F7X2 (S7X2) 4.6.0 Jul 13 2025 / 03:32:52 (8d4f005) MSP API: 1.47"
BUILTIN_DIFF = b"\n".join([
    b"# version", V431, b"", b"batch start", b"board_name KAKUTEH7", b"feature -TELEMETRY",
    b"serial 0 0 115200 57600 0 115200", b"aux 0 0 0 1300 1700 0 0", b"set small_angle = 180",
    b"set dshot_idle_value = 450", b"profile 0", b"set p_roll = 63", b"set d_roll = 46", b"set d_min_roll = 46",
    b"set ff_interpolate_sp = AVERAGED_3", b"rateprofile 1", b"set rates_type = BETAFLIGHT",
    b"set roll_rc_rate = 202", b"profile 0", b"rateprofile 1", b"batch end", b"save", b""])
BUILTIN_HEADER = b"".join(b"H " + line + b"\n" for line in [
    b"Product:Blackbox flight data recorder by Nicholas Sherlock", b"Data version:2",
    b"Field I name:loopIteration,time", b"Firmware type:Cleanflight",
    b"Firmware revision:Betaflight 4.2.9 (e097f4ab7) STM32F7X2", b"Craft name:DIATONE ROMA F5",
    b"Board information: MAMBA F722 I2C", b"motorOutput:158,2047", b"thr_mid:50", b"tpa_rate:65",
    b"rc_rates:100,100,100", b"rates:70,70,70", b"rollPID:47,85,38", b"d_min:23,25,0", b"dterm_lowpass_hz:150",
    b"ff_interpolate_sp:2", b"dshot_idle_value:550", b"acc_lpf_hz:1000", b"rates_type:0"])
FRAMES = b"I\x00\x01\x02\x03E\xff"  # what follows a header: binary frames

CONTROL = [b"\x00", b"\t", b"\x1b[2J", b"\x03", b"\x04", b"\x08", b"\x0c", b"\x7f", b"\x7f" * 19 + b"set p_roll = 123",
           b"\x1b]0;owned\x07", b"\x0b", b"\x1c", b"\r", b"\n", b"a\rset p_roll = 123", b"\x85"]
NON_ASCII = ["é", "\u00a0", "٤٥", "\ufeff", "\u202e", "飞", "\u2028", "ｐ"]
NUMBERS = {  # text -> is it an integer as the firmware reads one
    "1e2": False, "45.9": False, "4_5": False, "0x2d": False, "45 6": False, "٤٥": False, "1e9": False,
    "nan": False, "inf": False, "--45": False, "4-5": False, "45,": False, "": False, "+": False, "-": False,
    "+045": True, "045": True, "-0": True, " 45": True, "45 ": True, "00000000000000000045": True,
}
# (name, kind) of settings whose values reach the firmware: int, lookup, string, d (paired before 4.6)
DIFF_TARGETS = [("p_roll", "int"), ("i_pitch", "int"), ("thr_mid", "int"), ("tpa_rate", "int"),
                ("roll_rc_rate", "int"), ("motor_idle", "int"), ("dshot_idle_value", "int"), ("rates_type", "lookup"),
                ("feedforward_averaging", "lookup"), ("ff_interpolate_sp", "lookup"), ("profile_name", "string"),
                ("rateprofile_name", "string"), ("d_roll", "d"), ("d_min_pitch", "d")]
HEADER_TARGETS = [("thr_mid", "int"), ("tpa_rate", "int"), ("rollPID", "split"), ("rc_rates", "split"),
                  ("d_min", "split"), ("rates_type", "index"), ("ff_interpolate_sp", "index"),
                  ("dterm_lowpass_hz", "int"), ("profile_name", "string"), ("Craft name", "record"),
                  ("Board information", "record"), ("motorOutput", "record"), ("Field I name", "record")]
OTHERS = [(b"# INAV/MATEKF722SE 7.1.2 Jun  4 2024 / 08:46:38 (f5c4ed6d)", "INAV"),
          (b"# EmuFlight / HELIOSPRING (HESP) 0.4.1 Nov 11 2021 / 17:28:01 (f6a0ab6be) MSP API: 1.51", "EmuFlight"),
          (b"# Cleanflight/SPRACINGF3 2.5.0 Jan  1 2020 / 10:00:00 (abc) MSP API: 1.40", "Cleanflight"),
          (b"# Rotorflight / STM32F7X2 (S7X2) 4.3.0 Mar 1 2023 / 10:00:00 (abc) MSP API: 12.5", "Rotorflight")]


class Expect(StrEnum):
    """What a case must end in."""

    BAD = "bad"  # exit 2, one line naming the file and (when given) the setting or field
    GOOD = "good"  # exit 0
    ANY = "any"  # any clean outcome; on exit 0 the oracle


@dataclasses.dataclass(frozen=True)
class TuneCase:
    klass: str
    data: bytes
    suffix: str  # ".txt" (a diff) or ".bbl" (a blackbox log)
    expect: Expect
    names: tuple[str, ...] = ()  # what a refusal must name besides the file (any one of them)
    why: str = ""
    log_index: int | None = None
    applied: tuple[str, str] | None = None  # on exit 0, `set NAME = VALUE` must be among the commands


# ====================================================================== the files


def base_diff() -> bytes:
    return REAL_DIFF.read_bytes() if REAL_DIFF.is_file() else BUILTIN_DIFF


def base_header() -> bytes:
    if not REAL_LOG.is_file():
        return BUILTIN_HEADER
    data = REAL_LOG.read_bytes()[:1 << 16]
    end = position = data.find(b"H Product:")
    while data.startswith(b"H ", position):
        end = position = data.find(b"\n", position) + 1
    return data[data.find(b"H Product:"):end]


def with_value(header: bytes, field: bytes, value: bytes) -> bytes:
    """``header`` with ``H field:value`` replacing the field's line (appended if absent)."""
    lines = header.split(b"\n")
    line = b"H " + field + b":" + value
    for k, old in enumerate(lines):
        if old.startswith(b"H " + field + b":"):
            lines[k] = line
            return b"\n".join(lines)
    return header.rstrip(b"\n") + b"\n" + line + b"\n"


def diff_with(version: bytes, lines: list[bytes]) -> bytes:
    """A small diff of ``version`` holding the base diff's profile and rate-profile selection and ``lines``."""
    return b"\n".join([b"# version", version, b"", b"# master", *lines, b""])


def table() -> dict[str, Any]:
    from aerobat.firmware.betaflight.sitl_table import SITL_TABLE_PATH

    return dict(json.loads(SITL_TABLE_PATH.read_text())["settings"])


def enumerated(rng: random.Random) -> list[TuneCase]:
    """Every class's cases (the ``random`` class is drawn apart, :func:`random_case`)."""
    settings = table()
    header = base_header()
    cases: list[TuneCase] = []
    for version in (V431, V460):
        v = "4.3.1" if version == V431 else "4.6.0"
        for name, kind in DIFF_TARGETS:
            if kind == "d" and version == V460 and name.startswith("d_min"):
                continue  # 4.6 has no d_min_*: an unknown setting, another class's
            for bad in CONTROL:
                split = b"\r" in bad or b"\n" in bad  # two lines: the firmware's CLI ends a line there too
                utf8 = bad != b"\x85"  # a lone 0x85 is no UTF-8: the file is no text (named by its line, not setting)
                line = b"set " + name.encode() + b" = 4" + bad + b"5"
                cases.append(TuneCase("control", diff_with(version, [line]), ".txt",
                                      Expect.ANY if split else Expect.BAD, (name,) if utf8 and not split else (),
                                      f"{v}: {name} = 4{bad!r}5"))
            for text in NON_ASCII:
                cases.append(TuneCase("non-ascii", diff_with(version, [f"set {name} = 4{text}5".encode()]), ".txt",
                                      Expect.BAD, (name,), f"{v}: {name} = 4{text!r}5"))
            for size in (256, 4096, 1 << 19, 1 << 20):  # a 1 MiB value makes the file larger than any diff
                cases.append(TuneCase("huge", diff_with(version, [f"set {name} = {'9' * size}".encode()]), ".txt",
                                      Expect.BAD, (name,) if size < 1 << 20 else (), f"{v}: {name} = 9 x {size}"))
            for text, integer in NUMBERS.items():
                line = f"set {name} = {text}".encode()
                if kind in ("int", "d"):
                    good = integer
                    cases.append(TuneCase("number-grammar", diff_with(version, [line]), ".txt",
                                          Expect.ANY if good else Expect.BAD, (name,), f"{v}: {name} = {text!r}"))
                elif rng.random() < 0.3:
                    cases.append(TuneCase("number-grammar", diff_with(version, [line]), ".txt", Expect.ANY, (),
                                          f"{v}: {name} = {text!r}"))
            entry = settings.get(name)
            if kind in ("int", "d") and entry is not None and entry["low"] is not None:
                low, high = int(entry["low"]), int(entry["high"])
                for number in (low - 1, high + 1, high * 1000, -high, 2**31, 2**32, -(2**63), low, high):
                    cases.append(TuneCase("out-of-range", diff_with(version, [f"set {name} = {number}".encode()]),
                                          ".txt", Expect.ANY, (name,), f"{v}: {name} = {number}"))
            if kind == "lookup" and entry is not None:
                for text in [entry["values"][0].lower(), entry["values"][-1].title(), "NOPE", "ON OFF", "ACTUAL",
                             "-", "_", "0"]:
                    cases.append(TuneCase("lookup", diff_with(version, [f"set {name} = {text}".encode()]), ".txt",
                                          Expect.ANY, (name,), f"{v}: {name} = {text}"))
            if kind == "string":
                for text in ["fast", "-", "a b", "a#b", "a?b", "12345678", "123456789", "'x'", '"x"', "\\x7f"]:
                    cases.append(TuneCase("lookup", diff_with(version, [f"set {name} = {text}".encode()]), ".txt",
                                          Expect.ANY, (name,), f"{v}: {name} = {text}"))
        for typo in ("p_rol", "p_roll2", "zz_unknown", "P_ROLL", "p-roll", "p_roll.", "set", "ｐ_roll", "p_rollé", "_"):
            expect = Expect.ANY if typo == "P_ROLL" else Expect.BAD
            cases.append(TuneCase("unknown-name", diff_with(version, [f"set {typo} = 45".encode()]), ".txt", expect,
                                  (typo,) if typo.isascii() else (), f"{v}: set {typo} = 45"))
        for first, last in (("40", "41"), ("41", "1e2"), ("1e2", "41")):  # the last one counts, and is checked
            lines = [b"set p_roll = " + first.encode(), b"set p_roll = " + last.encode()]
            bad = last == "1e2"
            cases.append(TuneCase("duplicate", diff_with(version, lines), ".txt", Expect.BAD if bad else Expect.GOOD,
                                  ("p_roll",), f"{v}: p_roll {first} then {last}",
                                  applied=None if bad else ("p_roll", last)))
    for field, kind in HEADER_TARGETS:
        f = field.encode()
        base = {"split": b"47,85,38", "index": b"1"}.get(kind, b"50")
        setting = kind not in ("record",)
        for bad in CONTROL:
            value = base[:1] + bad + base[1:]
            ends = b"\n" in bad or value.endswith(b"\r")  # the header line ends there (CR LF)
            cases.append(TuneCase("control", with_value(header, f, value) + FRAMES, ".bbl",
                                  Expect.BAD if setting and not ends else Expect.ANY, (field,),
                                  f"header {field}: {bad!r} inside"))
        for text in NON_ASCII:
            cases.append(TuneCase("non-ascii", with_value(header, f, text.encode() + base) + FRAMES, ".bbl",
                                  Expect.BAD if setting else Expect.ANY, (field,), f"header {field}: {text!r}"))
        for size in (256, 1 << 20):
            cases.append(TuneCase("huge", with_value(header, f, b"9" * size) + FRAMES, ".bbl",
                                  Expect.BAD if setting else Expect.ANY, (field,), f"header {field}: 9 x {size}"))
        for text, integer in NUMBERS.items():
            value = text.encode() if kind != "split" else text.encode() + b",85,38"
            bad = kind in ("int", "split") and not integer
            cases.append(TuneCase("number-grammar", with_value(header, f, value) + FRAMES, ".bbl",
                                  Expect.BAD if bad else Expect.ANY, (field,), f"header {field}: {text!r}"))
        if kind in ("int", "split", "index"):
            for number in (-1, 251, 5, 99999, 2**32, 10**30):
                value = str(number).encode() if kind != "split" else str(number).encode() + b",85,38"
                cases.append(TuneCase("out-of-range", with_value(header, f, value) + FRAMES, ".bbl",
                                      Expect.ANY, (field,), f"header {field}: {number}"))
    for line, writer in OTHERS:
        diff = b"# diff all\n\n# version\n" + line + b"\n\nset gyro_main_lpf_hz = 110\n"
        cases.append(TuneCase("other-firmware", diff, ".txt", Expect.BAD, (writer,), f"a {writer} diff"))
        revision = line.lstrip(b"# ").split(b"/")[0].strip() + b" 7.1.2 (f5c4ed6d) MATEKF722SE"
        cases.append(TuneCase("other-firmware", with_value(header, b"Firmware revision", revision) + FRAMES, ".bbl",
                              Expect.BAD, ("Firmware revision",), f"a {writer} log"))
    diff = base_diff()
    cases += [
        TuneCase("structure", b"\xef\xbb\xbf" + diff, ".txt", Expect.GOOD, why="a BOM"),
        TuneCase("structure", diff.replace(b"\n", b"\r\n"), ".txt", Expect.GOOD, why="CRLF"),
        TuneCase("structure", diff.replace(b"\n", b"\r"), ".txt", Expect.GOOD, why="CR line ends"),
        TuneCase("structure", b"set p_roll = 45\n", ".txt", Expect.GOOD, why="no version line",
                 applied=("p_roll", "45")),
        TuneCase("structure", b"", ".txt", Expect.BAD, why="empty"),
        TuneCase("structure", b"# only\n# comments\n", ".txt", Expect.BAD, why="only comments"),
        TuneCase("structure", b"\xef\xbb\xbf" + header + FRAMES, ".bbl", Expect.GOOD, why="a BOM before a header"),
        TuneCase("structure", header + FRAMES + header + FRAMES, ".bbl", Expect.GOOD, why="two logs, the second",
                 log_index=2),
        TuneCase("structure", header + FRAMES, ".bbl", Expect.BAD, ("--log-index",), "log 3 of 1", log_index=3),
        TuneCase("structure", with_value(header, b"Firmware revision", b"") + FRAMES, ".bbl", Expect.BAD,
                 ("Firmware revision",), "no firmware"),
        TuneCase("structure", header.replace(b"H rollPID:", b"H rollPID") + FRAMES, ".bbl", Expect.ANY, why="no colon"),
        TuneCase("structure", header.replace(b"\n", b"\r\n") + FRAMES, ".bbl", Expect.GOOD, why="CRLF header"),
        TuneCase("structure", b"\xff\xfe" + diff.decode("latin-1").encode("utf-16-le"), ".txt", Expect.BAD,
                 why="UTF-16"),
        TuneCase("structure", diff_with(V460, [b"profile 99", b"set p_roll = 45"]), ".txt", Expect.ANY,
                 why="profile 99"),
        TuneCase("huge", diff_with(V460, [b"set p_roll = 45"] * 1_000_000), ".txt", Expect.BAD, why="a 16 MB diff"),
        TuneCase("huge", header + b"".join(b"H x%d:1\n" % k for k in range(20000)) + FRAMES, ".bbl", Expect.BAD,
                 why="20,000 header fields"),
        TuneCase("huge", (header + FRAMES) * 2 + b"H Product:x\nH Firmware revision:Betaflight 4.2.9\nI\n" * 500_000,
                 ".bbl", Expect.GOOD, why="500,002 logs, the second", log_index=2),
    ]
    return cases


def random_case(rng: random.Random) -> TuneCase:
    """A seeded mutation of the base diff or header: bytes inserted, replaced or removed, lines doubled or cut."""
    blackbox = rng.random() < 0.4
    data = bytearray(base_header() + FRAMES if blackbox else base_diff())
    lines = bytes(data).split(b"\n")
    pool = [b"\x7f", b"\x00", b"\r", b"\n", b"\t", b"#", b"?", b"=", b",", b" ", b":", b"-", b"9" * 300,
            b"\xc3\xa9", b"\xff", b"1e2", b".5", b"_", b"set p_roll = 123", b"H ", b"profile 1", b"\xef\xbb\xbf"]
    steps = []
    for _ in range(rng.choice([1, 1, 2, 3])):
        k = rng.randrange(len(lines))
        line = lines[k]
        at = rng.randrange(len(line) + 1)
        how = rng.randrange(6)
        if how == 0:
            piece = rng.choice(pool)
            lines[k] = line[:at] + piece + line[at:]
            steps.append(f"line {k + 1}: insert {piece[:12]!r} at {at}")
        elif how == 1 and line:
            piece = bytes([rng.randrange(256)])
            lines[k] = line[:at] + piece + line[at + 1:]
            steps.append(f"line {k + 1}: byte {at} = {piece!r}")
        elif how == 2:
            lines[k] = line[:at]
            steps.append(f"line {k + 1}: cut at {at}")
        elif how == 3:
            lines.insert(k, line)
            steps.append(f"line {k + 1}: doubled")
        elif how == 4:
            numbers = list(re.finditer(rb"\d+", line))
            if numbers:
                hit = rng.choice(numbers)
                piece = rng.choice([*(t.encode() for t in NUMBERS), b"99999", b"-1", b"256", b"2147483648"])
                lines[k] = line[:hit.start()] + piece + line[hit.end():]
                steps.append(f"line {k + 1}: number -> {piece!r}")
        else:
            lines[k] = line.upper() if rng.random() < 0.5 else line.lower()
            steps.append(f"line {k + 1}: case")
    return TuneCase("random", b"\n".join(lines), ".bbl" if blackbox else ".txt", Expect.ANY, why="; ".join(steps))


# ====================================================================== the oracle


def unsafe_commands(commands: Any, settings: dict[str, Any]) -> list[str]:
    """What in ``commands`` (the JSON's) the firmware's CLI would not run as written or take as written."""
    if not isinstance(commands, list):
        return [f"commands is {type(commands).__name__}, not a list"]
    problems, seen = [], set()
    for command in commands:
        if not isinstance(command, str) or not re.fullmatch(r"[ -~]{1,255}", command) or re.search(r"[#?]", command):
            problems.append(f"{command!r}: not a line the interactive CLI runs as written")
            continue
        match = re.fullmatch(r"set ([a-z0-9_]+) = (\S(?:.*\S)?)", command)
        if match is None:
            if not re.fullmatch(r"feature -?[A-Z0-9_]+", command):
                problems.append(f"{command!r}: neither a set nor a feature line")
            continue
        name, value = match.groups()
        if name in seen:
            problems.append(f"{name} set twice")
        seen.add(name)
        entry = settings.get(name)
        if entry is None:
            problems.append(f"{name}: not a setting of the build")
        elif entry["values"]:
            if value not in entry["values"]:
                problems.append(f"{name} = {value!r}: not one of {entry['values']}")
        elif entry["string"]:
            if not entry["min_length"] <= len(value) <= entry["max_length"]:
                problems.append(f"{name} = {value!r}: not {entry['min_length']}-{entry['max_length']} characters")
        else:
            parts = value.split(",") if entry["array"] else [value]
            for part in parts:
                if not re.fullmatch(r"0|-?[1-9][0-9]*", part):
                    problems.append(f"{name} = {value!r}: not an integer as the firmware prints it")
                elif entry["low"] is not None and not entry["low"] <= int(part) <= entry["high"]:
                    problems.append(f"{name} = {value!r}: out of {entry['low']:.0f}..{entry['high']:.0f}")
    return problems


# ====================================================================== running


def _digest(path: Path) -> str | None:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


def reproduce(work: Path, path: Path, case: TuneCase, argv: list[str], seed: int, index: int) -> str:
    if len(case.data) <= 4096:
        make = (f"python3 -c \"import base64, pathlib; pathlib.Path({str(path)!r}).write_bytes(base64.b64decode("
                f"'{base64.b64encode(case.data).decode()}'))\"")
    else:
        make = (f"python scripts/fuzz_tunes.py --seed {seed} --only {index} --keep  # writes {path.name} "
                f"({len(case.data)} bytes)")
    return "; ".join([f"cd {shlex.quote(str(work))}", make, "aerobat " + shlex.join(argv)])


def judge_case(fz: Any, case: TuneCase, path: Path, outcome: tuple[Any, ...], settings: dict[str, Any]
               ) -> tuple[str, str]:
    """(class, reason): the campaign's judge, then what this phase knows about the case."""
    how, code, out, err, escaped, fired, _ = outcome
    bad = [str(path)] if case.expect is Expect.BAD else []
    klass, reason = fz.judge(fz.Invocation(["tune", str(path)], "tune", bad, case.why), how, code, out, err, escaped,
                             fired)
    if klass == "INTERNAL":
        return klass, reason
    if klass == "bad-input":
        if case.expect is Expect.GOOD:
            return "INTERNAL", f"a good tune ({case.why}) was refused"
        if case.expect is Expect.BAD and case.names and not any(name in err for name in case.names):
            return "INTERNAL", f"the refusal names none of {list(case.names)}"
    if klass == "ok":
        try:
            data = json.loads(out)
        except ValueError:
            return "INTERNAL", "exit 0 without one JSON object on standard output"
        problems = unsafe_commands(data.get("commands"), settings)
        if problems:
            return "INTERNAL", "a command the firmware would not take as written: " + "; ".join(problems[:3])
        if case.applied is not None and "set {} = {}".format(*case.applied) not in data["commands"]:
            return "INTERNAL", f"set {case.applied[0]} = {case.applied[1]} is not among the commands"
    return klass, reason


def run_tunes_phase(fz: Any, campaign: Any, fx: Any, n: int, *, only: int | None = None) -> None:
    """Run the tune cases (all enumerated ones and as many random ones if ``n`` < 0, else a seeded sample of ``n``
    spread over the classes; ``only``: just that case of the sample)."""
    rng = random.Random(campaign.seed + 45)
    cases = enumerated(rng)
    by_class = {k: [c for c in cases if c.klass == k] for k in CLASSES}
    if n < 0:
        picked = cases + [random_case(rng) for _ in range(len(cases))]
    else:
        picked = []
        while len(picked) < n:
            for klass in CLASSES:
                if len(picked) >= n:
                    break
                if klass == "random":
                    picked.append(random_case(rng))
                elif by_class[klass]:
                    picked.append(by_class[klass].pop(rng.randrange(len(by_class[klass]))))
    report: dict[str, Any] = {"requested": n, "cases": len(picked), "classes": list(CLASSES), "counts": Counter(),
                              "by_class": {}, "internal": [], "hangs": [], "data_loss": [],
                              "sources": [str(p) if p.is_file() else "built-in" for p in (REAL_DIFF, REAL_LOG)]}
    campaign.report["tunes"] = report
    settings = table()
    folder = campaign.root / "tunes"
    folder.mkdir(exist_ok=True)
    work = Path.cwd()
    for k, case in enumerate(picked):
        if only is not None and k != only:
            continue
        path = folder / f"case{k}{case.suffix}"
        path.write_bytes(case.data)
        argv = ["tune", str(path), "--json", *(["--log-index", str(case.log_index)] if case.log_index else [])]
        before = (_digest(path), _digest(fx.store))
        campaign.current = {"phase": "tunes", "index": k, "class": case.klass, "why": case.why}
        outcome = fz.run_cli(argv, campaign.alarm, campaign.budget_s, campaign.on_hang)
        how, code, _, err, _, fired, seconds = outcome
        klass, reason = judge_case(fz, case, path, outcome, settings)
        entry = {"index": k, "class": case.klass, "why": case.why[:300], "expect": case.expect.value, "exit": code,
                 "how": how, "reason": reason, "stderr": err[-1500:], "seconds": round(seconds, 2),
                 "reproduce": reproduce(work, path, case, argv, campaign.seed, k)}
        if (_digest(path), _digest(fx.store)) != before:
            klass, entry["reason"] = "DATA-LOSS", "the tune file or the store changed"
            report["data_loss"].append(entry)
        elif how == "stopped" or fired:
            klass, entry["reason"] = "HANG", f"not done within the {campaign.budget_s:g} s budget"
            report["hangs"].append(entry)
        elif klass == "INTERNAL":
            report["internal"].append(entry)
        report["counts"][klass] += 1
        report["by_class"].setdefault(case.klass, Counter())[klass] += 1
        if klass in ("INTERNAL", "HANG", "DATA-LOSS"):
            campaign.say(f"fuzz: {klass} tunes #{k} ({case.klass}: {case.why[:120]}): {entry['reason']}\n"
                         f"  reproduce: {entry['reproduce'][:600]}")
        else:
            path.unlink()
        if (k + 1) % 100 == 0 or k + 1 == len(picked):
            campaign.say(f"fuzz: tunes {k + 1}/{len(picked)}: "
                         + " ".join(f"{c}={v}" for c, v in sorted(report["counts"].items())))


def main(argv: list[str] | None = None) -> int:
    """Only the tunes phase, in the campaign's scratch environment (no seeded store: the phase never opens it)."""
    import importlib.util
    import resource

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--cases", type=int, default=600, help="cases: -1 every enumerated case and as many random")
    parser.add_argument("--seed", type=int, default=0, help="seed of every draw")
    parser.add_argument("--budget-s", type=float, default=6.0, help="time budget of one case [s]")
    parser.add_argument("--report", type=Path, default=None, help="write the JSON report here")
    parser.add_argument("--only", type=int, default=None, help="run only case K of the sample (to reproduce it)")
    parser.add_argument("--keep", action="store_true", help="keep the scratch folder and the case files")
    parser.add_argument("--memory-gb", type=float, default=12.0, help="address-space limit")
    args = parser.parse_args(argv)
    spec = importlib.util.spec_from_file_location("fuzz_campaign", Path(__file__).with_name("fuzz_campaign.py"))
    assert spec is not None and spec.loader is not None
    fz = importlib.util.module_from_spec(spec)
    sys.modules["fuzz_campaign"] = fz
    spec.loader.exec_module(fz)
    if args.memory_gb > 0:
        with contextlib.suppress(ValueError, OSError):
            resource.setrlimit(resource.RLIMIT_AS, (int(args.memory_gb * 2**30),) * 2)
    real_err = os.dup(2)
    fz.Campaign.say_fd = real_err

    def say(text: str) -> None:
        os.write(real_err, (text + "\n").encode("utf-8", "backslashreplace"))

    root = Path(tempfile.mkdtemp(prefix="aerobat-fuzz-tunes-"))
    saved_cwd, saved_env = os.getcwd(), dict(os.environ)
    campaign = fz.Campaign(seed=args.seed, budget_s=args.budget_s, root=root, progress=say)
    campaign.report_path = args.report
    try:
        fx = fz.Fixtures(root, random.Random(args.seed))
        (root / "work").mkdir()
        os.chdir(root / "work")
        os.environ["AEROBAT_DB"] = str(fx.store)
        os.environ["MPLBACKEND"] = "Agg"
        run_tunes_phase(fz, campaign, fx, args.cases, only=args.only)
    finally:
        os.chdir(saved_cwd)
        os.environ.clear()
        os.environ.update(saved_env)
        campaign.alarm.close()
        if args.keep:
            say(f"fuzz: kept {root}")
        else:
            shutil.rmtree(root, ignore_errors=True)
    found = campaign.report["tunes"]
    campaign.report["wall_s"] = round(time.perf_counter() - campaign.started, 1)
    for key in ("internal", "hangs", "data_loss"):
        campaign.report[key] = len(found[key])
    campaign.write_report()
    say(f"fuzz: done in {campaign.report['wall_s']:.0f} s: tunes {sum(found['counts'].values())} cases in "
        f"{len(found['by_class'])} classes " + " ".join(f"{c}={v}" for c, v in sorted(found["counts"].items()))
        + f"; internal errors {len(found['internal'])}, hangs {len(found['hangs'])}, data loss "
          f"{len(found['data_loss'])}" + (f"; report {args.report}" if args.report else ""))
    return 1 if found["internal"] or found["hangs"] or found["data_loss"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
