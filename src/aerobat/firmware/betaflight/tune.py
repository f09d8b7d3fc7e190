"""A real quad's Betaflight configuration (its *tune*), from a CLI ``diff``/``dump`` or a blackbox header.

A :class:`Tune` is what the file says, in the vocabulary of the firmware that wrote it (4.2's
``d_min_roll``, 4.3's ``dshot_idle_value``, ...), with the line each setting came from.
:mod:`.translate` turns it into Betaflight 4.6 commands for the SITL and reports what was
applied, translated, refused and pinned.

* :func:`parse_cli` reads a ``diff`` or ``dump`` (``diff all``, ``dump all`` too): ``set``
  lines by section (master, ``profile N``, ``rateprofile N``), the other commands (``feature``,
  ``aux``, ``serial``, ...) as commands, and which profile and rate profile were active (the
  last ``profile``/``rateprofile`` line, as Betaflight's "restore original profile selection").
* :func:`tune_from_blackbox_header` maps a blackbox log's header (``H name:value`` lines) to the
  CLI names of the firmware that wrote it (``rollPID`` → ``p_roll``, ``i_roll``, ``d_roll``; enum
  indices to their names).
* :func:`load_tune` picks one of the two by the file's content.

Only printable ASCII gets into a :class:`Tune`'s settings and commands, each short enough for the
firmware's CLI line (:mod:`.cli_grammar`): a value with a control character (a DEL erases the
character before it in the firmware's CLI), a non-ASCII one or too many characters is bad input,
named by its line (``FILE: line N``) or header field (``FILE#log1: header field NAME``). A diff
or log header written by another firmware (INAV, EmuFlight, ...) is refused as such; a UTF-8
byte-order mark at the start of a file is skipped.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

from aerobat.errors import ConfigError

from .cli_grammar import MAX_LINE_CHARS, parse_integer, shown, text_problem

__all__ = ["Tune", "TuneError", "TuneKind", "load_tune", "parse_cli", "read_blackbox_headers", "with_settings",
           "tune_from_blackbox_header"]

MAX_TUNE_BYTES = 64 * 1024 * 1024  # a blackbox file is read only up to its headers, but never more than this
MAX_CLI_BYTES = 1024 * 1024  # a Betaflight `dump all` is about 100 KiB; a larger text is no diff or dump
MAX_HEADER_LINES = 1000  # Betaflight 4.2-4.6 write 130-250 header lines a log

SECTIONS = ("master", "profile", "rateprofile", "command")
_VERSION = re.compile(r"Betaflight\s*/?\s*(?:\S+\s+\(\S+\)\s+)?(\d+)\.(\d+)\.(\d+)")
_ANY_VERSION = re.compile(r"\b(\d+)\.(\d+)\.(\d+)\b")
_SET = re.compile(r"(?i:set) +([A-Za-z0-9_]+) *= *(.*?) *")
_NAME = re.compile(r"[A-Za-z0-9_]+")
_SETTING_NAME = re.compile(r"[a-z0-9_]+")
# the line `version` prints, which every diff and dump repeats: "# Betaflight / STM32F7X2 (S7X2) 4.3.1 ...",
# "# INAV/MATEKF722SE 7.1.2 ...", "# EmuFlight / HELIOSPRING (HESP) 0.4.1 ..."
_FIRMWARE_LINE = re.compile(r"#\s*([A-Za-z][A-Za-z0-9_-]*)\s*/\s*\S.*?\b(\d+\.\d+\.\d+)\b")
_BOM = "\ufeff"
_LINE_END = re.compile(r"\r\n|\r|\n")  # the firmware's CLI ends a line at CR or LF, nothing else
# commands a diff/dump holds besides `set` (cli/cli.c cmdTable); their arguments are not checked here
_COMMANDS = frozenset({
    "adjrange", "aux", "beacon", "beeper", "board_name", "color", "dma", "feature", "gpspids", "led", "manufacturer_id",
    "map", "mcu_id", "mixer", "mmix", "mode_color", "resource", "rxfail", "rxrange", "serial", "servo", "signature",
    "smix", "timer", "vtx", "vtxtable", "vtx_info", "simplified_tuning", "osd_layout",
})
_STRUCTURE = frozenset({"batch", "save", "defaults", "exit", "diff", "dump", "version"})


class TuneError(ConfigError):
    """A tune file that cannot be read: the message names the file and the line."""


class TuneKind(StrEnum):
    """What a configuration was read from."""

    CLI = "cli"
    """The firmware's CLI ``diff`` or ``dump``."""
    BLACKBOX = "blackbox"
    """A blackbox log's header."""


@dataclass(frozen=True)
class Tune:
    """A Betaflight configuration as written by the firmware that wrote it.

    Attributes
    ----------
    firmware : the writer's firmware line (``"Betaflight / STM32H743 (SH74) 4.3.1 MSP API: 1.44"``,
        or a blackbox header's ``Firmware revision``); empty if the file does not say.
    version : (major, minor, patch) parsed from ``firmware``; (0, 0, 0) if unknown.
    source : where it came from (a path, ``path#log2``, ...).
    kind : :class:`TuneKind`: ``cli`` (diff or dump) or ``blackbox`` (a log header).
    active_profile, active_rateprofile : the PID profile and rate profile the quad flew.
    lines : ``(section, index, name, value, line)`` in file order. ``section`` is ``master``,
        ``profile``, ``rateprofile`` (``index`` its number) or ``command`` (``name`` the command
        word, ``value`` the rest); ``line`` counts from 1 (for a header, the header field).
        Settings and commands are printable ASCII that fits the firmware's CLI line (checked here,
        whoever builds the tune: a parser, a plant file's ``[tune]``, a stored session); a log
        header's lines that are no setting (``command`` ``header``) are kept escaped, never sent.
    fields : for a blackbox header, the header field of each line (``line`` N is ``fields[N - 1]``),
        so that messages name it; empty for a CLI file.
    changes : single changes made on top (:func:`with_settings`), ``NAME=VALUE`` each; their lines are
        numbered −1, −2, … so that messages name the change.
    """

    firmware: str
    version: tuple[int, int, int]
    source: str
    kind: TuneKind
    active_profile: int
    active_rateprofile: int
    lines: tuple[tuple[str, int, str, str, int], ...]
    fields: tuple[str, ...] = ()
    changes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "kind", TuneKind(self.kind))
        except ValueError:
            raise ConfigError(f"tune {self.source}: kind {self.kind!r}: expected 'cli' or 'blackbox'") from None
        if not isinstance(self.firmware, str) or text_problem(self.firmware) is not None:
            raise ConfigError(f"tune {self.source}: firmware {shown(self.firmware)}: expected printable ASCII")
        if not isinstance(self.fields, tuple) or not all(isinstance(f, str) for f in self.fields):
            raise ConfigError(f"tune {self.source}: fields: expected the header field names")
        for entry in self.lines:
            if (not isinstance(entry, tuple) or len(entry) != 5 or entry[0] not in SECTIONS
                    or not all(isinstance(v, t) for v, t in zip(entry[1:], (int, str, str, int), strict=True))):
                raise ConfigError(f"tune {self.source}: bad entry {shown(repr(entry), 80)}: expected (section, "
                                  f"index, name, value, line) with section one of {', '.join(SECTIONS)}")
            section, _, name, value, line = entry
            problem = _entry_problem(section, name, value)
            if problem is not None:
                raise ConfigError(f"tune {self.source}: {self.where(line)}: {problem}")

    def where(self, line: int) -> str:
        """Where entry ``line`` came from, as messages name it: ``line 12``, ``header field rollPID`` or ``--set
        p_roll=90``."""
        if line < 0 and -line <= len(self.changes):
            return f"--set {self.changes[-line - 1]}"
        if self.kind is TuneKind.BLACKBOX:
            return f"header field {self.fields[line - 1]}" if 1 <= line <= len(self.fields) else f"header line {line}"
        return f"line {line}"

    @property
    def version_text(self) -> str:
        return ".".join(map(str, self.version)) if self.version != (0, 0, 0) else "unknown"

    def active_settings(self) -> list[tuple[str, str, str, int]]:
        """``(section, name, value, line)`` of the settings the quad flew: master, active profiles; last wins."""
        out: dict[tuple[str, str], tuple[str, str, str, int]] = {}
        for section, index, name, value, line in self.lines:
            if section == "master" or (section == "profile" and index == self.active_profile) or (
                    section == "rateprofile" and index == self.active_rateprofile):
                out[(section, name)] = (section, name, value, line)
        return list(out.values())

    def inactive_settings(self) -> list[tuple[str, int, str, str, int]]:
        """Settings of profiles the quad did not fly (not applied)."""
        return [entry for entry in self.lines if (entry[0] == "profile" and entry[1] != self.active_profile)
                or (entry[0] == "rateprofile" and entry[1] != self.active_rateprofile)]

    def commands(self) -> list[tuple[str, str, int]]:
        """``(command, arguments, line)`` of the non-``set`` lines."""
        return [(name, value, line) for section, _, name, value, line in self.lines if section == "command"]


def _entry_problem(section: str, name: str, value: str) -> str | None:
    """None if a :attr:`Tune.lines` entry can reach the firmware's CLI as a line of its own, else why not."""
    if section == "command":
        if name == "header":  # a log header line that is no setting: recorded (escaped), never sent
            return None
        if name not in _COMMANDS:
            return f"{shown(name)}: not a CLI command a diff holds"
        line = f"{name} {value}"
    else:
        if _SETTING_NAME.fullmatch(name) is None:
            return f"{shown(name)}: not a setting name (lowercase ASCII letters, digits and '_')"
        line = f"set {name} = {value}"
    problem = text_problem(value)
    if problem is not None:
        return f"{name} = {shown(value)}: {problem} (only printable ASCII reaches the firmware's CLI)"
    if len(line) > MAX_LINE_CHARS:
        return (f"{name} = {shown(value)}: the line {shown(line, 24)} would be longer than the {MAX_LINE_CHARS} "
                "characters the firmware's CLI reads")
    return None


def _allowed(name: str) -> str:
    """``; allowed 0..250``: what Betaflight 4.6 takes for ``name``, if it is a 4.6 setting of the SITL build."""
    from .sitl_table import load_table

    entry = load_table().get(name) if _NAME.fullmatch(name) else None
    return f"; {entry.allowed()}" if entry is not None else ""


def _escaped(text: str) -> str:
    """``text`` with what is not printable ASCII escaped (``\\x7f``), cut to the CLI's line length."""
    text = str(text)
    if text_problem(text) is not None:
        text = ascii(text)[1:-1]
    return text if len(text) <= MAX_LINE_CHARS else text[:MAX_LINE_CHARS - 3] + "..."


def _version(text: str) -> tuple[int, int, int]:
    match = _VERSION.search(text) or _ANY_VERSION.search(text)
    return (int(match.group(1)), int(match.group(2)), int(match.group(3))) if match else (0, 0, 0)


def _read(path: Path, limit: int = MAX_TUNE_BYTES) -> bytes:
    try:
        if not path.is_file():
            raise TuneError(f"{path}: not a regular file")
        with open(path, "rb") as handle:
            return handle.read(limit)
    except OSError as error:
        raise TuneError(f"{path}: cannot read the tune: {error.strerror or error}") from None


def parse_cli(text: str, *, source: str) -> Tune:
    """Parse a Betaflight CLI ``diff`` or ``dump``.

    A byte-order mark before the first line is skipped. Lines end at CR, LF or CR LF, as the firmware's
    CLI reads them (a form feed or U+2028 is a character of the line, and refused as such).

    Raises
    ------
    TuneError
        A line that is no CLI command a diff holds, a malformed ``set``/``profile`` line, a line
        with a character that is not printable ASCII or longer than the firmware's CLI reads, or
        a file another firmware wrote (its version line names INAV, EmuFlight, ...); the message
        names ``source`` and the line number.
    """
    firmware = ""
    section, index = "master", 0
    active = {"profile": 0, "rateprofile": 0}
    lines: list[tuple[str, int, str, str, int]] = []
    for number, raw in enumerate(_LINE_END.split(text.removeprefix(_BOM)), start=1):
        line = raw.strip(" ")
        where = f"{source}: line {number}"
        if not line:
            continue
        if line.startswith("#"):
            writer = _FIRMWARE_LINE.match(line)
            if not firmware and writer is not None and writer.group(1).lower() != "betaflight":
                raise TuneError(f"{where}: not a Betaflight diff or dump: written by {_escaped(writer.group(1))} "
                                f"{writer.group(2)} (aerobat reads Betaflight 4.2-4.6 CLI diffs, dumps and logs)")
            if not firmware and "Betaflight" in line and _ANY_VERSION.search(line):
                firmware = _escaped(line.lstrip("# ").strip())
            continue
        problem = text_problem(line)
        setting = _SET.fullmatch(line)
        if problem is not None and setting is not None:
            name, value = setting.group(1).lower(), setting.group(2)
            raise TuneError(f"{where}: {name} = {shown(value)}: {text_problem(value) or problem}{_allowed(name)}")
        if problem is not None:
            raise TuneError(f"{where}: not a Betaflight CLI line: {problem} in {shown(line)}")
        if len(line) > MAX_LINE_CHARS:
            raise TuneError(f"{where}: {shown(line)}: {len(line)} characters, more than the firmware's CLI reads in a "
                            f"line ({MAX_LINE_CHARS})" + (_allowed(setting.group(1).lower()) if setting else ""))
        word, _, rest = line.partition(" ")
        word = word.lower()
        if word == "set":
            match = _SET.fullmatch(line)
            if match is None or not match.group(2):
                raise TuneError(f"{where}: malformed set line {shown(line)}: expected 'set NAME = VALUE'")
            lines.append((section, index, match.group(1).lower(), match.group(2), number))
        elif word in ("profile", "rateprofile"):
            if not re.fullmatch(r"\d{1,2}", rest.strip()):
                raise TuneError(f"{where}: malformed {word} line {shown(line)}: expected '{word} N'")
            section, index = word, int(rest)
            active[word] = index
        elif word in _COMMANDS:
            lines.append(("command", 0, word, rest.strip(), number))
        elif word in _STRUCTURE:
            continue
        else:
            raise TuneError(f"{where}: unknown CLI command {shown(word)} in {shown(line)} (a diff or dump holds set, "
                            "profile, rateprofile, feature, aux, serial, ... lines)")
    if not lines:
        raise TuneError(f"{source}: no Betaflight settings found (expected a CLI diff or dump)")
    return Tune(firmware, _version(firmware), source, TuneKind.CLI, active["profile"], active["rateprofile"],
                tuple(lines))


def read_blackbox_headers(data: bytes) -> list[dict[str, str]]:
    """The header of every log in a blackbox file: ``{name: raw value}`` of its ``H name:value`` lines.

    A log starts at ``H Product:``; its header ends at the first line not starting with ``H ``. A line
    ends at LF (a CR before it is dropped); a name and a value lose their surrounding spaces, nothing
    else (a TAB or DEL stays, for :func:`tune_from_blackbox_header` to refuse).

    Raises
    ------
    TuneError
        A header of more than :data:`MAX_HEADER_LINES` lines (no Betaflight log's).
    """
    return [_header_at(data, start) for start in _log_starts(data)]


def _log_starts(data: bytes) -> list[int]:
    """Where each log's header starts: an ``H Product:`` after the previous header (the log's frames between)."""
    starts = []
    start = data.find(b"H Product:")
    while start >= 0:
        starts.append(start)
        start = data.find(b"H Product:", _header_lines(data, start)[-1])
    return starts


def _header_lines(data: bytes, start: int) -> list[int]:
    """Where each line of the header at ``start`` begins, and where the header ends (the last entry)."""
    lines = [start]
    while data.startswith(b"H ", lines[-1]):
        if len(lines) > MAX_HEADER_LINES:
            raise TuneError(f"the header at byte {start} has more than {MAX_HEADER_LINES} lines (a Betaflight "
                            "log's has 130-250): not a Betaflight blackbox log")
        end = data.find(b"\n", lines[-1])
        lines.append(len(data) + 1 if end < 0 else end + 1)
    return lines


def _header_at(data: bytes, start: int) -> dict[str, str]:
    """The header that starts at ``start``: ``{name: value}`` of its ``H name:value`` lines (the first of a name)."""
    header: dict[str, str] = {}
    lines = _header_lines(data, start)
    for begin, end in zip(lines, lines[1:], strict=False):
        name, sep, value = data[begin + 2:end].rstrip(b"\n").removesuffix(b"\r").decode("latin-1").partition(":")
        if sep:
            header.setdefault(name.strip(" "), value.strip(" "))
    return header


# Header fields that are several CLI settings (blackbox/blackbox.c writes them as "a,b,c").
_AXES3 = ("roll", "pitch", "yaw")
_SPLIT: dict[str, tuple[str, ...]] = {
    "rollPID": ("p_roll", "i_roll", "d_roll"),
    "pitchPID": ("p_pitch", "i_pitch", "d_pitch"),
    "yawPID": ("p_yaw", "i_yaw", "d_yaw"),
    "levelPID": ("p_level", "i_level", "d_level"),
    "magPID": ("p_mag",),
    "d_min": ("d_min_roll", "d_min_pitch", "d_min_yaw"),
    "d_max": ("d_max_roll", "d_max_pitch", "d_max_yaw"),
    "rc_rates": tuple(f"{a}_rc_rate" for a in _AXES3),
    "rates": tuple(f"{a}_srate" for a in _AXES3),
    "rc_expo": tuple(f"{a}_expo" for a in _AXES3),
    "rate_limits": tuple(f"{a}_rate_limit" for a in _AXES3),
    "feedforward_weight": ("f_roll", "f_pitch", "f_yaw"),
    "gyro_lowpass_dyn_hz": ("dyn_lpf_gyro_min_hz", "dyn_lpf_gyro_max_hz"),
    "dterm_lowpass_dyn_hz": ("dyn_lpf_dterm_min_hz", "dyn_lpf_dterm_max_hz"),
    "gyro_lpf1_dyn_hz": ("gyro_lpf1_dyn_min_hz", "gyro_lpf1_dyn_max_hz"),
    "dterm_lpf1_dyn_hz": ("dterm_lpf1_dyn_min_hz", "dterm_lpf1_dyn_max_hz"),
    "gyro_notch_hz": ("gyro_notch1_hz", "gyro_notch2_hz"),
    "gyro_notch_cutoff": ("gyro_notch1_cutoff", "gyro_notch2_cutoff"),
}
# Header names that differ from the same firmware's CLI name.
_RENAME = {
    "dterm_filter_type": "dterm_lowpass_type",
    "dterm_filter2_type": "dterm_lowpass2_type",
    "pidAtMinThrottle": "pid_at_min_throttle",
    "minthrottle": "min_throttle",
    "maxthrottle": "max_throttle",
}
# Enum indices as the 4.2-4.6 lookup tables order them (cli/settings.c of each version).
_FILTER_TYPES = ("PT1", "BIQUAD", "PT2", "PT3")
_LOOKUPS: dict[str, tuple[str, ...]] = {
    "rates_type": ("BETAFLIGHT", "RACEFLIGHT", "KISS", "ACTUAL", "QUICK"),
    "dterm_lowpass_type": _FILTER_TYPES, "dterm_lowpass2_type": _FILTER_TYPES,
    "gyro_lowpass_type": _FILTER_TYPES, "gyro_lowpass2_type": _FILTER_TYPES,
    "dterm_lpf1_type": _FILTER_TYPES, "dterm_lpf2_type": _FILTER_TYPES,
    "gyro_lpf1_type": _FILTER_TYPES, "gyro_lpf2_type": _FILTER_TYPES,
    "iterm_relax": ("OFF", "RP", "RPY", "RP_INC", "RPY_INC"),
    "iterm_relax_type": ("GYRO", "SETPOINT"),
    "ff_interpolate_sp": ("OFF", "ON", "AVERAGED_2", "AVERAGED_3", "AVERAGED_4"),
    "feedforward_averaging": ("OFF", "2_POINT", "3_POINT", "4_POINT"),
    "anti_gravity_mode": ("SMOOTH", "STEP"),
    "rc_smoothing_type": ("INTERPOLATION", "FILTER"),
    "use_integrated_yaw": ("OFF", "ON"),
    "pid_at_min_throttle": ("OFF", "ON"),
    "iterm_rotation": ("OFF", "ON"),
    "dshot_bidir": ("OFF", "ON"),
    "gyro_cal_on_first_arm": ("OFF", "ON"),
    "use_unsynced_pwm": ("OFF", "ON"),
    "throttle_limit_type": ("OFF", "SCALE", "CLIP"),
    "tpa_mode": ("PD", "D"),
    "rc_smoothing_debug_axis": ("ROLL", "PITCH", "YAW", "THROTTLE"),
}
# Header lines that record the log or the hardware, not a setting.
_NOT_SETTINGS = frozenset({
    "Product", "Data version", "Firmware type", "Firmware revision", "Firmware date", "Board information",
    "Log start datetime", "Craft name", "I interval", "P interval", "P ratio", "gyro_scale", "motorOutput",
    "acc_1G", "vbatref", "vbatcellvoltage", "currentSensor", "looptime", "features", "rc_smoothing_active_cutoffs",
    "rc_smoothing_rx_average", "rc_smoothing_cutoffs", "rc_smoothing_filter_type", "rc_interpolation",
    "rc_interpolation_interval", "rc_interpolation_channels", "gyro_sync_denom",
})


def tune_from_blackbox_header(header: Mapping[str, str], *, source: str) -> Tune:
    """The tune a blackbox log's header records.

    Parameters
    ----------
    header : each header field's name and raw text exactly as written after ``"H "`` (``"rollPID"``
        → ``"47,85,38"``).
    source : names the log in messages (``"flight.bbl#log1"``).

    Multi-value fields become the CLI settings of the firmware that wrote the log (``rollPID``
    → ``p_roll``, ``i_roll``, ``d_roll``; ``d_min`` → ``d_min_roll``, ...; ``rates`` →
    ``roll_srate``, ...); enum fields written as indices become their names. 4.2-4.6 write every
    value in the unit of its CLI setting (the ×100 filter fields of 3.x headers, ``dterm_lpf_hz``
    and ``yaw_lpf_hz``, are no longer written); fields that record the log or the hardware
    (``motorOutput``, ``looptime``, ``features``, ...) are kept as commands and reported, not applied.
    The log's profile is flown as profile 0 and rate profile 0.

    Raises
    ------
    TuneError
        The header has no ``Firmware revision`` or another firmware's, a multi-value field has the
        wrong count or a value that is not an integer, or a field that sets a setting has a
        character that is not printable ASCII or more than the firmware's CLI reads in a line
        (the message names ``source`` and the header field).
    """
    if not isinstance(header, Mapping):
        raise TuneError(f"{source}: expected a mapping of header names to values, got {type(header).__name__}")
    firmware = _escaped(str(header.get("Firmware revision", "")).strip(" "))
    if not firmware:
        raise TuneError(f"{source}: the header has no 'Firmware revision' (is it a Betaflight blackbox log?)")
    if not firmware.lower().startswith("betaflight"):
        raise TuneError(f"{source}: Firmware revision {shown(firmware, 60)}: only Betaflight logs carry a Betaflight "
                        "tune")
    lines: list[tuple[str, int, str, str, int]] = []
    fields: list[str] = []
    for number, (raw_name, raw) in enumerate(header.items(), start=1):
        name, value = str(raw_name), str(raw).strip(" ")
        fields.append(_escaped(name))
        where = f"{source}: header field {fields[-1]}:{shown(value)}"
        cli = _RENAME.get(name, name)
        if name in _NOT_SETTINGS or name.startswith("Field ") or (name not in _SPLIT and not _NAME.fullmatch(cli)):
            lines.append(("command", 0, "header", _escaped(f"{name}:{value}"), number))  # recorded, never sent
            continue
        problem = text_problem(value)
        if problem is None and len(f"set {cli} = {value}") > MAX_LINE_CHARS:
            problem = f"{len(value)} characters, more than the firmware's CLI reads in a line ({MAX_LINE_CHARS})"
        if problem is not None:
            sets = ", ".join(_SPLIT.get(name, (cli.lower(),)))
            raise TuneError(f"{where}: {problem} (the field sets {sets}){_allowed(sets.partition(',')[0])}")
        names = _SPLIT.get(name)
        if names is not None:
            parts = [part.strip(" ") for part in value.split(",")]
            if len(parts) != len(names) or any(parse_integer(part) is None for part in parts):
                raise TuneError(f"{where}: expected {len(names)} comma-separated integers, each an optional sign and "
                                f"decimal digits ({', '.join(names)})")
            lines.extend(("master", 0, cli, part, number) for cli, part in zip(names, parts, strict=True))
            continue
        table = _LOOKUPS.get(cli)
        index = parse_integer(value)
        if table is not None and index is not None:
            if not 0 <= index < len(table):
                raise TuneError(f"{where}: index out of range, allowed 0..{len(table) - 1} ({', '.join(table)})")
            value = table[index]
        lines.append(("master", 0, cli.lower(), value, number))
    return Tune(firmware, _version(firmware), source, TuneKind.BLACKBOX, 0, 0, tuple(lines), tuple(fields))


def load_tune(path: str | Path, *, log_index: int | None = None) -> Tune:
    """A tune from a CLI ``diff``/``dump`` or from a blackbox log's header (``.bbl``, ``.bfl``, ``.txt``).

    ``log_index`` picks the log of a file that holds several (counting from 1; default 1); a CLI file
    takes none.

    Raises
    ------
    TuneError
        The file cannot be read, is neither form, has no log ``log_index``, has a bad line, or is
        larger than a Betaflight diff or dump (:data:`MAX_CLI_BYTES`) or header (:data:`MAX_HEADER_LINES`).
    """
    path = Path(path)
    data = _read(path).removeprefix(_BOM.encode())
    if data.lstrip().startswith(b"H Product:") or b"\nH Product:" in data[:4096]:
        try:
            starts = _log_starts(data)  # only the log asked for is read whole
        except TuneError as error:
            raise TuneError(f"{path}: {error}") from None
        log_index = 1 if log_index is None else log_index
        if isinstance(log_index, bool) or not isinstance(log_index, int) or not 1 <= log_index <= len(starts):
            raise TuneError(f"{path}:{log_index!r}: no such log; the file holds {len(starts)} log(s), "
                            f"allowed {path}:1 … {path}:{len(starts)}")
        source = f"{path}#log{log_index}"
        return tune_from_blackbox_header(_header_at(data, starts[log_index - 1]), source=source)
    if len(data) > MAX_CLI_BYTES:
        raise TuneError(f"{path}: {len(data)} bytes, larger than any Betaflight CLI diff or dump (at most "
                        f"{MAX_CLI_BYTES // 1024} KiB) and no blackbox log (no 'H Product:' header)")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        line = data[:error.start].count(b"\n") + 1
        raise TuneError(f"{path}: line {line}: byte 0x{data[error.start]:02x} is not UTF-8 text: neither a Betaflight "
                        "CLI diff/dump nor a blackbox log (no 'H Product:' header)") from None
    if log_index is not None:
        raise TuneError(f"{path}:{log_index}: the file is a CLI diff/dump, not a blackbox log: it holds no log "
                        f"{log_index}")
    return parse_cli(text, source=str(path))


_CHANGE = re.compile(r"([A-Za-z0-9_]+) *= *(.+?) *")


def with_settings(tune: Tune, changes: Sequence[str]) -> Tune:
    """``tune`` with single settings changed, each ``NAME=VALUE`` (``p_roll=90``), in the firmware's own terms.

    A change lands in the section (master, the flown profile or rate profile) where ``tune`` sets that name,
    else in master, after everything the tune sets, so it wins. Values are checked when the tune is
    translated (:func:`~aerobat.firmware.betaflight.translate.translate`), and a refusal names the change.

    Raises
    ------
    TuneError
        A change that is not ``NAME=VALUE``.
    """
    if not changes:
        return tune
    flown = {name: (section, tune.active_profile if section == "profile" else
                    tune.active_rateprofile if section == "rateprofile" else 0)
             for section, name, _, _ in tune.active_settings()}
    lines = list(tune.lines)
    texts = []
    for k, change in enumerate(changes, start=1):
        match = _CHANGE.fullmatch(str(change).strip())
        if match is None or text_problem(str(change)) is not None:
            raise TuneError(f"--set {shown(str(change))}: expected NAME=VALUE, e.g. --set p_roll=90")
        name, value = match.group(1).lower(), match.group(2)
        section, index = flown.get(name, ("master", 0))
        lines.append((section, index, name, value, -(len(tune.changes) + k)))
        texts.append(f"{name}={value}")
    changed = "; ".join(texts)
    return dataclasses.replace(tune, source=f"{tune.source} with {changed}", lines=tuple(lines),
                               changes=tune.changes + tuple(texts))
