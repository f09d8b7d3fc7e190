"""What Betaflight's CLI reads, and how, so that aerobat sends it nothing it would read otherwise.

The CLI is a line editor on the serial port (cli/cli.c ``processCharacter`` and
``processCharacterInteractive``). It keeps printable ASCII (0x20-0x7e) in a 256-byte buffer and
drops every other byte; CR or LF ends the line; ``#`` starts a comment that runs to the end of
the line. Entered with ``#``, as aerobat enters it, the CLI is *interactive*: DEL erases the
character before it, TAB and ``?`` complete a command name instead of being kept, Ctrl-D leaves
the CLI and reboots, Ctrl-L clears the screen. A line holding any of these, or more characters
than the buffer keeps, is not the line the firmware runs (19 DELs turn ``set profile_name =
…set p_roll = 123`` into ``set p_roll = 123``): :func:`line_problem` says what is wrong with
such a line, and :class:`~.cli.CliClient` sends none.

``set NAME = VALUE`` (cli/cli.c ``cliSet``) reads an integer setting with ``atoi``/``strtol``,
which stop at the first character that is not a decimal digit: ``1e2`` is 1, ``45.9`` is 45,
``4_5`` is 4, where Python's ``int``/``float`` read 100, 45.9 and 45 (and ``int`` also reads
``١٢`` and `` 3 ``). The only integer text both read alike is an optional sign and decimal digits
(:func:`parse_integer`); :class:`~.sitl_table.SettingRange` checks every value by it.
"""

from __future__ import annotations

import re

__all__ = ["MAX_LINE_CHARS", "line_problem", "parse_integer", "shown", "text_problem"]

MAX_LINE_CHARS = 255
"""The longest line the CLI reads whole: its buffer is ``cliBuffer[256]``, and it writes the line's
terminating zero at ``cliBuffer[length]`` (a 256-character line would put it one byte past the end)."""

_INTEGER = re.compile(r"[+-]?[0-9]+")
_NAMED = {0x00: "NUL", 0x03: "Ctrl-C", 0x04: "Ctrl-D", 0x08: "backspace", 0x09: "TAB", 0x0A: "LF", 0x0C: "Ctrl-L",
          0x0D: "CR", 0x1B: "ESC", 0x7F: "DEL"}
# printable ASCII the interactive CLI does not keep as typed
_SPECIAL = {"?": "'?' (the interactive CLI completes a command name instead of keeping it)",
            "#": "'#' (the CLI takes the rest of the line for a comment)"}


def _character(char: str) -> str:
    code = ord(char)
    if code > 0x7F:
        return f"the non-ASCII character U+{code:04X}"
    return f"the control character 0x{code:02x}" + (f" ({_NAMED[code]})" if code in _NAMED else "")


def text_problem(text: str) -> str | None:
    """None if ``text`` is printable ASCII (the only characters the CLI keeps), else what is not.

    Examples
    --------
    >>> text_problem("ACTUAL") is None
    True
    >>> text_problem("a\\x7fb")
    'the control character 0x7f (DEL) at character 2'
    """
    for position, char in enumerate(text, start=1):
        if not " " <= char <= "~":
            return f"{_character(char)} at character {position}"
    return None


def line_problem(line: str) -> str | None:
    """None if the firmware's interactive CLI runs ``line`` exactly as written, else why it would not."""
    if not isinstance(line, str):
        return f"a CLI line is text, not {type(line).__name__}"
    problem = text_problem(line)
    if problem is not None:
        return problem
    if not line.strip(" "):
        return "an empty line (the CLI runs nothing and prints no prompt)"
    for char, why in _SPECIAL.items():
        if char in line:
            return f"{why} at character {line.index(char) + 1}"
    if len(line) > MAX_LINE_CHARS:
        return f"{len(line)} characters: the CLI reads lines of at most {MAX_LINE_CHARS}"
    return None


def parse_integer(text: str) -> int | None:
    """The integer ``text`` is, if it is one as both Betaflight and aerobat read it: an optional sign and decimal
    digits, nothing else (no spaces, exponent, point, underscore or non-ASCII digit); None otherwise.

    Examples
    --------
    >>> [parse_integer(t) for t in ("45", "+045", "-3", "1e2", "45.9", "4_5", " 3", "١٢")]
    [45, 45, -3, None, None, None, None, None]
    """
    if not isinstance(text, str) or len(text) > MAX_LINE_CHARS or _INTEGER.fullmatch(text) is None:
        return None
    return int(text)


def shown(text: str, limit: int = 40) -> str:
    """``text`` as a message shows it: quoted, non-printable characters escaped, at most ``limit`` characters.

    Examples
    --------
    >>> shown("ab\\x7f")
    "'ab\\\\x7f'"
    >>> shown("A" * 50, limit=4)
    "'AAAA'... (50 characters)"
    """
    text = str(text)
    head = ascii(text[:limit])
    return head if len(text) <= limit else f"{head}... ({len(text)} characters)"
