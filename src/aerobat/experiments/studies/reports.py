"""Study reports: each study's table of rows, its CSV and its figures, in one call.

A report is built from what a study did (a :class:`~aerobat.experiments.studies.runner.StudyOutcome`
and its jobs, or a stored study: :func:`study_report`). Every report has

* ``rows``: the table, frozen dataclass rows (one per (scenario, scheme), method, vehicle or cell);
* ``to_csv(path=None)``: the table as CSV text (written to ``path`` if given);
* ``plot(path=None)``: its main figure (saved to ``path`` if given);
* ``write(folder)``: every file ``aerobat study …`` writes, by the names it uses (the folder made if
  missing);
* ``outcome``: what the run did (jobs run now, already done, failed).

Printing is the command line's: a report knows no console. A job that raised counts as a failed
run of its row and its error is listed in the row, never dropped.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from aerobat.errors import ConfigError
from aerobat.experiments.job import Job, JobStatus
from aerobat.experiments.studies.envelope import ENVELOPE_QUANTITIES, envelope_grid
from aerobat.experiments.studies.feedback import summarize_feedback
from aerobat.experiments.studies.robustness import RobustnessSummary, sampled_properties, summarize_robustness
from aerobat.experiments.studies.rules import summarize_rules
from aerobat.experiments.studies.runner import FailedJob, StudyOutcome
from aerobat.quadrotor.feedback import FeedbackScheme
from aerobat.store.records import StudyKind

if TYPE_CHECKING:
    from aerobat.store import Store

__all__ = [
    "EnvelopeCell",
    "EnvelopeReport",
    "FeedbackReport",
    "FeedbackRow",
    "RobustnessReport",
    "RobustnessVehicle",
    "RulesReport",
    "RulesRow",
    "StudyReport",
    "envelope_report",
    "feedback_report",
    "robustness_report",
    "rules_report",
    "study_report",
]


@runtime_checkable
class StudyReport(Protocol):
    """What every study report offers (see the module's docstring)."""

    @property
    def study_id(self) -> int: ...

    @property
    def rows(self) -> tuple[Any, ...]: ...

    @property
    def outcome(self) -> StudyOutcome: ...

    def to_csv(self, path: str | Path | None = None) -> str: ...

    def plot(self, path: str | Path | None = None) -> Any: ...

    def write(self, folder: str | Path) -> list[Path]: ...


def _csv(fieldnames: Sequence[str], rows: Sequence[Mapping[str, Any]], path: str | Path | None) -> str:
    handle = io.StringIO(newline="")
    writer = csv.DictWriter(handle, fieldnames=list(fieldnames))
    writer.writeheader()
    writer.writerows(rows)
    text = handle.getvalue()
    if path is not None:
        from aerobat.plotting.files import write_text

        write_text(path, text)
    return text


def _made(folder: str | Path) -> Path:
    """The folder a report writes into, made if missing."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def _saved(fig: Any, path: str | Path | None) -> Any:
    if path is not None:
        from aerobat.plotting.files import save_figure

        save_figure(fig, path)
    return fig


def _sorted_results(outcome: StudyOutcome, field: str) -> list[dict[str, Any]]:
    """The done jobs' results in key order, those that carry ``field`` (a study's own kind of result)."""
    return [r for _, r in sorted(outcome.results.items()) if field in r]


def _unique(values: Sequence[Any]) -> list[Any]:
    return list(dict.fromkeys(values))


def _job_value(jobs: Sequence[Job], name: str, default: Any = None) -> Any:
    return jobs[0].spec.get(name, default) if jobs else default


# ------------------------------------------------------------------ feedback


@dataclass(frozen=True)
class FeedbackRow:
    """One (scenario, scheme) of the feedback study, over its seeds.

    last10_mean_m, last10_worst_seed_m : the mean position error of the last 10 trials [m], mean
    and worst over seeds. last10_angle_deg : mean |angle errors| over the last 10 trials [deg].
    median_trials_to_tolerance : inf when most runs never got there. failures : failed runs, jobs
    that raised included (their errors in ``job_errors``). wall_ms_per_trial : [ms].
    """

    scenario: str
    scheme: str
    runs: int
    last10_mean_m: float
    last10_worst_seed_m: float
    last10_angle_deg: tuple[float, ...]
    median_trials_to_tolerance: float
    failures: int
    job_errors: tuple[str, ...]
    wall_ms_per_trial: float


@dataclass(frozen=True)
class FeedbackReport:
    """The feedback study's report: a row per (scenario, scheme) and the error curves of every run."""

    study_id: int
    rows: tuple[FeedbackRow, ...]
    curves: Mapping[str, Mapping[str, list[list[float]]]]
    """Position errors per trial [m] of every run, by scenario and scheme."""
    trials: int
    tolerance_m: float
    outcome: StudyOutcome
    """What the run did: jobs run now, already done, failed (a stored study's: none run now)."""

    def to_csv(self, path: str | Path | None = None) -> str:
        """``feedback.csv``: job errors joined by `` | ``, angles by spaces (3 decimals)."""
        return _csv([f.name for f in dataclasses.fields(FeedbackRow)], [
            {**dataclasses.asdict(r), "job_errors": " | ".join(r.job_errors),
             "last10_angle_deg": " ".join(f"{a:.3f}" for a in r.last10_angle_deg)} for r in self.rows], path)

    def plot(self, path: str | Path | None = None) -> Any:
        """``feedback.png``: one panel per scenario, median and quartiles of each scheme's errors."""
        from aerobat.plotting.studies import plot_feedback

        return _saved(plot_feedback(self.curves, self.trials, self.tolerance_m), path)

    def write(self, folder: str | Path) -> list[Path]:
        folder = _made(folder)
        self.to_csv(folder / "feedback.csv")
        self.plot(folder / "feedback.png")
        return [folder / "feedback.csv", folder / "feedback.png"]


def feedback_report(outcome: StudyOutcome, jobs: Sequence[Job], *, schemes: Sequence[str] | None = None,
                    scenarios: Sequence[str] | None = None) -> FeedbackReport:
    """The report of a feedback study from its outcome and its jobs
    (:func:`~aerobat.experiments.studies.feedback.feedback_study_jobs`).

    ``schemes`` and ``scenarios`` give the rows' order (default: the order of the jobs).
    """
    scenarios = list(scenarios) if scenarios is not None else _unique([job.spec["scenario"] for job in jobs])
    names = list(schemes) if schemes is not None else _unique([job.spec["scheme"] for job in jobs])
    chosen = [FeedbackScheme(name) for name in names]
    trials = int(_job_value(jobs, "trials", 0))
    results = _sorted_results(outcome, "scheme")
    by_key = {job.key: job for job in jobs}
    failed: dict[tuple[str, str], list[str]] = {}
    for f in outcome.failed:
        job = by_key.get(f.key)
        pair = (job.spec["scenario"], job.spec["scheme"]) if job else ("?", f.label)
        failed.setdefault(pair, []).append(f.error)
    rows = tuple(FeedbackRow(**{**r, "last10_angle_deg": tuple(r["last10_angle_deg"]),
                                "job_errors": tuple(r["job_errors"])})
                 for r in summarize_feedback(results, chosen, scenarios, trials, failed))
    curves = {sc: {s.value: [r["position_errors_m"] for r in results
                             if r["scenario"] == sc and r["scheme"] == s.value] for s in chosen}
              for sc in scenarios}
    return FeedbackReport(outcome.study_id, rows, curves, trials, float(_job_value(jobs, "tolerance_m", 0.12)),
                          outcome)


# ------------------------------------------------------------------ rules


@dataclass(frozen=True)
class RulesRow:
    """One method of the rules study, over its seeds.

    median_trials_to_tolerance : inf when most runs never got there. reached : runs that got
    there. share_below_after : mean share of the trials after that which stayed below.
    last10_mean_m : mean position error of the last 10 trials [m]. failures : failed runs, jobs
    that raised included (their errors in ``job_errors``). wall_s : mean wall time of a run [s].
    """

    method: str
    runs: int
    median_trials_to_tolerance: float
    reached: int
    share_below_after: float
    last10_mean_m: float
    failures: int
    job_errors: tuple[str, ...]
    wall_s: float


@dataclass(frozen=True)
class RulesReport:
    """The rules study's report: a row per method and the error curves of every run."""

    study_id: int
    rows: tuple[RulesRow, ...]
    curves: Mapping[str, list[list[float]]]
    """Position errors per trial [m] of every run, by method."""
    trials: int
    tolerance_m: float
    outcome: StudyOutcome
    """What the run did: jobs run now, already done, failed (a stored study's: none run now)."""

    def to_csv(self, path: str | Path | None = None) -> str:
        """``rules.csv``: job errors joined by `` | ``."""
        return _csv([f.name for f in dataclasses.fields(RulesRow)],
                    [{**dataclasses.asdict(r), "job_errors": " | ".join(r.job_errors)} for r in self.rows], path)

    def plot(self, path: str | Path | None = None, *, ax: Any = None) -> Any:
        """``rules.png``: median and quartiles of each method's errors per trial (on ``ax`` if given)."""
        from aerobat.plotting.studies import plot_rules

        return _saved(plot_rules(self.curves, self.trials, self.tolerance_m, ax=ax), path)

    def write(self, folder: str | Path) -> list[Path]:
        folder = _made(folder)
        self.to_csv(folder / "rules.csv")
        self.plot(folder / "rules.png")
        return [folder / "rules.csv", folder / "rules.png"]


def rules_report(outcome: StudyOutcome, jobs: Sequence[Job], *, methods: Sequence[str] | None = None) -> RulesReport:
    """The report of a rules study from its outcome and its jobs
    (:func:`~aerobat.experiments.studies.rules.rules_study_jobs`).

    ``methods`` gives the rows' order (default: the order of the jobs).
    """
    methods = list(methods) if methods is not None else _unique([job.spec["method"] for job in jobs])
    results = _sorted_results(outcome, "method")
    by_key = {job.key: job for job in jobs}
    failed: dict[str, list[str]] = {}
    for f in outcome.failed:
        method = by_key[f.key].spec["method"] if f.key in by_key else f.label
        failed.setdefault(method, []).append(f.error)
    rows = tuple(RulesRow(**{**r, "job_errors": tuple(r["job_errors"])})
                 for r in summarize_rules(results, methods, failed))
    curves = {m: [r["position_errors_m"] for r in results if r["method"] == m] for m in methods}
    return RulesReport(outcome.study_id, rows, curves, int(_job_value(jobs, "trials", 0)),
                       float(_job_value(jobs, "tolerance_m", 0.12)), outcome)


# ------------------------------------------------------------------ robustness


@dataclass(frozen=True)
class RobustnessVehicle:
    """One sampled vehicle that learned: whether it met the tolerance, when, and what it was.

    trials_to_tolerance : the trial at which the position error first fell below the tolerance
    (None: never). final_error_m : [m]. properties : the sampled properties, by name.
    """

    key: str
    success: bool
    trials_to_tolerance: int | None
    final_error_m: float
    properties: Mapping[str, float]


@dataclass(frozen=True)
class RobustnessReport:
    """The robustness study's report: a row per vehicle that learned, and their summary."""

    study_id: int
    rows: tuple[RobustnessVehicle, ...]
    summary: RobustnessSummary
    properties: tuple[str, ...]
    """The sampled properties, in the order of the CSV columns and the figure's panels."""
    vehicles: int
    tolerance_m: float
    outcome: StudyOutcome
    """What the run did: jobs run now, already done, failed (a stored study's: none run now)."""

    @property
    def failed(self) -> tuple[FailedJob, ...]:
        """The jobs that raised, with their errors."""
        return self.outcome.failed

    @property
    def ran(self) -> int:
        """Jobs run by this run."""
        return self.outcome.ran

    @property
    def skipped(self) -> int:
        """Jobs already done before this run."""
        return self.outcome.skipped

    def to_json(self) -> dict[str, Any]:
        """``robustness.json``: the summary, the failed jobs and what ran now."""
        final = self.summary.final_errors_m
        return {
            "study": self.study_id, "vehicles": self.vehicles, "learned": self.summary.completed,
            "failed_jobs": [{"key": f.key, "error": f.error} for f in self.failed],
            "success_rate": self.summary.success_rate,
            "median_trials_to_tolerance": self.summary.median_trials_to_tolerance,
            "median_final_error_m": float(np.nanmedian(final)) if final else None,
            "predictors": self.summary.predictors, "ran": self.ran, "skipped": self.skipped,
        }

    def to_csv(self, path: str | Path | None = None) -> str:
        """One line per vehicle: key, success, trials to tolerance (empty: never), final error, properties."""
        return _csv(["key", "success", "trials_to_tolerance", "final_error_m", *self.properties], [
            {"key": r.key, "success": r.success, "trials_to_tolerance": r.trials_to_tolerance,
             "final_error_m": r.final_error_m, **{p: r.properties.get(p, math.nan) for p in self.properties}}
            for r in self.rows], path)

    def plot(self, path: str | Path | None = None, *, ax: Any = None) -> Any:
        """``trials_to_tolerance.png``: when each vehicle first met the tolerance (on ``ax`` if given)."""
        from aerobat.plotting.studies import plot_trials_to_tolerance

        return _saved(plot_trials_to_tolerance(self.summary.trials_to_tolerance, self.tolerance_m, ax=ax), path)

    def plot_properties(self, path: str | Path | None = None) -> Any:
        """``success_vs_property.png``: success per quintile of each property (None if no vehicle has them)."""
        from aerobat.plotting.studies import plot_success_by_property

        with_props = [r for r in self.rows if r.properties]
        if not with_props:
            return None
        return _saved(plot_success_by_property([r.properties for r in with_props], [r.success for r in with_props],
                                               self.properties, [r.trials_to_tolerance for r in with_props]), path)

    def write(self, folder: str | Path) -> list[Path]:
        """``trials_to_tolerance.png``, ``success_vs_property.png`` (if any vehicle learned) and ``robustness.json``."""
        from aerobat.plotting.files import write_text

        folder = _made(folder)
        written = [folder / "trials_to_tolerance.png"]
        self.plot(written[0])
        if self.plot_properties(folder / "success_vs_property.png") is not None:
            written.append(folder / "success_vs_property.png")
        written.append(write_text(folder / "robustness.json", json.dumps(self.to_json(), indent=1)))
        return written


def robustness_report(outcome: StudyOutcome, jobs: Sequence[Job], *, vehicles: int | None = None) -> RobustnessReport:
    """The report of a robustness study from its outcome and its jobs
    (:func:`~aerobat.experiments.studies.robustness.robustness_jobs`).

    ``vehicles``: how many the study samples (default: one per job).
    """
    keyed = sorted(outcome.results.items())
    results = [r for _, r in keyed]
    properties = sampled_properties((_job_value(jobs, "plant") or {}).get("kind"), results)
    rows = tuple(RobustnessVehicle(key, bool(r.get("success")), r.get("trials_to_tolerance"),
                                   float(r.get("final_error_m", math.nan)), dict(r.get("properties") or {}))
                 for key, r in keyed)
    return RobustnessReport(outcome.study_id, rows, summarize_robustness(results, properties), properties,
                            len(jobs) if vehicles is None else vehicles, float(_job_value(jobs, "tolerance_m", 0.12)),
                            outcome)


# ------------------------------------------------------------------ envelope


@dataclass(frozen=True)
class EnvelopeCell:
    """One (flip count, max rate) of the envelope: its job's status and the design's numbers
    (None where the job failed): duration_s [s], apex_m and lowest_m above the start [m]."""

    flips: int
    max_rate_deg_s: float
    job: JobStatus
    converged: bool | None
    status: str | None
    duration_s: float | None
    apex_m: float | None
    lowest_m: float | None
    condition_number: float | None
    continued_from_deg_s: list[float] | None = None
    """The lower and upper rates whose designs' mean p⁰ it converged from when its own guess failed."""


@dataclass(frozen=True)
class EnvelopeReport:
    """The envelope study's report: a cell per (flip count, max rate) and their grids."""

    study_id: int
    rows: tuple[EnvelopeCell, ...]
    flips: tuple[int, ...]
    rates_deg_s: tuple[float, ...]
    feasible: np.ndarray
    """1 where the design converged, 0 where not, NaN where the job failed (flips × rates)."""
    grids: Mapping[str, np.ndarray]
    """Each of :data:`~aerobat.experiments.studies.envelope.ENVELOPE_QUANTITIES` over flips × rates."""
    outcome: StudyOutcome
    """What the run did: jobs run now, already done, failed (a stored study's: none run now)."""

    def to_json(self) -> list[dict[str, Any]]:
        """``envelope.json``: one object per cell."""
        return [dataclasses.asdict(r) for r in self.rows]

    def to_csv(self, path: str | Path | None = None) -> str:
        """One line per cell."""
        return _csv([f.name for f in dataclasses.fields(EnvelopeCell)], self.to_json(), path)

    def plot(self, path: str | Path | None = None, *, quantity: str = "feasible", ax: Any = None) -> Any:
        """``envelope_QUANTITY.png``: ``feasible`` or one of the quantities over the grid (on ``ax`` if given)."""
        from aerobat.plotting.studies import plot_envelope

        if quantity != "feasible" and quantity not in self.grids:
            raise ConfigError(f"envelope quantity {quantity!r}: use feasible, {', '.join(self.grids)}")
        values = self.feasible if quantity == "feasible" else self.grids[quantity]
        continued = [(r.flips, r.max_rate_deg_s) for r in self.rows if r.continued_from_deg_s]
        return _saved(plot_envelope(quantity, self.flips, self.rates_deg_s, values, ax=ax, continued=continued), path)

    def write(self, folder: str | Path) -> list[Path]:
        """``envelope.json`` and ``envelope_feasible.png`` with one figure per quantity."""
        from aerobat.plotting.files import write_text

        folder = _made(folder)
        written = [write_text(folder / "envelope.json", json.dumps(self.to_json(), indent=1))]
        for name in ("feasible", *self.grids):
            written.append(folder / f"envelope_{name}.png")
            self.plot(written[-1], quantity=name)
        return written


def envelope_report(outcome: StudyOutcome, flips: Sequence[int], rates_deg_s: Sequence[float]) -> EnvelopeReport:
    """The report of an envelope study (:func:`~aerobat.experiments.studies.envelope.envelope_jobs`
    over ``flips`` × ``rates_deg_s``) from its outcome."""
    feasible, grids, cells = envelope_grid(outcome.results, flips, rates_deg_s)
    rows = tuple(EnvelopeCell(**c) for c in cells)
    return EnvelopeReport(outcome.study_id, rows, tuple(flips), tuple(rates_deg_s), feasible,
                          {q: grids[q] for q in ENVELOPE_QUANTITIES}, outcome)


# ------------------------------------------------------------------ stored studies


def study_report(store: Store, study: int | str) -> StudyReport:
    """The report of a stored robustness, rules, feedback or envelope study (an id or ``last``).

    Built from the store alone: the study's specification and every recorded job (a job never
    run, as in a study stopped early, is in no row); ``ran`` is 0, every recorded job ``skipped``.
    """
    study_id = store.resolve_study(study)
    record = store.study(study_id)
    stored = store.study_jobs(study_id)
    jobs = [Job(key=j.key, kind=record.kind, spec=j.spec) for j in stored]
    by_key = {job.key: job for job in jobs}
    failed = tuple(FailedJob(j.key, str(by_key[j.key].spec.get("method", record.kind)), j.error or "failed")
                   for j in stored if JobStatus(j.status) is JobStatus.FAILED)
    results = {j.key: j.result for j in stored if JobStatus(j.status) is JobStatus.DONE}
    outcome = StudyOutcome(study_id, len(jobs), 0, len(jobs), failed, results)
    spec = record.spec
    if record.kind is StudyKind.FEEDBACK:
        return feedback_report(outcome, jobs, schemes=spec.get("schemes"), scenarios=spec.get("scenarios"))
    if record.kind is StudyKind.RULES:
        return rules_report(outcome, jobs, methods=spec.get("methods"))
    if record.kind is StudyKind.ROBUSTNESS:
        return robustness_report(outcome, jobs, vehicles=spec.get("vehicles"))
    if record.kind is StudyKind.ENVELOPE:
        return envelope_report(outcome, record.spec["flips"], record.spec["rates_deg_s"])
    raise ConfigError(f"study {study_id} is a {record.kind} study: reports exist for robustness, rules, feedback "
                      f"and envelope studies")
