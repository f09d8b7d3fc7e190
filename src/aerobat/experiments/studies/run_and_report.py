"""A whole study in one call: its specification, its jobs, the run, and its report.

What ``aerobat study feedback|rules|robustness|envelope`` does, a library user does with one
call that returns the study's report (:mod:`~aerobat.experiments.studies.reports`)::

    report = feedback_study(store, maneuver, design, model, schemes=[FeedbackScheme.NONE],
                            scenarios=["default"], seeds=2, trials=8, plant=PlantChoice("arena"))
    report.to_csv("feedback.csv")

Each ``*_spec`` function gives the specification the study is stored (and resumed) under, the
same the command line stores. The keyword options of the run (``resume``, ``workers``,
``scheduler``, ``executor``, ``progress``, ``on_start``, ``command``) are those of
:func:`~aerobat.experiments.studies.runner.run_study`. Failed jobs are in the report's rows
(and ``report`` of the outcome), never dropped.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, TypedDict, Unpack

from aerobat.core.design import Design
from aerobat.core.maneuver import Maneuver
from aerobat.errors import ConfigError
from aerobat.experiments.designing import NominalDesign
from aerobat.experiments.execution import Executor
from aerobat.experiments.studies.envelope import envelope_jobs
from aerobat.experiments.studies.feedback import feedback_study_jobs
from aerobat.experiments.studies.reports import (
    EnvelopeReport,
    FeedbackReport,
    RobustnessReport,
    RulesReport,
    envelope_report,
    feedback_report,
    robustness_report,
    rules_report,
)
from aerobat.experiments.studies.robustness import RobustnessRanges, robustness_jobs
from aerobat.experiments.studies.rules import check_method_names, rules_study_jobs
from aerobat.experiments.studies.runner import Progress, run_study
from aerobat.quadrotor.feedback import FeedbackScheme
from aerobat.quadrotor.vehicle import VehicleConfig
from aerobat.store.records import StudyKind

if TYPE_CHECKING:
    from aerobat.core.rules import RuleChoice
    from aerobat.plants import PlantChoice
    from aerobat.quadrotor.maneuvers.flip import Axis
    from aerobat.store import Store

__all__ = [
    "StudyRunOptions",
    "check_envelope_grid",
    "envelope_spec",
    "envelope_study",
    "feedback_spec",
    "feedback_study",
    "robustness_spec",
    "robustness_study",
    "rules_spec",
    "rules_study",
]

class StudyRunOptions(TypedDict, total=False):
    """How a study runs (:func:`~aerobat.experiments.studies.runner.run_study`'s keywords)."""

    resume: int | str | None
    executor: Executor | None
    workers: int | None
    scheduler: str | None
    progress: Progress | None
    on_start: Callable[[int, int, int], None] | None
    command: Sequence[str]


# ------------------------------------------------------------------ feedback


def feedback_spec(maneuver: Maneuver, *, schemes: Sequence[FeedbackScheme], scenarios: Sequence[str], seeds: int,
                  trials: int, plant: PlantChoice, rule: str = "paper", tolerance_m: float = 0.12) -> dict[str, Any]:
    """The specification a feedback study is stored and resumed under."""
    return {"maneuver": maneuver.spec(), "schemes": [s.value for s in schemes], "scenarios": list(scenarios),
            "seeds": seeds, "trials": trials, "plant": plant.to_table(), "rule": rule, "tolerance_m": tolerance_m}


def feedback_study(store: Store, maneuver: Maneuver, design: Design | NominalDesign,
                   model: VehicleConfig, *,
                   schemes: Sequence[FeedbackScheme], scenarios: Sequence[str], seeds: int, trials: int,
                   plant: PlantChoice, rule: str = "paper", tolerance_m: float = 0.12,
                   **options: Unpack[StudyRunOptions]) -> FeedbackReport:
    """Every (scenario, onboard scheme) learning ``maneuver`` on ``seeds`` plant seeds; its report.

    ``design`` is the maneuver's nominal design on ``model``; ``plant`` the plant every run flies
    (the scenarios are the plant's, :attr:`aerobat.plants.PlantSpec.scenarios`).
    """
    schemes = [FeedbackScheme(s) for s in schemes]
    jobs = feedback_study_jobs(maneuver, design, model, schemes=schemes, scenarios=list(scenarios), seeds=seeds,
                               trials=trials, plant=plant, rule=rule, tolerance_m=tolerance_m)
    spec = feedback_spec(maneuver, schemes=schemes, scenarios=scenarios, seeds=seeds, trials=trials, plant=plant,
                         rule=rule, tolerance_m=tolerance_m)
    outcome = run_study(store, StudyKind.FEEDBACK, spec, jobs, **options)
    return feedback_report(outcome, jobs, schemes=[s.value for s in schemes], scenarios=list(scenarios))


# ------------------------------------------------------------------ rules


def rules_spec(maneuver: Maneuver, *, methods: Sequence[str], seeds: int, trials: int, plant: PlantChoice,
               tolerance_m: float = 0.12) -> dict[str, Any]:
    """The specification a rules study is stored and resumed under."""
    return {"maneuver": maneuver.spec(), "methods": list(methods), "seeds": seeds, "trials": trials,
            "plant": plant.to_table(), "tolerance_m": tolerance_m}


def rules_study(store: Store, maneuver: Maneuver, design: Design | NominalDesign,
                model: VehicleConfig, *, methods: Sequence[str],
                seeds: int, trials: int, plant: PlantChoice, tolerance_m: float = 0.12,
                **options: Unpack[StudyRunOptions]) -> RulesReport:
    """Every update rule or baseline in ``methods`` learning ``maneuver`` on ``seeds`` plant seeds; its report.

    Every method's name and package are checked before a job runs
    (:func:`~aerobat.experiments.baselines.check_methods`).
    """
    from aerobat.experiments.baselines import check_methods

    methods = check_method_names(methods)
    check_methods(methods)
    jobs = rules_study_jobs(maneuver, design, model, methods=methods, seeds=seeds, trials=trials, plant=plant,
                            tolerance_m=tolerance_m)
    spec = rules_spec(maneuver, methods=methods, seeds=seeds, trials=trials, plant=plant, tolerance_m=tolerance_m)
    outcome = run_study(store, StudyKind.RULES, spec, jobs, **options)
    return rules_report(outcome, jobs, methods=methods)


# ------------------------------------------------------------------ robustness


def robustness_spec(maneuver: Maneuver, *, vehicles: int, iterations: int, seed: int, ranges: RobustnessRanges,
                    rule: RuleChoice, tolerance_m: float, plant: str, feedback: str = "none") -> dict[str, Any]:
    """The specification a robustness study is stored and resumed under (``feedback``: the scheme's name)."""
    spec: dict[str, Any] = {
        "maneuver": maneuver.spec(), "vehicles": vehicles, "iterations": iterations, "seed": seed,
        "rule": rule.label, "tolerance_m": tolerance_m, "plant": plant,
        "ranges": {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(ranges).items()}}
    if feedback != "none":
        spec["feedback"] = feedback
    return spec


def robustness_study(store: Store, maneuver: Maneuver, design: Design | NominalDesign,
                     model: VehicleConfig, *, vehicles: int,
                     iterations: int, seed: int, ranges: RobustnessRanges | None = None,
                     rule: RuleChoice | None = None, tolerance_m: float = 0.12, plant: str = "arena",
                     base: Any = None, feedback: Any = None,
                     **options: Unpack[StudyRunOptions]) -> RobustnessReport:
    """``vehicles`` vehicles sampled from ``ranges`` around ``model`` (or a Betaflight ``base``), each
    learning ``maneuver`` for ``iterations`` trials; its report
    (:func:`~aerobat.experiments.studies.robustness.robustness_jobs` says what is sampled)."""
    from aerobat.core.rules import RuleChoice

    ranges = ranges if ranges is not None else RobustnessRanges()
    rule = rule if rule is not None else RuleChoice.parse("paper", source="rule")
    jobs = robustness_jobs(maneuver, design, model, vehicles=vehicles, iterations=iterations, seed=seed,
                           ranges=ranges, rule=rule, tolerance_m=tolerance_m, plant=plant, base=base,
                           feedback=feedback)
    scheme = jobs[0].spec["plant"].get("feedback", {}).get("scheme", "none") if jobs else "none"
    spec = robustness_spec(maneuver, vehicles=vehicles, iterations=iterations, seed=seed, ranges=ranges, rule=rule,
                           tolerance_m=tolerance_m, plant=plant, feedback=scheme)
    outcome = run_study(store, StudyKind.ROBUSTNESS, spec, jobs, **options)
    return robustness_report(outcome, jobs, vehicles=vehicles)


# ------------------------------------------------------------------ envelope


def envelope_spec(base: dict[str, Any], *, flips: Sequence[int], rates_deg_s: Sequence[float]) -> dict[str, Any]:
    """The specification an envelope study is stored and resumed under (``base``: a flip's specification)."""
    return {"base": base, "flips": list(flips), "rates_deg_s": list(rates_deg_s)}


def check_envelope_grid(flips: Sequence[int], rates_deg_s: Sequence[float]) -> tuple[list[int], list[float]]:
    """The flip counts and maximum rates [deg/s] of an envelope, each checked against the flip's own
    bounds (:data:`~aerobat.quadrotor.maneuvers.flip.FLIPS`, ``MAX_RATE_DEG_S``); :class:`ConfigError` otherwise.

    :func:`envelope_study` checks them; the command line calls it before it opens the store.
    """
    from aerobat.quadrotor.maneuvers.flip import FLIPS, MAX_RATE_DEG_S

    if not flips:
        raise ConfigError("flips = []: expected at least one flip count")
    if not rates_deg_s:
        raise ConfigError("rates_deg_s = []: expected at least one rate")
    return ([FLIPS.check(f"flips[{i}]", n) for i, n in enumerate(flips)],
            [MAX_RATE_DEG_S.check(f"rates_deg_s[{i}]", r) for i, r in enumerate(rates_deg_s)])


def envelope_study(store: Store, model: VehicleConfig, *, flips: Sequence[int], rates_deg_s: Sequence[float],
                   dims: int = 3, axis: Axis = "roll", **options: Unpack[StudyRunOptions]) -> EnvelopeReport:
    """A flip designed on ``model`` for every (flip count, maximum rate [deg/s]); its report."""
    from aerobat.quadrotor.maneuvers import MultiFlip

    flips, rates_deg_s = check_envelope_grid(flips, rates_deg_s)
    base = MultiFlip(vehicle=model.vehicle, dims=dims, axis=axis).spec()
    jobs = envelope_jobs(base, model, flips, rates_deg_s)
    outcome = run_study(store, StudyKind.ENVELOPE, envelope_spec(base, flips=flips, rates_deg_s=rates_deg_s), jobs,
                        **options)
    return envelope_report(outcome, flips, rates_deg_s)
