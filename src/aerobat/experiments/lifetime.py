"""Worker processes that never outlive their owner.

A spawned worker of a :class:`~concurrent.futures.ProcessPoolExecutor` waits for work on a pipe
whose writing end it holds itself, so it never sees its owner go: after a SIGKILL of the owner it
would wait forever, keeping the owner's standard output open (a caller reading that pipe blocks)
and multiprocessing's resource tracker alive. Every process pool aerobat starts is made by
:func:`process_pool`, whose workers

- get SIGKILL from the kernel when the thread that started them ends (Linux ``PR_SET_PDEATHSIG``),
  at once even while a compiled kernel holds the worker's interpreter lock;
- watch their owner's sentinel pipe from a thread (any POSIX system) and exit when it closes;
- exit at start-up when their owner is already gone;
- ignore SIGINT: a Ctrl-C reaches the whole terminal's process group, and the owner, which
  records the results, decides what stops (it ends its workers itself).

A worker has nothing of its own to save (the owner commits every result), so it exits at once.
The resource tracker exits by itself once the owner and every worker are gone.

PR_SET_PDEATHSIG is tied to the *thread* that started the worker: submit jobs to a pool from a
thread that lives as long as the pool (:class:`~aerobat.experiments.execution.LocalExecutor`
makes a new pool when it is used from another thread).
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from typing import Any

__all__ = ["process_pool", "watch_owner"]

_PR_SET_PDEATHSIG = 1
_ORPHANED = 1  # a worker's exit status when its owner is gone


def _prctl() -> Callable[..., int] | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


def watch_owner(owner_pid: int) -> None:
    """In a worker: exit when the process ``owner_pid`` (its parent) is gone, now or later."""
    prctl = _prctl()
    if prctl is not None:
        prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if os.getppid() != owner_pid:  # the owner died before the kernel could be told
        os._exit(_ORPHANED)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    parent = multiprocessing.parent_process()
    threading.Thread(target=_wait_for_owner, args=(parent, owner_pid), name="aerobat-owner-watch",
                     daemon=True).start()


def _wait_for_owner(parent: Any, owner_pid: int) -> None:
    if parent is not None and parent.pid == owner_pid:
        parent.join()  # the sentinel pipe: only the owner holds its other end; it closes when the owner dies
    else:  # not a spawned multiprocessing child: poll the parent's pid
        while os.getppid() == owner_pid:
            time.sleep(0.5)
    os._exit(_ORPHANED)


def _start_worker(owner_pid: int, initializer: Callable[..., object] | None, initargs: tuple) -> None:
    watch_owner(owner_pid)
    if initializer is not None:
        initializer(*initargs)


def process_pool(max_workers: int, initializer: Callable[..., object] | None = None,
                 initargs: tuple = ()) -> ProcessPoolExecutor:
    """A pool of spawned workers that exit when this process dies (see the module's notes)."""
    return ProcessPoolExecutor(max_workers=max_workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_start_worker, initargs=(os.getpid(), initializer, initargs))
