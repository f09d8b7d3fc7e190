"""The settings this SITL build accepts, read from the firmware itself (``sitl_settings.json``).

Betaflight's setting table (``src/main/cli/settings.c``) depends on the build's ``#define``\\ s:
the SITL has no OSD, VTX, ESC telemetry, ... so the authoritative list of what *this* binary
accepts is what its CLI reports. :func:`.table_reader.read_table` starts a SITL from a blank eeprom, takes the
names and their section (master, PID profile, rate profile) from ``dump all`` and each one's range
or allowed values and default from ``get NAME``. The result is shipped as ``sitl_settings.json``
(so parsing a tune needs no firmware); ``python -m aerobat.firmware.betaflight.table_reader``
regenerates it (:mod:`.table_reader`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from enum import StrEnum
from functools import lru_cache
from pathlib import Path

from .cli_grammar import MAX_LINE_CHARS, parse_integer, text_problem

__all__ = ["SITL_TABLE_PATH", "Checked", "SettingRange", "SitlTable", "Verdict", "load_table"]

SITL_TABLE_PATH = Path(__file__).with_name("sitl_settings.json")


class Verdict(StrEnum):
    """What a setting makes of a value (:meth:`SettingRange.checked`)."""

    ACCEPTED = "accepted"
    """The firmware takes it, as :attr:`Checked.value` (the text it prints back)."""
    REJECTED = "rejected"
    """A value of the setting's type that this build does not take: out of range, not one of the
    allowed names, a string too long. Another version may have taken it (4.2's ``acc_lpf_hz = 1000``)."""
    MALFORMED = "malformed"
    """Not a value of the setting's type as the firmware's CLI reads one (``1e2``, ``45.9`` or ``abc`` for
    an integer, a control or non-ASCII character anywhere): no Betaflight version wrote it."""


@dataclass(frozen=True)
class Checked:
    """A value as a setting takes it.

    Attributes
    ----------
    verdict : :class:`Verdict`.
    value : accepted: the value as the firmware prints it back (``+045`` → ``45``, ``actual`` →
        ``ACTUAL``); otherwise the value given, without its surrounding spaces.
    reason : why it is not accepted, naming what the setting allows; empty when accepted.
    """

    verdict: Verdict
    value: str
    reason: str = ""


@dataclass(frozen=True)
class SettingRange:
    """What one setting accepts, as the firmware's ``get NAME`` reports it.

    Attributes
    ----------
    name : the 4.6 CLI name.
    section : ``"master"``, ``"profile"`` (PID profile) or ``"rateprofile"``.
    low, high : integer range (None for a lookup, a string or an array).
    values : allowed lookup names (empty for a number).
    default : the firmware's default, as the CLI prints it.
    array : the value is a comma-separated array (``Array length``), length given.
    string : the value is text (``String length: min_length - max_length``).
    min_length, max_length : a string's length range (0 for other settings).
    """

    name: str
    section: str
    low: float | None
    high: float | None
    values: tuple[str, ...]
    default: str
    array: int = 0
    string: bool = False
    min_length: int = 0
    max_length: int = 0

    def allowed(self) -> str:
        """What the setting takes, in words (``allowed 0..250``)."""
        if self.values:
            return f"allowed {', '.join(self.values)}"
        if self.string:
            return (f"allowed {self.min_length}-{self.max_length} printable ASCII characters other than '#' and "
                    "'?' ('-' for empty)")
        if self.array:
            return f"allowed {self.array} comma-separated integers"
        if self.low is not None and self.high is not None:
            return f"allowed {int(self.low)}..{int(self.high)}"
        return "allowed an integer"

    def checked(self, value: str) -> Checked:
        """What the firmware makes of ``value`` (surrounding spaces aside, which its CLI drops).

        An integer must be an optional sign and decimal digits (what ``atoi`` reads whole) within
        ``low..high``; a lookup one of ``values``, in any case; a string printable ASCII of
        ``min_length..max_length`` characters; an array ``array`` integers separated by commas.
        """
        if not isinstance(value, str):
            return Checked(Verdict.MALFORMED, str(value), f"expected text, got {type(value).__name__}; "
                                                          f"{self.allowed()}")
        text = value.strip(" ")
        problem = text_problem(text)
        if problem is None and len(text) > MAX_LINE_CHARS:
            problem = f"{len(text)} characters, more than the firmware's CLI reads in a line ({MAX_LINE_CHARS})"
        if problem is not None:
            return Checked(Verdict.MALFORMED, text, f"{problem}; {self.allowed()}")
        if self.values:
            name = text.upper()
            return (Checked(Verdict.ACCEPTED, name) if name in self.values
                    else Checked(Verdict.REJECTED, text, self.allowed()))
        if self.string:
            special = next((c for c in "#?" if c in text), None)
            if special is not None:
                return Checked(Verdict.REJECTED, text, f"the firmware's CLI cannot enter {special!r}; {self.allowed()}")
            if not self.min_length <= len(text) <= self.max_length:
                return Checked(Verdict.REJECTED, text, f"{len(text)} characters; {self.allowed()}")
            return Checked(Verdict.ACCEPTED, text)
        parts = [part.strip(" ") for part in text.split(",")] if self.array else [text]
        numbers = [parse_integer(part) for part in parts]
        if any(number is None for number in numbers):
            return Checked(Verdict.MALFORMED, text, "not an integer as the firmware reads one (an optional sign and "
                                                    f"decimal digits); {self.allowed()}")
        if self.array and len(parts) != self.array:
            return Checked(Verdict.REJECTED, text, f"{len(parts)} values; {self.allowed()}")
        for number in numbers:
            assert number is not None
            if self.low is not None and self.high is not None and not self.low <= number <= self.high:
                return Checked(Verdict.REJECTED, text, f"out of range, {self.allowed()}")
        return Checked(Verdict.ACCEPTED, ",".join(str(number) for number in numbers))

    def check(self, value: str) -> str | None:
        """None if ``value`` is accepted, else why not (:meth:`checked`'s reason)."""
        result = self.checked(value)
        return None if result.verdict is Verdict.ACCEPTED else result.reason


@dataclass(frozen=True)
class SitlTable:
    """Every setting of the SITL build, by name."""

    firmware: str
    settings: dict[str, SettingRange]
    features: tuple[str, ...]
    all_names: frozenset[str]

    def get(self, name: str) -> SettingRange | None:
        return self.settings.get(name.lower())


@lru_cache(maxsize=1)
def load_table(path: Path | None = None) -> SitlTable:
    """The shipped table (``sitl_settings.json``)."""
    data = json.loads((path or SITL_TABLE_PATH).read_text())
    settings = {
        name: SettingRange(name, e["section"], e["low"], e["high"], tuple(e["values"]), e["default"],
                           int(e["array"]), bool(e["string"]), int(e["min_length"]), int(e["max_length"]))
        for name, e in data["settings"].items()
    }
    return SitlTable(data["firmware"], settings, tuple(data["features"]), frozenset(data["all_4_6_names"]))
