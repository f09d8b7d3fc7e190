"""Running independent jobs: a local process pool by default, a Dask cluster on request.

A job is a pure function of its specification and seed (:class:`Job`), so it runs
the same anywhere and its result can be checked against another run. Results are
yielded as they complete, so callers can record them immediately (a study that is
interrupted keeps everything that finished).

Dask is optional (``pip install 'aerobat[dask]'``); it is imported only when a
scheduler address is given (``--scheduler tcp://HOST:PORT`` or the environment
variable ``DASK_SCHEDULER_ADDRESS``).
"""

from __future__ import annotations

import gc
import multiprocessing
import os
import signal
import threading
from collections.abc import Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any, Protocol

from aerobat.errors import ConfigError
from aerobat.experiments.job import Job, JobResult, JobStatus, run_job

__all__ = ["DaskExecutor", "Executor", "LocalExecutor", "make_executor"]


def _collect(future: Any) -> JobResult:
    """The result of a finished future; a worker that died or could not return is a failed job."""
    try:
        result = future.result()
    except Exception as exc:  # the worker process died, or the result could not be sent back
        return JobResult(JobStatus.FAILED, {}, f"the worker running it failed: {type(exc).__name__}: {exc}")
    return result if isinstance(result, JobResult) else JobResult(JobStatus.FAILED, {}, f"bad job result {result!r}")


def _completed(futures: Iterable[Future]) -> Iterator[Future]:
    """Futures as they complete, like ``as_completed``, with Ctrl-C raised only between waits.

    A KeyboardInterrupt raised asynchronously inside the pool's locks (``as_completed`` holds
    them while it waits) can leave a lock released twice: the interrupted command then dies of
    ``RuntimeError: release unlocked lock`` instead of stopping. Here a Ctrl-C only sets a flag
    (when the default handler is in place, on the main thread), checked every 0.2 s and between
    results, and is raised from there.
    """
    pending = set(futures)
    interrupted: list[int] = []
    previous = None
    if threading.current_thread() is threading.main_thread() and \
            signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        previous = signal.signal(signal.SIGINT, lambda signum, frame: interrupted.append(signum))
    try:
        while pending:
            if interrupted:
                raise KeyboardInterrupt
            done, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            for future in done:
                yield future
                if interrupted:
                    raise KeyboardInterrupt
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


class Executor(Protocol):
    """Runs jobs, yielding (job, result) pairs as they complete."""

    workers: int

    def run(self, jobs: Iterable[Job]) -> Iterator[tuple[Job, JobResult]]: ...

    def close(self) -> None: ...


def _worker_init() -> None:
    # one simulation thread per worker process: the pool already uses every core
    from aerobat.quadrotor.simulate import set_batch_threads

    set_batch_threads(1)


class LocalExecutor:
    """A process pool on this machine (spawned workers, one simulation thread each)."""

    def __init__(self, workers: int | None = None) -> None:
        self.workers = workers or os.cpu_count() or 1
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) or not 1 <= self.workers <= 1024:
            raise ConfigError(f"workers = {self.workers!r}: allowed integers 1 … 1024")
        self._pool: ProcessPoolExecutor | None = None

    def run(self, jobs: Iterable[Job]) -> Iterator[tuple[Job, JobResult]]:
        jobs = list(jobs)
        if not jobs:
            return
        if self.workers == 1:  # in this process, whose batches may use every core
            for job in jobs:
                yield job, run_job(job)
            return
        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_worker_init)
        futures = {self._pool.submit(run_job, job): job for job in jobs}
        try:
            for future in _completed(futures):
                yield futures[future], _collect(future)
        finally:
            for future in futures:
                future.cancel()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


class DaskExecutor:
    """Jobs on a ``dask.distributed`` cluster (any scheduler address, or an in-process client)."""

    def __init__(self, address: str | None = None, *, client: Any = None) -> None:
        from aerobat.errors import require

        Client = require("distributed", extra="dask", purpose="running studies on a Dask cluster").Client
        self._own = client is None
        if client is None:
            where = f"Dask scheduler {address!r} (--scheduler or $DASK_SCHEDULER_ADDRESS)"
            problem = None
            try:
                client = Client(address, timeout="10s")
            except (ValueError, TypeError) as exc:  # not an address distributed can use
                problem = f"{where}: expected tcp://HOST:PORT: {exc}"
            except Exception as exc:  # unreachable, or something else answers there (its replies can be anything)
                problem = f"{where}: cannot connect: {type(exc).__name__}: {exc}"
            if problem is not None:
                # The half-made Client is garbage in a reference cycle; its __del__ closes it under
                # distributed's loop-runner lock. Collected later, in whatever thread the collector
                # runs, that deadlocked the next Client: its loop thread collected the old one while
                # the starting thread held the lock and waited for the loop thread. Collect it here.
                gc.collect()
                raise ConfigError(problem)
        self.client = client
        self.workers = max(1, sum(w.get("nthreads", 1) for w in self.client.scheduler_info()["workers"].values()))

    def run(self, jobs: Iterable[Job]) -> Iterator[tuple[Job, JobResult]]:
        from distributed import as_completed as dask_completed

        jobs = list(jobs)
        if not jobs:
            return
        futures = self.client.map(run_job, jobs, key=[f"aerobat-{j.key}-{abs(hash(j.to_json()))}" for j in jobs],
                                  pure=False)
        index = {f.key: job for f, job in zip(futures, jobs, strict=True)}
        try:
            for future in dask_completed(futures):
                yield index[future.key], _collect(future)
        finally:
            self.client.cancel(futures)

    def close(self) -> None:
        if self._own:
            self.client.close()


def make_executor(*, scheduler: str | None = None, workers: int | None = None) -> Executor:
    """The Dask cluster at ``scheduler`` (or ``$DASK_SCHEDULER_ADDRESS``), else a local pool."""
    address = scheduler or os.environ.get("DASK_SCHEDULER_ADDRESS")
    if address:
        return DaskExecutor(address)
    return LocalExecutor(workers)
