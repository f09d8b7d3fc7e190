"""Exceptions of the Betaflight plant, inside aerobat's one hierarchy (:mod:`aerobat.errors`).

Every firmware or link problem is a :class:`~aerobat.errors.PlantError` (the
plant cannot fly); a bad settings file is a :class:`~aerobat.errors.ConfigError`
raised where the file is read, and so is a CLI line the firmware would not run as
written (:class:`CliLineRefused`, never sent)::

    PlantError
    └── BetaflightError
        ├── FirmwareUnavailable     the SITL binary cannot be obtained or built
        ├── ConfigureFailed         the CLI rejected a setting, or no eeprom was saved
        ├── LinkError               MSP/CLI link problems
        │   ├── LinkTimeout         no (complete) answer in time
        │   ├── LinkClosed          the other side closed the connection
        │   └── MspError            the firmware answered an MSP request with an error
        └── FirmwareNotResponding   a lockstep step got no motor packet in time
            └── FirmwareExited      … because the firmware process is gone

    ConfigError
    └── CliLineRefused              a CLI line with a control or non-ASCII character, '#', '?', or too long
"""

from __future__ import annotations

from aerobat.errors import ConfigError, PlantError

__all__ = [
    "BetaflightError",
    "CliLineRefused",
    "ConfigureFailed",
    "FirmwareExited",
    "FirmwareNotResponding",
    "FirmwareUnavailable",
    "LinkClosed",
    "LinkError",
    "LinkTimeout",
    "MspError",
]


class BetaflightError(PlantError):
    """Base of every error the Betaflight plant raises on purpose."""


class FirmwareUnavailable(BetaflightError):
    """The SITL firmware cannot be obtained or built; the message says why and what to do."""


class CliLineRefused(ConfigError):
    """A line :class:`~.cli.CliClient` does not send: the firmware's CLI would not run it as written
    (:func:`~.cli_grammar.line_problem`). A :class:`ValueError`, so a caller's bad argument reads as one."""


class ConfigureFailed(BetaflightError):
    """Applying the CLI settings failed; the message names the command and the firmware's answer."""


class LinkError(BetaflightError):
    """A problem on an MSP or CLI link."""


class LinkTimeout(LinkError):
    """No complete answer arrived within the timeout."""


class LinkClosed(LinkError):
    """The other end closed the link."""


class MspError(LinkError):
    """The flight controller answered an MSP request with an error frame ('!')."""


class FirmwareNotResponding(BetaflightError):
    """A lockstep step got no motor packet within the timeout.

    The caller should discard the instance (``close()``) and start a new one
    (``restart()``); the lockstep sequence cannot be resumed.

    Parameters
    ----------
    message : str
        What happened.
    log_tail : str
        The last lines of the firmware's log, for diagnosis.
    log_path : str or None
        Where the full log is (it is deleted on close unless kept).
    """

    def __init__(self, message: str, log_tail: str = "", log_path: str | None = None) -> None:
        details = f"{message}\n--- last firmware log lines ---\n{log_tail}" if log_tail else message
        super().__init__(details)
        self.log_tail = log_tail
        self.log_path = log_path


class FirmwareExited(FirmwareNotResponding):
    """The firmware process exited (or was killed); ``returncode`` is its exit status."""

    def __init__(self, returncode: int, log_tail: str = "", log_path: str | None = None) -> None:
        super().__init__(f"the SITL firmware exited with status {returncode}", log_tail, log_path)
        self.returncode = returncode
