"""The feedback study: open loop and each onboard feedback scheme side by side, across scenarios.

Every (scenario, scheme) pair learns the same maneuver on the same plant seeds with the same
update rule, so the only difference is what the onboard loop mixes into the program. Scenarios
are the plant's (:attr:`aerobat.plants.PlantSpec.scenarios`): on the arena they change it so that the
feedback's assumptions fail (a gyro much worse than the estimator believes, a radio that loses or delays
the relayed estimates, :data:`aerobat.plants.arena.sampling.SCENARIOS`); every plant runs ``default``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from aerobat.core.design import Design
from aerobat.core.maneuver import Maneuver
from aerobat.errors import ConfigError
from aerobat.experiments.designing import NominalDesign, job_design
from aerobat.experiments.job import Job
from aerobat.experiments.job_specs import RuleRunJob
from aerobat.plants import PlantChoice
from aerobat.plants.spec import PLANTS
from aerobat.quadrotor.feedback import Feedback, FeedbackScheme
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["feedback_study_jobs", "parse_scenarios", "parse_schemes", "summarize_feedback"]


def parse_schemes(text: str, *, source: str = "--schemes") -> list[FeedbackScheme]:
    names = [s.strip() for s in str(text).split(",") if s.strip()]
    if not names:
        raise ConfigError(f"{source}: name at least one scheme ({', '.join(s.value for s in FeedbackScheme)})")
    schemes = [FeedbackScheme.parse(n, where=source) for n in names]
    if len(set(schemes)) != len(schemes):
        raise ConfigError(f"{source} {text!r}: a scheme is named twice")
    return schemes


def parse_scenarios(text: str, *, plant: str, source: str = "--scenarios") -> list[str]:
    """The scenario names in ``text`` (comma-separated), each one the plant ``plant`` has."""
    spec = PLANTS.get(plant, source="--plant")
    known = ", ".join(s.name for s in spec.scenarios)
    names = [s.strip() for s in str(text).split(",") if s.strip()]
    if not names:
        raise ConfigError(f"{source}: name at least one scenario ({known})")
    for name in names:
        spec.scenario(name, source=source)
    if len(set(names)) != len(names):
        raise ConfigError(f"{source} {text!r}: a scenario is named twice")
    return names


def feedback_study_jobs(maneuver: Maneuver, design: Design | NominalDesign, model: VehicleConfig, *,
                        schemes: list[FeedbackScheme], scenarios: list[str], seeds: int, trials: int,
                        plant: PlantChoice, rule: str = "paper", tolerance_m: float = 0.12) -> list[Job]:
    """Every (scenario, scheme) on the same ``seeds`` plant seeds (``plant.seed``, ``plant.seed + 1``, …)."""
    design_table, model_table = job_design(design, model)
    jobs = []
    spec = plant.spec
    for scenario in scenarios:
        settings = spec.scenario(scenario).change(plant.settings)
        for scheme in schemes:
            choice = PlantChoice(plant.kind, settings, plant.seed, Feedback(scheme, plant.feedback.gains))
            for k in range(seeds):
                job_spec = RuleRunJob(maneuver=maneuver.spec(), design=design_table, model=model_table,
                                      plant={**choice.to_table(), "seed": plant.seed + k}, method=rule,
                                      trials=trials, tolerance_m=tolerance_m, scenario=scenario, scheme=scheme.value)
                jobs.append(Job(key=f"{scenario}-{scheme.value}-seed-{plant.seed + k:04d}", kind=RuleRunJob.kind,
                                spec=job_spec.to_table()))
    return jobs


def summarize_feedback(results: list[dict[str, Any]], schemes: list[FeedbackScheme], scenarios: list[str],
                       trials: int, failed_jobs: dict[tuple[str, str], list[str]] | None = None,
                       ) -> list[dict[str, Any]]:
    """Per (scenario, scheme): last-10 mean over seeds and its worst seed, mean |angle errors| over the
    last 10 [deg], median trials to tolerance, failed runs (jobs that raised count and are listed),
    wall time per trial [ms]. Every pair gets a row."""
    failed_jobs = failed_jobs or {}
    rows = []
    for scenario in scenarios:
        for scheme in schemes:
            runs = [r for r in results if r.get("scenario") == scenario and r.get("scheme") == scheme.value]
            errors = failed_jobs.get((scenario, scheme.value), [])
            last = [r["last10_mean_m"] for r in runs]
            ttt = [r["trials_to_tolerance"] if r["trials_to_tolerance"] is not None else math.inf for r in runs]
            ttt += [math.inf] * len(errors)
            angles = [r["last10_angle_deg"] for r in runs if r.get("last10_angle_deg")]
            rows.append({
                "scenario": scenario,
                "scheme": scheme.value,
                "runs": len(runs) + len(errors),
                "last10_mean_m": float(np.mean(last)) if last else math.nan,
                "last10_worst_seed_m": float(np.max(last)) if last else math.nan,
                "last10_angle_deg": (np.mean(np.array(angles), axis=0).round(3).tolist() if angles else []),
                "median_trials_to_tolerance": float(np.median(ttt)) if ttt else math.nan,
                "failures": sum(1 for r in runs if r["failed"]) + len(errors),
                "job_errors": errors,
                "wall_ms_per_trial": (1e3 * float(np.mean([r["wall_s"] for r in runs])) / trials) if runs else math.nan,
            })
    return rows
