"""Client of the firmware's CLI (Betaflight's text console): enter with '#', send a command, read until the prompt.

The CLI prompt is ``"\\r\\n# "`` (``cliPrompt`` in cli/cli.c); errors are
printed as ``###ERROR IN <command>: <message>###``. The firmware echoes what
it receives.

A command is sent only if the firmware runs it exactly as written
(:func:`.cli_grammar.line_problem`): one line of printable ASCII without ``#``
or ``?``, at most 255 characters. Anything else (a DEL erases the character
before it in the interactive CLI, a CR ends the line) is refused with
:class:`~.errors.CliLineRefused` before a byte leaves.

Entering the CLI sets the CLI arming-disable flag for the life of the
process, even after ``exit noreboot``: a flying process must never open it.
"""

from __future__ import annotations

import time

from .cli_grammar import line_problem, shown
from .errors import CliLineRefused, ConfigureFailed, LinkClosed, LinkTimeout
from .transport import Transport

__all__ = ["CLI_PROMPT", "CliClient"]

CLI_PROMPT = "\r\n# "
_ERROR_MARK = "###ERROR"


class CliClient:
    """A CLI session over a :class:`~.transport.Transport`.

    Parameters
    ----------
    transport : Transport
        Byte link to the flight controller (the same port serves MSP).
    timeout_s : float
        Default time to wait for the prompt after a command.
    quiet_s : float
        After the prompt appears, how long no further output must arrive
        before the answer is taken as complete (``diff`` output contains
        ``# `` comment lines that could look like a prompt at a chunk border).
    """

    def __init__(self, transport: Transport, timeout_s: float = 5.0, quiet_s: float = 0.05) -> None:
        self._transport = transport
        self._timeout_s = timeout_s
        self._quiet_s = quiet_s
        self.active = False

    def _read_until_prompt(self, timeout_s: float) -> str:
        deadline = time.monotonic() + timeout_s
        received = bytearray()
        while True:
            remaining_s = deadline - time.monotonic()
            if remaining_s <= 0:
                tail = received[-200:].decode("ascii", "replace")
                raise LinkTimeout(f"no CLI prompt within {timeout_s} s; last output: {tail!r}")
            if received.endswith(CLI_PROMPT.encode()):
                more = self._transport.read(65536, min(self._quiet_s, remaining_s))
                if not more:
                    return received.decode("ascii", "replace")
                received += more
            else:
                received += self._transport.read(65536, remaining_s)

    def enter(self) -> str:
        """Enter CLI mode (send '#') and return the banner."""
        self._transport.write(b"#")
        banner = self._read_until_prompt(self._timeout_s)
        self.active = True
        return banner

    def command(self, line: str, timeout_s: float | None = None, check: bool = True) -> str:
        """Run one CLI command and return its output (without echo and prompt).

        Parameters
        ----------
        line : str
            The command, e.g. ``"set pwr_on_arm_grace = 0"``.
        timeout_s : float, optional
            Time to wait for the prompt (default: the client's).
        check : bool
            Raise :class:`ConfigureFailed` when the output reports an error.

        Raises
        ------
        CliLineRefused
            The firmware would not run ``line`` as written (a control or non-ASCII character, ``#``,
            ``?``, more than 255 characters, or more than one line); nothing was sent.
        """
        problem = line_problem(line)
        if problem is not None:
            raise CliLineRefused(f"CLI command {shown(line)} not sent: {problem}")
        if not self.active:
            raise RuntimeError("call enter() first")
        self._transport.write(line.encode("ascii") + b"\n")
        output = self._read_until_prompt(self._timeout_s if timeout_s is None else timeout_s)
        output = output[: -len(CLI_PROMPT)]
        lines = output.replace("\r\n", "\n").split("\n")
        if lines and lines[0].strip() == line.strip():
            lines = lines[1:]
        text = "\n".join(lines).strip("\n")
        if check and _ERROR_MARK in text:
            raise ConfigureFailed(f"CLI command {line!r} failed: {text.strip()}")
        return text

    def save(self, timeout_s: float = 10.0) -> str:
        """Send ``save``: the firmware writes its eeprom and reboots (the SITL exits).

        Returns what the firmware printed before the link closed.
        """
        if not self.active:
            raise RuntimeError("call enter() first")
        self._transport.write(b"save\n")
        deadline = time.monotonic() + timeout_s
        received = bytearray()
        while time.monotonic() < deadline:
            try:
                received += self._transport.read(65536, deadline - time.monotonic())
            except LinkClosed:
                break
        self.active = False
        return received.decode("ascii", "replace")
