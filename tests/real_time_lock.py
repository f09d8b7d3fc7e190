"""One wall-clock flight at a time, whatever the scheduler does (a pytest plugin; tests/conftest.py loads it).

Tests marked ``xdist_group("real_time")`` fly on the wall clock (tests/README.md). ``make test`` sends
them to one worker with ``--dist loadgroup``, but that grouping has failed silently before: pytest 9.2
ignores the node-id suffix pytest-xdist 3.8 groups by (pytest-dev/pytest-xdist#1386), so two rehearsals
flew at once beside the rest of the suite and one did not settle in 20 s. Here each such test holds an
exclusive lock on one file for its whole run (set-up and tear-down included), shared by every worker of
the session and by any other pytest session of this user on the machine, so two never overlap.
"""

from __future__ import annotations

import fcntl
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

GROUP = "real_time"
LOCK_ENV = "AEROBAT_REAL_TIME_LOCK"
"""Where the lock file is (default: ``aerobat-real-time.lock`` in the temporary folder)."""


def lock_path() -> Path:
    """The lock file every wall-clock test takes."""
    return Path(os.environ.get(LOCK_ENV) or Path(tempfile.gettempdir()) / f"aerobat-real-time-{os.getuid()}.lock")


def flies_on_the_wall_clock(item: pytest.Item) -> bool:
    """The test carries ``xdist_group("real_time")`` (on itself, its class or its module)."""
    return any((mark.args[0] if mark.args else mark.kwargs.get("name")) == GROUP
               for mark in item.iter_markers("xdist_group"))


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    if not flies_on_the_wall_clock(item):
        return (yield)
    fd = os.open(lock_path(), os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)  # waits for another worker's flight to end
        return (yield)
    finally:
        os.close(fd)  # drops the lock
