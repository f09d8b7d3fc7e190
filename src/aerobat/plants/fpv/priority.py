"""Real-time priority for the threads that must keep the wall clock: the world's, and the ground station's.

A ground station on a busy laptop still has to send each RC frame at its deadline and take in
every motion-capture pose as it arrives. Where the user may (root, or ``CAP_SYS_NICE``), the threads
that do so run under ``SCHED_FIFO`` while a trial flies, and get their previous scheduling back
afterwards: they block between deadlines (``time.sleep``, ``select``), so they take a core only when
they have work, and the kernel keeps 5 % of every second for everything else
(``sched_rt_runtime_us``). Elsewhere nothing changes and the trial reports ``"normal"``.

Priorities: the world and its firmware (:data:`~aerobat.plants.fpv.rehearsal.WORLD_FIFO_PRIORITY`) above the ground
(:data:`GROUND_FIFO_PRIORITY`): the simulated vehicle must never wait for the station watching it.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterable, Iterator

__all__ = ["GROUND_FIFO_PRIORITY", "fifo", "real_time_threads"]

GROUND_FIFO_PRIORITY = 5
"""The ground station's real-time priority while it flies (below the rehearsal's world, 10)."""


def fifo(thread_id: int, priority: int) -> bool:
    """Put one thread (a native id; 0: the calling one) under ``SCHED_FIFO`` at ``priority``; False if not allowed."""
    try:
        os.sched_setscheduler(thread_id, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, ProcessLookupError, OSError, AttributeError):
        return False
    return True


@contextlib.contextmanager
def real_time_threads(thread_ids: Iterable[int | None], priority: int = GROUND_FIFO_PRIORITY) -> Iterator[str]:
    """``SCHED_FIFO`` at ``priority`` for ``thread_ids`` (native ids; None entries skipped) while inside.

    Yields ``"fifo"`` when every thread got it, ``"normal"`` when none did (not allowed here) and
    ``"partial"`` otherwise; on the way out each thread that was changed gets its policy back.
    """
    saved: list[tuple[int, int, os.sched_param]] = []
    wanted = [int(t) for t in dict.fromkeys(thread_ids) if t is not None]
    try:
        for thread_id in wanted:
            try:
                before = (thread_id, os.sched_getscheduler(thread_id), os.sched_getparam(thread_id))
            except (ProcessLookupError, OSError, AttributeError):
                continue
            if fifo(thread_id, priority):
                saved.append(before)
        yield "fifo" if wanted and len(saved) == len(wanted) else ("partial" if saved else "normal")
    finally:
        for thread_id, policy, param in reversed(saved):
            with contextlib.suppress(ProcessLookupError, PermissionError, OSError):
                os.sched_setscheduler(thread_id, policy, param)
