"""Naming one log inside a file: ``FILE:N`` (log N of FILE, from 1), the one grammar every command takes."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from aerobat.errors import ConfigError

__all__ = ["LogRef", "parse_log_ref"]


@dataclass(frozen=True)
class LogRef:
    """A log in a file: ``path`` and ``index`` (from 1; None: every log in the file)."""

    path: Path
    index: int | None = None

    def __str__(self) -> str:
        return f"{self.path}" + (f":{self.index}" if self.index is not None else "")

    def with_index(self, index: int | None, option: str = "--index") -> LogRef:
        """This reference with ``index`` given separately (an option); both given and different is an error."""
        if index is None:
            return self
        if self.index is not None and self.index != index:
            raise ConfigError(f"{self}: names log {self.index}, {option} {index} another; give one of them")
        return LogRef(self.path, index)


def parse_log_ref(text: str | os.PathLike[str]) -> LogRef:
    """``FILE`` or ``FILE:N`` (log N of FILE, from 1). A file whose own name ends in ``:N`` is that file."""
    raw = os.fspath(text)
    head, sep, tail = raw.rpartition(":")
    if sep and head and tail.isascii() and tail.isdigit() and not os.path.lexists(raw):
        index = int(tail)
        if index < 1:
            raise ConfigError(f"{raw}: log numbers start at 1")
        return LogRef(Path(head), index)
    return LogRef(Path(raw))
