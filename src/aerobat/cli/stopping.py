"""SIGTERM ends a command the way Ctrl-C does: through the code that stores what was done.

By default SIGTERM kills Python at once, with no message and none of the ``finally`` blocks
that end a study's workers. :func:`sigterm_stops` turns it into :class:`Stopped`, a
KeyboardInterrupt, so everything that handles Ctrl-C handles it too; ``aerobat`` then exits with
128 + the signal's number (143) after one line on stderr.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from typing import Any

__all__ = ["Stopped", "sigterm_stops"]


class Stopped(KeyboardInterrupt):
    """A command stopped by a signal: ``signum`` and the line to print (without ``aerobat: ``)."""

    def __init__(self, signum: int, message: str = "") -> None:
        super().__init__(message or f"interrupted by {signal.Signals(signum).name}")
        self.signum = signum
        self.message = message or f"interrupted by {signal.Signals(signum).name}"


def _raise_stopped(signum: int, frame: Any) -> None:
    raise Stopped(signum)


@contextlib.contextmanager
def sigterm_stops(*, standalone: bool = False) -> Iterator[None]:
    """While inside, SIGTERM raises :class:`Stopped` (on the main thread; elsewhere nothing changes).

    ``standalone`` (the process ends after the command): once stopped, further SIGINT and SIGTERM
    are ignored, so a repeated signal cannot kill the interpreter while it shuts down.
    """
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(signal.SIGTERM) is _raise_stopped:
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_stopped)
    stopped = False
    try:
        yield
    except KeyboardInterrupt:
        stopped = True
        raise
    finally:
        if stopped and standalone:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
        else:
            signal.signal(signal.SIGTERM, previous)
