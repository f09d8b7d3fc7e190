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

import json
import multiprocessing
import os
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from typing import Any, Protocol

__all__ = ["DaskExecutor", "Executor", "Job", "LocalExecutor", "make_executor", "run_job"]


@dataclass(frozen=True)
class Job:
    """One unit of work: ``kind`` selects the function, ``spec`` (JSON-ready) says everything else.

    Attributes
    ----------
    key : unique name within a study (used to resume: finished keys are skipped).
    kind : ``"learn"``, ``"design"`` or ``"benchmark"``.
    spec : the job's full specification, including its seed.
    """

    key: str
    kind: str
    spec: dict[str, Any] = field(hash=False)

    def to_json(self) -> str:
        return json.dumps({"key": self.key, "kind": self.kind, "spec": self.spec}, sort_keys=True)


JobFunction = Callable[[dict[str, Any]], dict[str, Any]]
_KINDS: dict[str, JobFunction] = {}


def job_kind(name: str) -> Callable[[JobFunction], JobFunction]:
    """Register a job function under ``name`` (module import registers the built-in kinds)."""

    def decorate(fn: JobFunction) -> JobFunction:
        _KINDS[name] = fn
        return fn

    return decorate


def run_job(job: Job) -> dict[str, Any]:
    """Run one job in this process and return its JSON-ready result (never raises for job failures)."""
    from . import studies  # noqa: F401  (registers the built-in job kinds)

    fn = _KINDS.get(job.kind)
    if fn is None:
        return {"status": "error", "message": f"unknown job kind {job.kind!r}"}
    try:
        return fn(job.spec)
    except Exception as exc:  # a failed job is a result, not a crashed study
        return {"status": "error", "message": f"{type(exc).__name__}: {exc}"}


class Executor(Protocol):
    """Runs jobs, yielding (job, result) pairs as they complete."""

    workers: int

    def run(self, jobs: Iterable[Job]) -> Iterator[tuple[Job, dict[str, Any]]]: ...

    def close(self) -> None: ...


def _worker_init() -> None:
    # one numba thread per worker process: the pool already uses every core
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    try:
        import numba

        numba.set_num_threads(1)
    except (ImportError, ValueError):
        pass


class LocalExecutor:
    """A process pool on this machine (spawned workers, one numba thread each)."""

    def __init__(self, workers: int | None = None) -> None:
        self.workers = workers or os.cpu_count() or 1
        if self.workers < 1:
            raise ValueError(f"workers = {self.workers} must be >= 1")
        self._pool: ProcessPoolExecutor | None = None

    def run(self, jobs: Iterable[Job]) -> Iterator[tuple[Job, dict[str, Any]]]:
        jobs = list(jobs)
        if not jobs:
            return
        if self.workers == 1:
            _worker_init()
            for job in jobs:
                yield job, run_job(job)
            return
        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_worker_init)
        futures = {self._pool.submit(run_job, job): job for job in jobs}
        try:
            for future in as_completed(futures):
                yield futures[future], future.result()
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
        try:
            from distributed import Client
        except ImportError as exc:  # pragma: no cover - depends on the install
            raise ImportError("Dask is not installed: pip install 'aerobat[dask]'") from exc
        self._own = client is None
        self.client = client if client is not None else Client(address, timeout="10s")
        self.workers = max(1, sum(w.get("nthreads", 1) for w in self.client.scheduler_info()["workers"].values()))

    def run(self, jobs: Iterable[Job]) -> Iterator[tuple[Job, dict[str, Any]]]:
        from distributed import as_completed as dask_completed

        jobs = list(jobs)
        if not jobs:
            return
        futures = self.client.map(run_job, jobs, key=[f"aerobat-{j.key}-{abs(hash(j.to_json()))}" for j in jobs],
                                  pure=False)
        index = {f.key: job for f, job in zip(futures, jobs, strict=True)}
        try:
            for future in dask_completed(futures):
                yield index[future.key], future.result()
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
