"""Studies: many independent designs or learning runs on a local pool or a Dask cluster.

Each study is a list of :class:`~aerobat.experiments.execution.Job` built from a
seed; :func:`~aerobat.experiments.studies.runner.run_study` runs them and commits
every outcome to the store as it arrives.
"""

from aerobat.experiments.studies.envelope import envelope_grid, envelope_jobs
from aerobat.experiments.studies.feedback import (
    SCENARIOS,
    feedback_study_jobs,
    parse_scenarios,
    parse_schemes,
    summarize_feedback,
)
from aerobat.experiments.studies.maps import map_csv, map_grid, map_jobs
from aerobat.experiments.studies.robustness import (
    BETAFLIGHT_PROPERTIES,
    SAMPLED_PROPERTIES,
    RobustnessRanges,
    RobustnessSummary,
    load_ranges,
    robustness_jobs,
    sample_arena,
    sample_betaflight,
    summarize_robustness,
)
from aerobat.experiments.studies.rules import DEFAULT_METHODS, parse_methods, rules_study_jobs, summarize_rules
from aerobat.experiments.studies.runner import FailedJob, StudyOutcome, run_study

__all__ = [
    "BETAFLIGHT_PROPERTIES",
    "DEFAULT_METHODS",
    "SAMPLED_PROPERTIES",
    "SCENARIOS",
    "FailedJob",
    "RobustnessRanges",
    "RobustnessSummary",
    "StudyOutcome",
    "envelope_grid",
    "envelope_jobs",
    "feedback_study_jobs",
    "load_ranges",
    "map_csv",
    "map_grid",
    "map_jobs",
    "parse_methods",
    "parse_scenarios",
    "parse_schemes",
    "robustness_jobs",
    "rules_study_jobs",
    "run_study",
    "sample_arena",
    "sample_betaflight",
    "summarize_feedback",
    "summarize_robustness",
    "summarize_rules",
]
