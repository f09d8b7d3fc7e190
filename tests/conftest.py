"""Suite-wide guards."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(autouse=True, scope="session")
def _the_suite_leaves_the_users_store_alone():
    """No test may write the default store ``./aerobat.sqlite`` of the folder it runs in: give it ``--db``."""
    path = Path.cwd() / "aerobat.sqlite"

    def stamp():
        return path.stat().st_mtime_ns if path.exists() else None

    before = stamp()
    yield
    assert stamp() == before, f"a test wrote {path}: tests must pass --db (or run in a temporary folder)"


@pytest.fixture(autouse=True, scope="session")
def _ctrl_c_raises_keyboard_interrupt():
    """The Ctrl-C tests need SIGINT to raise KeyboardInterrupt, however the suite was started.

    A shell without job control starts a background command (``make test &``, ``nohup … &``)
    with SIGINT ignored, and Python then leaves it ignored: a Ctrl-C test would see nothing. The
    suite restores Python's default handler (its subprocesses then start with the default too).
    """
    import signal

    previous = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    if previous is not None:  # None: a handler not installed from Python, which cannot be put back
        signal.signal(signal.SIGINT, previous)
