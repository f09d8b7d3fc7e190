"""The application layer: durable sessions, studies, their execution and their reports.

Everything the command line does with the store is a call here, so a Python user
(a notebook, a script, another tool) does it with one call too:
:func:`start_session` / :func:`resume_session` for learning whose every trial is
stored, :func:`~aerobat.experiments.studies.run_study` for studies.
"""

from aerobat.experiments.execution import DaskExecutor, LocalExecutor, make_executor
from aerobat.experiments.job import Job, JobResult, JobStatus
from aerobat.experiments.sessions import SessionOutcome, StoredSession, resume_session, start_session, warm_start
from aerobat.experiments.studies import StudyOutcome, run_study

__all__ = [
    "DaskExecutor",
    "Job",
    "JobResult",
    "JobStatus",
    "LocalExecutor",
    "SessionOutcome",
    "StoredSession",
    "StudyOutcome",
    "make_executor",
    "resume_session",
    "run_study",
    "start_session",
    "warm_start",
]
