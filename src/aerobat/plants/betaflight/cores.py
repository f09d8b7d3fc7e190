"""A core each for the driver and the firmware while they spin for each other (issue 46).

Over spinning shared memory the driver and the lockstep firmware hand each step to each other
in a fraction of a microsecond while each has a core. Left to the scheduler, beside one busy
process the two were often put on one core, where each spins out its budget while the other
cannot run: the triple flip flew at 14–18× real time, and at 60× with the two pinned to a core
each (docs/performance.md, "Betaflight on a shared machine"). :func:`claim_core_pair` takes a
pair of the cores this thread may use, held by a lock file per pair, so that instances in other
processes (a study's workers) take other pairs; when every pair is taken, or fewer than two cores
are allowed, it returns None and nothing is pinned. :meth:`CorePair.release` restores the
driver thread's cores and drops the lock; a process that dies drops its locks with it.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import threading
from dataclasses import dataclass, field

from aerobat.firmware.betaflight.build import default_cache_dir

__all__ = ["CorePair", "claim_core_pair"]


@dataclass
class CorePair:
    """Two cores held for one flight: ``driver`` for the driver's thread, ``firmware`` for the firmware."""

    driver: int
    firmware: int
    thread_id: int
    """The native id of the driver's thread (its cores are restored on release)."""
    previous: frozenset[int]
    """The driver thread's cores before."""
    _lock: int | None = field(default=None, repr=False)

    def release(self) -> None:
        """Give the driver's thread its cores back and drop the pair's lock (idempotent)."""
        if self._lock is None:
            return
        with contextlib.suppress(OSError):  # the thread may be gone
            os.sched_setaffinity(self.thread_id, self.previous)
        os.close(self._lock)  # drops the flock
        self._lock = None


def claim_core_pair(firmware_pid: int) -> CorePair | None:
    """Pin the calling (driver) thread and the process ``firmware_pid`` to a free pair of this thread's cores.

    Pairs are the allowed cores taken two by two in order; the first pair whose lock file is free
    is taken. None (nothing pinned) with fewer than two allowed cores or every pair taken.
    """
    allowed = sorted(os.sched_getaffinity(0))
    if len(allowed) < 2:
        return None
    folder = default_cache_dir() / "cores"
    folder.mkdir(parents=True, exist_ok=True)
    for k in range(0, len(allowed) - 1, 2):
        driver, firmware = allowed[k], allowed[k + 1]
        fd = os.open(folder / f"pair-{driver}-{firmware}.lock", os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        pair = CorePair(driver=driver, firmware=firmware, thread_id=threading.get_native_id(),
                        previous=frozenset(allowed), _lock=fd)
        try:
            os.sched_setaffinity(firmware_pid, {firmware})
            os.sched_setaffinity(0, {driver})
        except OSError:  # the firmware already gone, or the cores refused: fly unpinned
            pair.release()
            return None
        return pair
    return None
