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

import contextlib
import gc
import os
import signal
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Protocol

from aerobat.errors import ConfigError, WorkersUnavailable
from aerobat.experiments.job import Job, JobResult, JobStatus, run_job
from aerobat.experiments.lifetime import process_pool

__all__ = ["DaskExecutor", "Executor", "LocalExecutor", "default_workers", "make_executor"]


def _collect(future: Any) -> JobResult:
    """The result of a finished future; a worker that died or could not return is a failed job."""
    try:
        result = future.result()
    except Exception as exc:  # the worker process died, or the result could not be sent back
        return JobResult(JobStatus.FAILED, {}, f"the worker running it failed: {type(exc).__name__}: {exc}")
    return result if isinstance(result, JobResult) else JobResult(JobStatus.FAILED, {}, f"bad job result {result!r}")


_DEFERRED_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def _signals_deferred() -> Iterator[Callable[[], None]]:
    """SIGINT and SIGTERM only noted while inside; the function yielded runs their handlers now.

    A KeyboardInterrupt raised asynchronously inside a pool's locks (``as_completed`` holds
    them while it waits) can leave a lock released twice: the interrupted command then dies of
    ``RuntimeError: release unlocked lock`` instead of stopping. Inside, a signal whose handler is a
    Python function (SIGINT's default raises KeyboardInterrupt; the command line's SIGTERM handler
    raises too) only sets a flag, on the main thread; the waiting loop calls the function yielded
    between waits, which calls the handlers (whatever they raise comes out of the loop).
    """
    caught: list[int] = []
    previous: dict[int, Any] = {}
    if threading.current_thread() is threading.main_thread():
        for signum in _DEFERRED_SIGNALS:
            if callable(signal.getsignal(signum)):
                previous[signum] = signal.signal(signum, lambda number, frame: caught.append(number))

    def deliver() -> None:
        while caught:
            number = caught.pop(0)
            previous[number](number, None)

    try:
        yield deliver
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def _completed(futures: Iterable[Future]) -> Iterator[Future]:
    """Futures as they complete, like ``as_completed``, with SIGINT and SIGTERM handled only between waits
    (every 0.2 s and between results; see :func:`_signals_deferred`)."""
    pending = set(futures)
    with _signals_deferred() as deliver:
        while pending:
            deliver()
            done, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
            for future in done:
                yield future
                deliver()


class Executor(Protocol):
    """Runs jobs, yielding (job, result) pairs as they complete."""

    workers: int

    def run(self, jobs: Iterable[Job]) -> Iterator[tuple[Job, JobResult]]: ...

    def close(self) -> None: ...


_WORKER_START_TIMEOUT_S = 300.0  # a spawned worker imports aerobat and numba: seconds, minutes on a loaded machine


def _started() -> int:
    """A worker's answer that it started: its process id."""
    return os.getpid()


def _workers_started(pool: ProcessPoolExecutor) -> None:
    """Wait until a worker of ``pool`` has started; raise :class:`WorkersUnavailable` if none can.

    A spawned worker re-imports the script that made the pool; a script that starts a study at its top
    level, without ``if __name__ == "__main__":``, makes every worker die as it starts. Each job would then
    count as failed and the study would report its runs failed with exit status 0, although none ran.
    """
    try:
        pool.submit(_started).result(timeout=_WORKER_START_TIMEOUT_S)
    except BrokenProcessPool as exc:
        raise WorkersUnavailable(
            f"the study's worker processes could not start ({exc}); nothing ran. A script that runs a study with "
            f"workers > 1 must start it under `if __name__ == \"__main__\":` (each worker re-imports the "
            f"script), or use workers=1") from None
    except TimeoutError:
        raise WorkersUnavailable(f"no worker process started within {_WORKER_START_TIMEOUT_S:g} s; nothing "
                                 f"ran") from None


def _worker_init() -> None:
    # one simulation thread per worker process: the pool already uses every core
    from aerobat.quadrotor.simulate import set_batch_threads

    set_batch_threads(1)


class LocalExecutor:
    """A process pool on this machine (spawned workers, one simulation thread each).

    The workers never outlive this process (:mod:`aerobat.experiments.lifetime`), and a run that
    is abandoned (an interrupt, an error while recording a result, a consumer that stops
    iterating) ends them at once: the jobs they were running are not waited for.
    """

    def __init__(self, workers: int | None = None) -> None:
        self.workers = workers or os.cpu_count() or 1
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) or not 1 <= self.workers <= 1024:
            raise ConfigError(f"workers = {self.workers!r}: allowed integers 1 … 1024")
        self._pool: ProcessPoolExecutor | None = None
        self._owner: threading.Thread | None = None  # the thread that started the pool's workers

    def run(self, jobs: Iterable[Job]) -> Iterator[tuple[Job, JobResult]]:
        jobs = list(jobs)
        if not jobs:
            return
        if self.workers == 1:  # in this process, whose batches may use every core
            for job in jobs:
                yield job, run_job(job)
            return
        if self._pool is not None and self._owner is not threading.current_thread():
            self.close()  # its workers die with the thread that started them (PR_SET_PDEATHSIG)
        if self._pool is None:
            pool = process_pool(self.workers, _worker_init)
            try:
                _workers_started(pool)
            except WorkersUnavailable:
                pool.shutdown(wait=True, cancel_futures=True)
                raise
            self._pool = pool
            self._owner = threading.current_thread()
        futures = {self._pool.submit(run_job, job): job for job in jobs}
        finished = False
        try:
            for future in _completed(futures):
                yield futures[future], _collect(future)
            finished = True
        finally:
            if not finished:
                self._stop()

    def _stop(self) -> None:
        """End the workers now (SIGTERM, then SIGKILL after 5 s) and forget the pool."""
        pool, self._pool = self._pool, None
        if pool is None:
            return
        # the pool has no public list of its processes before Python 3.14 (terminate_workers)
        processes = list((getattr(pool, "_processes", None) or {}).values())
        for process in processes:
            process.terminate()
        for process in processes:
            process.join(timeout=5.0)
            if process.is_alive():
                process.kill()
                process.join(timeout=5.0)
        pool.shutdown(wait=True, cancel_futures=True)

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
            with _signals_deferred() as deliver:  # as for the local pool: signals only between waits
                completed = dask_completed(futures)
                while not completed.is_empty():
                    deliver()
                    batch = completed.next_batch(block=False)
                    if not batch:
                        time.sleep(0.1)
                    for future in batch:
                        yield index[future.key], _collect(future)
                        deliver()
        finally:
            self.client.cancel(futures)

    def close(self) -> None:
        if self._own:
            self.client.close()


def default_workers(cores_per_job: int = 1) -> int:
    """How many jobs run at once on this machine by default: its cores ÷ the cores a job keeps busy.

    A job whose plant keeps two cores busy (a Betaflight firmware over spinning shared memory:
    :meth:`aerobat.plants.PlantChoice.cores`) runs ``cpu_count // 2`` at a time, at least one.
    """
    if isinstance(cores_per_job, bool) or not isinstance(cores_per_job, int) or cores_per_job < 1:
        raise ConfigError(f"cores_per_job = {cores_per_job!r}: allowed integers ≥ 1")
    return max(1, (os.cpu_count() or 1) // cores_per_job)


def make_executor(*, scheduler: str | None = None, workers: int | None = None) -> Executor:
    """The Dask cluster at ``scheduler`` (or ``$DASK_SCHEDULER_ADDRESS``), else a local pool."""
    address = scheduler or os.environ.get("DASK_SCHEDULER_ADDRESS")
    if address:
        return DaskExecutor(address)
    return LocalExecutor(workers)
