"""Studies: many independent designs or learning runs on a local pool or a Dask cluster.

Each study is a list of :class:`~aerobat.experiments.execution.Job` built from a
seed; :func:`~aerobat.experiments.studies.runner.run_study` runs them and commits
every outcome to the store as it arrives; :mod:`~aerobat.experiments.studies.reports` makes
each study's rows, CSV and figures (``feedback_report(outcome, jobs)``, or
``study_report(store, study_id)`` for a stored study);
:mod:`~aerobat.experiments.studies.run_and_report` does all of it in one call
(``feedback_study(store, maneuver, design, model, …)`` returns the report).
"""

from aerobat.experiments.studies.envelope import envelope_grid, envelope_jobs
from aerobat.experiments.studies.feedback import (
    feedback_study_jobs,
    parse_scenarios,
    parse_schemes,
    summarize_feedback,
)
from aerobat.experiments.studies.maps import map_csv, map_grid, map_jobs
from aerobat.experiments.studies.reports import (
    EnvelopeCell,
    EnvelopeReport,
    FeedbackReport,
    FeedbackRow,
    RobustnessReport,
    RobustnessVehicle,
    RulesReport,
    RulesRow,
    StudyReport,
    envelope_report,
    feedback_report,
    robustness_report,
    rules_report,
    study_report,
)
from aerobat.experiments.studies.robustness import (
    RobustnessRanges,
    RobustnessSummary,
    load_ranges,
    robustness_jobs,
    summarize_robustness,
)
from aerobat.experiments.studies.rules import DEFAULT_METHODS, parse_methods, rules_study_jobs, summarize_rules
from aerobat.experiments.studies.run_and_report import (
    StudyRunOptions,
    check_envelope_grid,
    envelope_spec,
    envelope_study,
    feedback_spec,
    feedback_study,
    robustness_spec,
    robustness_study,
    rules_spec,
    rules_study,
)
from aerobat.experiments.studies.runner import FailedJob, StudyOutcome, run_study

__all__ = [
    "DEFAULT_METHODS",
    "EnvelopeCell",
    "EnvelopeReport",
    "FailedJob",
    "FeedbackReport",
    "FeedbackRow",
    "RobustnessRanges",
    "RobustnessReport",
    "RobustnessSummary",
    "RobustnessVehicle",
    "RulesReport",
    "RulesRow",
    "StudyOutcome",
    "StudyReport",
    "StudyRunOptions",
    "check_envelope_grid",
    "envelope_grid",
    "envelope_jobs",
    "envelope_report",
    "envelope_spec",
    "envelope_study",
    "feedback_report",
    "feedback_spec",
    "feedback_study",
    "feedback_study_jobs",
    "load_ranges",
    "map_csv",
    "map_grid",
    "map_jobs",
    "parse_methods",
    "parse_scenarios",
    "parse_schemes",
    "robustness_jobs",
    "robustness_report",
    "robustness_spec",
    "robustness_study",
    "rules_report",
    "rules_spec",
    "rules_study",
    "rules_study_jobs",
    "run_study",
    "study_report",
    "summarize_feedback",
    "summarize_robustness",
    "summarize_rules",
]
