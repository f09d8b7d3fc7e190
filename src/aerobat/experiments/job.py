"""What a job is: a pure function's name and its JSON specification, and its typed result.

This module is light on purpose: a worker process imports it before it knows which
job it will run, and must not load a compiler before the worker is configured.
The built-in kinds live in :mod:`aerobat.experiments.jobs` and are imported on first use.
"""

from __future__ import annotations

import importlib
import json
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from aerobat.store.records import JobStatus

__all__ = ["Job", "JobResult", "JobStatus", "job_kind", "run_job"]


@dataclass(frozen=True)
class Job:
    """One unit of work: ``kind`` selects the function, ``spec`` (JSON-ready) says everything else.

    Attributes
    ----------
    key : unique name within a study (used to resume: finished keys are skipped).
    kind : a registered job kind (``"learn"``, ``"design"``, ``"benchmark"``, ``"rule_run"``).
    spec : the job's full specification, including its seed.
    """

    key: str
    kind: str
    spec: dict[str, Any] = field(hash=False)

    def to_json(self) -> str:
        return json.dumps({"key": self.key, "kind": self.kind, "spec": self.spec}, sort_keys=True)


@dataclass(frozen=True)
class JobResult:
    """A job's outcome: its status, its JSON-ready result (empty if failed) and the error if it failed."""

    status: JobStatus
    result: dict[str, Any]
    error: str | None = None

    @property
    def done(self) -> bool:
        return self.status is JobStatus.DONE


JobFunction = Callable[[dict[str, Any]], dict[str, Any]]
_KINDS: dict[str, JobFunction] = {}


def job_kind(name: str) -> Callable[[JobFunction], JobFunction]:
    """Register a job function under ``name`` (:mod:`aerobat.experiments.jobs` registers the built-in kinds)."""

    def decorate(fn: JobFunction) -> JobFunction:
        _KINDS[name] = fn
        return fn

    return decorate


_BUILTIN = {kind: f"aerobat.experiments.jobs:{kind}_job" for kind in ("learn", "design", "benchmark", "rule_run")}
"""The built-in kinds, imported on first use (a worker process imports nothing heavy before it must)."""


def _function(kind: str) -> JobFunction | None:
    if kind not in _KINDS and kind in _BUILTIN:
        module, _, name = _BUILTIN[kind].partition(":")
        _KINDS[kind] = getattr(importlib.import_module(module), name)
    return _KINDS.get(kind)


def run_job(job: Job) -> JobResult:
    """Run one job in this process; a job that raises is a :attr:`JobStatus.FAILED` result, never an exception."""
    try:
        fn = _function(job.kind)
    except Exception as exc:  # a kind whose module cannot be imported
        return JobResult(JobStatus.FAILED, {}, f"job kind {job.kind!r}: {type(exc).__name__}: {exc}")
    if fn is None:
        return JobResult(JobStatus.FAILED, {}, f"unknown job kind {job.kind!r}")
    try:
        return JobResult(JobStatus.DONE, fn(job.spec))
    except Exception as exc:  # a failed job is a result, not a crashed study
        where = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
        at = f" (at {where.filename.rsplit('/', 1)[-1]}:{where.lineno})" if where else ""
        return JobResult(JobStatus.FAILED, {}, f"{type(exc).__name__}: {exc}{at}")
