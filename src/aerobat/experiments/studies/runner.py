"""Running a study: its jobs on an executor, every result (or failure) committed as it arrives.

A study is a row in the store and a list of jobs. :func:`run_study` submits the
jobs not yet done (failed ones run again), records each outcome as soon as it
arrives — a learning run also as a session linked to the study — and returns a
:class:`StudyOutcome` that lists every failure with its error. Nothing is
filtered: a report built from it shows what ran, what was skipped and what failed.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from aerobat.config import short_repr
from aerobat.core.design import Design
from aerobat.core.learning import Iteration, SessionStatus
from aerobat.core.registry import from_spec
from aerobat.core.rules import RuleChoice
from aerobat.errors import ConfigError
from aerobat.experiments.execution import Executor, default_workers, make_executor
from aerobat.experiments.job import Job, JobResult, JobStatus
from aerobat.experiments.setup import plant_record_config
from aerobat.plants import PlantChoice
from aerobat.store import Store
from aerobat.store.records import StudyKind

__all__ = ["FailedJob", "StudyOutcome", "job_cores", "run_study"]


@dataclass(frozen=True)
class FailedJob:
    """A job that raised: its key, its method or label, and the error."""

    key: str
    label: str
    error: str


@dataclass(frozen=True)
class StudyOutcome:
    """What :func:`run_study` did.

    Attributes
    ----------
    study_id : the study's id in the store.
    total : jobs in the study.
    ran, skipped : jobs run now, and jobs already done before (resumed studies).
    failed : every job that is failed now (run now or earlier), with its error.
    results : results of every done job, by key.
    """

    study_id: int
    total: int
    ran: int
    skipped: int
    failed: tuple[FailedJob, ...]
    results: dict[str, dict[str, Any]]

    @property
    def ok(self) -> bool:
        return not self.failed


Progress = Callable[[int, int, Job, JobResult], None]
"""``progress(done, total, job, result)``, called as each job's outcome is committed."""


def _label(job: Job) -> str:
    return str(job.spec.get("method", job.kind))


def _ended(status: str) -> SessionStatus:
    """How a study's learning run ended, from its result's ``status`` (``failed`` for anything else)."""
    try:
        state = SessionStatus(status)
    except ValueError:
        return SessionStatus.FAILED
    return SessionStatus.FAILED if state is SessionStatus.RUNNING else state


def _record(store: Store, study_id: int, job: Job, outcome: JobResult) -> None:
    """Commit one job's outcome; a finished learning run also becomes a session, in the same transaction."""
    iterations = outcome.result.get("iterations") if outcome.done else None
    spec = job.spec
    if not iterations or not all(k in spec for k in ("maneuver", "design", "model", "plant")):
        store.record_study_job(study_id, job.key, spec, outcome.result, status=outcome.status,
                               error=outcome.error)
        return
    source = f"study {study_id} job {job.key}"
    maneuver = from_spec(spec["maneuver"], source=f"{source} maneuver")
    design = Design.from_json_dict(maneuver, spec["design"])
    plant = PlantChoice.from_table(spec["plant"], source=f"{source} plant")
    rule = RuleChoice.parse(str(spec.get("rule") or spec.get("method", "paper")), source=f"{source} rule")
    status = str(outcome.result.get("status", "completed"))
    store.record_study_run(
        study_id, job.key, spec, outcome.result,
        session={"vehicle": spec["model"], "plant_kind": plant.kind, "plant_config": plant_record_config(plant),
                 "maneuver": maneuver, "design": design, "seed": plant.seed, "rule": rule.to_table(),
                 "target_iterations": max(1, int(spec.get("iterations", spec.get("trials", 1)))),
                 "start_params": design.p_nominal, "command": ("study", str(study_id), job.key),
                 "study_id": study_id},
        iterations=[Iteration.from_json_dict(it) for it in iterations],
        state=_ended(status),
        message=str(outcome.result.get("message", status)))


def run_study(
    store: Store,
    kind: StudyKind | str,
    spec: Mapping[str, Any],
    jobs: Sequence[Job],
    *,
    resume: int | str | None = None,
    executor: Executor | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Progress | None = None,
    on_start: Callable[[int, int, int], None] | None = None,
    command: Sequence[str] = (),
) -> StudyOutcome:
    """Run the study's jobs that are not done yet; commit each outcome as it arrives.

    Parameters
    ----------
    store : where the study, its jobs and their sessions go.
    kind, spec : what the study is (a :class:`~aerobat.store.records.StudyKind` or its name; ``spec`` is
        compared on resume).
    jobs : all of the study's jobs.
    resume : continue this study (id or ``last``) instead of creating one.
    executor : run the jobs here (default: :func:`make_executor` with ``workers``/``scheduler``).
    workers : jobs at once in the local pool (default: the machine's cores ÷ :func:`job_cores`).
    progress : called after each committed outcome.
    on_start : ``on_start(study_id, to_run, already_done)`` before the first job is submitted.
    command : the command line, kept with the study.
    """
    jobs = _check_study(kind, spec, jobs, resume=resume, progress=progress, on_start=on_start, command=command)
    kind = StudyKind(kind)
    keys = [job.key for job in jobs]
    if len(set(keys)) != len(keys):
        raise ConfigError(f"study {kind}: job keys repeat")
    own = executor is None
    if own and workers is None:
        workers = default_workers(job_cores(jobs))
    # the executor first: an unusable scheduler address is refused before a study is created or announced
    runner = make_executor(scheduler=scheduler, workers=workers) if executor is None else executor
    try:
        if resume is not None:
            study_id = store.resolve_study(resume)
            record = store.study(study_id)
            if record.kind != kind:
                raise ConfigError(f"--resume {study_id}: study {study_id} is a {record.kind} study, not {kind}")
            if _canonical(record.spec) != _canonical(spec):
                raise ConfigError(f"--resume {study_id}: the command line describes another {kind} study than "
                                  f"study {study_id}; give the same options (see `aerobat studies show {study_id}`)")
        else:
            study_id = store.create_study(kind, spec, command=command)
        done = store.finished_study_jobs(study_id)
        todo = [job for job in jobs if job.key not in done]
        if on_start is not None:
            on_start(study_id, len(todo), len(jobs) - len(todo))
        count = len(jobs) - len(todo)
        for job, outcome in runner.run(todo):
            _record(store, study_id, job, outcome)
            count += 1
            if progress is not None:
                progress(count, len(jobs), job, outcome)
    finally:
        if own:
            runner.close()
    by_key = {job.key: job for job in jobs}
    failed = tuple(FailedJob(j.key, _label(by_key[j.key]) if j.key in by_key else j.key, j.error or "failed")
                   for j in store.study_jobs(study_id) if j.status is JobStatus.FAILED)
    return StudyOutcome(study_id, len(jobs), len(todo), len(jobs) - len(todo), failed,
                        store.study_results(study_id))


def job_cores(jobs: Iterable[Job]) -> int:
    """The most cores one of ``jobs`` keeps busy: its plant's (:meth:`~aerobat.plants.PlantChoice.cores`), else 1."""
    seen: dict[str, int] = {}
    for job in jobs:
        table = job.spec.get("plant")
        if not isinstance(table, Mapping):
            continue
        key = json.dumps(table, sort_keys=True, default=str)
        if key not in seen:
            seen[key] = PlantChoice.from_table(table, source=f"job {job.key} plant").cores()
    return max(seen.values(), default=1)


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} {short_repr(value)} is not a JSON value")


_KIND = re.compile(r"[A-Za-z][A-Za-z0-9_.-]{0,63}")


def _check_study(kind: Any, spec: Any, jobs: Any, *, resume: Any, progress: Any, on_start: Any,
                 command: Any) -> list[Job]:
    """The jobs as a list, once every argument of :func:`run_study` is what it must be (ConfigError if not)."""
    if not isinstance(kind, str) or not _KIND.fullmatch(kind):
        raise ConfigError(f"study kind = {short_repr(kind)}: expected a name of 1 … 64 letters, digits, '_', '-' "
                          f"or '.' that starts with a letter (e.g. 'robustness')")
    if kind not in set(StudyKind):
        raise ConfigError(f"study kind = {short_repr(kind)}: expected one of {', '.join(StudyKind)}")
    if not isinstance(spec, Mapping):
        raise ConfigError(f"study {kind} spec: expected a mapping of the study's options (a dict), got "
                          f"{type(spec).__name__} {short_repr(spec)}")
    try:  # stored as JSON and compared on resume: an object would be stored as its repr
        json.dumps(spec, default=_plain)
    except (TypeError, ValueError, RecursionError) as exc:
        raise ConfigError(f"study {kind} spec: not JSON-ready (numbers, strings, lists and dicts): {exc}") from None
    if isinstance(jobs, str | bytes | Mapping) or not isinstance(jobs, Iterable):
        raise ConfigError(f"study {kind} jobs: expected a sequence of Job, got {type(jobs).__name__} "
                          f"{short_repr(jobs)}")
    jobs = list(jobs)
    for job in jobs:
        if not isinstance(job, Job):
            raise ConfigError(f"study {kind} jobs: expected Job items, got {type(job).__name__} {short_repr(job)}")
    if resume is not None and (isinstance(resume, bool) or not isinstance(resume, int | str)):
        raise ConfigError(f"resume = {short_repr(resume)}: expected a study id or 'last'")
    for name, value in (("progress", progress), ("on_start", on_start)):
        if value is not None and not callable(value):
            raise ConfigError(f"{name} = {short_repr(value)}: expected a function or None")
    if isinstance(command, str | bytes) or not isinstance(command, Sequence) or \
            not all(isinstance(word, str) for word in command):
        raise ConfigError(f"command = {short_repr(command)}: expected a sequence of strings (the command line)")
    return jobs


def _canonical(value: Any) -> str:
    return json.dumps(json.loads(json.dumps(value, default=str)), sort_keys=True)
