"""The ``aerobat`` command line: argument parsing and printing only; nothing imports it.

See :mod:`aerobat.cli.app` for the exit statuses and ``docs/cli.md`` for the commands.
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``aerobat`` with ``argv`` (default: the process's arguments); returns the exit status."""
    from aerobat.cli.app import main as run

    return run(argv)
