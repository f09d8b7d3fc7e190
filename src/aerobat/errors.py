"""Every exception aerobat raises on purpose, in one hierarchy.

The library raises these; it never decides exit statuses or prints. The command
line owns one table from these classes to exit statuses (``aerobat.cli.app``).
Anything else that escapes is a bug and is reported as an internal error.

::

    AerobatError
    ├── ConfigError            bad input: a file, field, option or argument (also a ValueError)
    ├── MissingDependency      an optional package is not installed (also an ImportError)
    ├── DesignFailed           the nominal design did not converge or is unusable
    ├── IdentificationFailed   too few usable identification trials, or a fit too poor to use
    ├── SolveFailed            a time-optimal benchmark solve failed
    ├── PlantError             a plant could not fly (firmware gone, simulator broken)
    ├── OutputError            an output file or folder could not be written
    │   └── DiskFull           … because the disk (or a file size limit) is full
    └── StoreError             the experiment store (see :mod:`aerobat.store`)
        ├── StoreAccessError   cannot open, create or write the file
        ├── StoreFormatError   not an aerobat store, or damaged
        ├── StoreVersionError  written by a newer aerobat
        ├── SessionNotFound    no such session or study
        ├── SessionInUse       run by another live process
        ├── StoreWriteError    a write failed while running (disk full, I/O error)
        └── StoreBusyError     locked by another process for too long
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "AerobatError",
    "ConfigError",
    "DesignFailed",
    "DiskFull",
    "IdentificationFailed",
    "MissingDependency",
    "OutputError",
    "PlantError",
    "SessionInUse",
    "SessionNotFound",
    "SolveFailed",
    "StoreAccessError",
    "StoreBusyError",
    "StoreError",
    "StoreFormatError",
    "StoreVersionError",
    "StoreWriteError",
    "WorkersUnavailable",
    "require",
]


class AerobatError(Exception):
    """Base of every error aerobat raises on purpose; the message says what and where."""


class ConfigError(AerobatError, ValueError):
    """Bad input: the message names the file or option, the field, the value and the allowed range."""


class MissingDependency(AerobatError, ImportError):
    """An optional package is not installed.

    Attributes
    ----------
    package : the importable module that is missing (``"rotorpy"``).
    extra : the aerobat extra that installs it (``"rotorpy"`` → ``pip install 'aerobat[rotorpy]'``).
    purpose : what needs it, for the message.
    """

    def __init__(self, package: str, *, extra: str, purpose: str, detail: str = "") -> None:
        self.package = package
        self.extra = extra
        self.purpose = purpose
        more = f" ({detail})" if detail else ""
        super().__init__(f"{purpose} needs the optional package {package}{more}; install it with: "
                         f"pip install 'aerobat[{extra}]'", name=package)

    @property
    def install_hint(self) -> str:
        return f"pip install 'aerobat[{self.extra}]'"


def require(module: str, *, extra: str, purpose: str) -> Any:
    """Import ``module`` or raise :class:`MissingDependency` with the install hint."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise MissingDependency(module.split(".")[0], extra=extra, purpose=purpose, detail=str(exc)) from None


class DesignFailed(AerobatError):
    """The nominal design did not converge or its Jacobian is unusable; ``design`` holds the result."""

    def __init__(self, message: str, design: Any = None) -> None:
        super().__init__(message)
        self.design = design


class IdentificationFailed(AerobatError):
    """No vehicle was identified: too few usable trials, or a fit whose residual is too large.

    ``result`` holds the fit (or None if it was refused before fitting); the message says
    what is missing or which residual is too large.
    """

    def __init__(self, message: str, result: Any = None) -> None:
        super().__init__(message)
        self.result = result


class SolveFailed(AerobatError):
    """A time-optimal benchmark solve failed; ``solution`` holds the (failed) result if any."""

    def __init__(self, message: str, solution: Any = None) -> None:
        super().__init__(message)
        self.solution = solution


class PlantError(AerobatError):
    """A plant cannot fly at all (as opposed to one trial failing, which is a :class:`~aerobat.core.plant.Trial`)."""


class WorkersUnavailable(AerobatError):
    """A process pool's workers could not start: no job ran (an infrastructure failure, not failed jobs)."""


class OutputError(AerobatError):
    """An output file or folder could not be written; the message names it and why."""


class DiskFull(OutputError):
    """Writing an output failed because the disk, or a file size limit, is full."""


# ------------------------------------------------------------------ store


class StoreError(AerobatError):
    """A problem with the experiment store; the message names the file and what is wrong."""


class StoreAccessError(StoreError):
    """The file cannot be opened or created, or is read-only where writing is needed."""


class StoreFormatError(StoreError):
    """Not an aerobat database: not SQLite at all, another application's SQLite file, or corrupted."""


class StoreVersionError(StoreError):
    """Written by a newer aerobat (a schema version this one does not know)."""


class SessionNotFound(StoreError):
    """No session (or study) with that id."""


class SessionInUse(StoreError):
    """The session is being run by another live process."""


class StoreWriteError(StoreError):
    """A write failed while running: disk full, file size limit, I/O error."""


class StoreBusyError(StoreError):
    """Another process kept the database locked for longer than the busy timeout."""
