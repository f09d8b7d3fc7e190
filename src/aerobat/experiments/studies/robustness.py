"""Robustness: learn one maneuver on many sampled vehicles (Monte Carlo over a plant's true vehicle).

A plant is sampled as its spec says (:attr:`aerobat.plants.PlantSpec.robustness`, a
:class:`~aerobat.plants.sampling.Sampling`): the arena's true vehicle around the Table 1 model
(:mod:`aerobat.plants.arena.sampling`), the Betaflight plant's 5-inch racer around its settings
(:mod:`aerobat.plants.betaflight.sampling`), or any plant whose spec declares how. This module imports
no plant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from aerobat.config import dataclass_from_table, read_toml
from aerobat.core.design import Design
from aerobat.core.maneuver import Maneuver
from aerobat.core.rules import RuleChoice
from aerobat.errors import ConfigError
from aerobat.experiments.designing import NominalDesign, job_design
from aerobat.experiments.job import Job
from aerobat.experiments.job_specs import LearnJob
from aerobat.plants import sampled_plants
from aerobat.plants.sampling import RobustnessRanges
from aerobat.plants.spec import PLANTS
from aerobat.quadrotor.feedback import Feedback, as_feedback
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = [
    "RobustnessRanges",
    "RobustnessSummary",
    "load_ranges",
    "robustness_jobs",
    "sampled_properties",
    "summarize_robustness",
]


def load_ranges(path: str | Path) -> RobustnessRanges:
    """Read robustness ranges from a TOML file (a ``[ranges]`` table; omitted fields keep defaults)."""
    data = read_toml(path)
    unknown = sorted(set(data) - {"ranges"})
    if unknown:
        raise ConfigError(f"{path}: unknown table(s) {', '.join(unknown)}; allowed: [ranges]")
    return dataclass_from_table(RobustnessRanges, data.get("ranges", {}), source=f"{path}: [ranges]")


def robustness_jobs(maneuver: Maneuver, design: Design | NominalDesign,
                    model: VehicleConfig, *, vehicles: int, iterations: int,
                    seed: int, ranges: RobustnessRanges | None = None, rule: RuleChoice | None = None,
                    tolerance_m: float = 0.12, plant: str = "arena", base: Any = None,
                    feedback: Any = None) -> list[Job]:
    """One learning job per sampled vehicle; vehicle k's sample and plant seed derive from ``seed`` and k.

    ``plant`` is a plant whose spec declares its sampling (:func:`sampled_plants`); ``base`` the settings
    sampled around (default: the plant's defaults); ``feedback`` the onboard feedback every vehicle runs (a
    :class:`~aerobat.quadrotor.feedback.Feedback`, a scheme name, or None for the plant's default).
    """
    spec = PLANTS.get(plant, source="robustness --plant")
    sampling = spec.robustness
    if sampling is None:
        raise ConfigError(f"robustness --plant {plant!r}: the {plant} plant declares no sampling "
                          f"(PlantSpec.robustness); plants that do: {', '.join(sampled_plants())}")
    ranges = ranges or RobustnessRanges()
    rule = rule or RuleChoice()
    fb = Feedback(spec.default_feedback) if feedback is None else as_feedback(feedback)
    spec.check_feedback(fb)
    design_table, model_table = job_design(design, model)
    jobs = []
    for k in range(vehicles):
        sample_seed = seed * 1_000_003 + k
        settings, props = sampling.sample(ranges, sample_seed, base)
        table: dict[str, Any] = {"kind": plant, "settings": settings, "seed": sample_seed}
        if spec.module is not None:  # a plant registered by importing its module: the workers import it too
            table["module"] = spec.module
        if fb.enabled:
            table["feedback"] = fb.to_table()
        job_spec = LearnJob(maneuver=maneuver.spec(), design=design_table, model=model_table, plant=table,
                            properties=props, iterations=iterations, rule=rule.label, tolerance_m=tolerance_m)
        jobs.append(Job(key=f"vehicle-{k:05d}", kind=LearnJob.kind, spec=job_spec.to_table()))
    return jobs


@dataclass(frozen=True)
class RobustnessSummary:
    vehicles: int
    completed: int
    success_rate: float
    median_trials_to_tolerance: float
    trials_to_tolerance: list[int | None]
    final_errors_m: list[float]
    predictors: list[tuple[str, float]] = field(default_factory=list)


def sampled_properties(kind: str | None, results: list[dict[str, Any]]) -> tuple[str, ...]:
    """The properties a robustness study of the plant ``kind`` reports, in its spec's order; for a plant
    not registered here (or ``kind`` None: jobs stored without their plant), those the results carry."""
    if kind is not None and kind in PLANTS:
        sampling = PLANTS.get(kind).robustness
        if sampling is not None:
            return sampling.properties
    names: dict[str, None] = {}
    for result in results:
        names.update(dict.fromkeys(result.get("properties") or {}))
    return tuple(names)


def summarize_robustness(results: list[dict[str, Any]],
                         properties: tuple[str, ...] | None = None) -> RobustnessSummary:
    """Success rate, trials-to-tolerance distribution, and which properties predict failure.

    A property's predictive strength is the (point-biserial) correlation between the
    property and failure, listed strongest first. ``properties``: which (None: those the results carry).
    """
    done = list(results)
    if properties is None:
        properties = sampled_properties(None, done)
    success = np.array([bool(r.get("success")) for r in done])
    ttt = [r.get("trials_to_tolerance") for r in done]
    reached = [t for t in ttt if t is not None]
    predictors: list[tuple[str, float]] = []
    if len(done) >= 3 and 0 < success.sum() < len(done):
        for name in properties:
            values = np.array([r["properties"].get(name, math.nan) for r in done], dtype=float)
            if np.all(np.isfinite(values)) and values.std() > 0:
                predictors.append((name, float(np.corrcoef(values, ~success)[0, 1])))
        predictors.sort(key=lambda p: -abs(p[1]))
    return RobustnessSummary(
        vehicles=len(results),
        completed=len(done),
        success_rate=float(success.mean()) if len(done) else math.nan,
        median_trials_to_tolerance=float(np.median(reached)) if reached else math.nan,
        trials_to_tolerance=ttt,
        final_errors_m=[float(r.get("final_error_m", math.nan)) for r in done],
        predictors=predictors,
    )
