"""The rules study: every update rule and the model-free baselines on the same plant seeds, side by side."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from aerobat.core.design import Design
from aerobat.core.maneuver import Maneuver
from aerobat.core.rules import RULES, RuleChoice
from aerobat.errors import ConfigError
from aerobat.experiments.baselines import BASELINES
from aerobat.experiments.designing import NominalDesign, job_design
from aerobat.experiments.job import Job
from aerobat.experiments.job_specs import RuleRunJob
from aerobat.plants import PlantChoice
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["DEFAULT_METHODS", "check_method_names", "parse_methods", "rules_study_jobs", "summarize_rules"]

DEFAULT_METHODS = ("paper", "tsvd", "damped", "kalman", "broyden", "tsvd+isc", "cma", "bayesopt")
"""What ``aerobat study rules`` compares by default."""


def parse_methods(text: str, *, source: str = "--methods") -> list[str]:
    """A comma list of update rules (``+isc`` allowed) and baselines (``cma``, ``bayesopt``), checked."""
    methods = [m.strip() for m in str(text).split(",") if m.strip()]
    return check_method_names(methods, source=source, text=text)


def check_method_names(methods: Sequence[str], *, source: str = "methods", text: str | None = None) -> list[str]:
    """``methods`` if each is an update rule (``+isc`` allowed) or a baseline, named once; else
    :class:`~aerobat.errors.ConfigError` naming ``source`` (``text``: what the user wrote, for the message)."""
    methods = list(methods)
    if not methods:
        raise ConfigError(f"{source}: name at least one method")
    for method in methods:
        if method not in BASELINES:
            RuleChoice.parse(method, source=source)
    if len(set(methods)) != len(methods):
        raise ConfigError(f"{source} {text if text is not None else ','.join(methods)!r}: a method is named twice")
    return methods


def all_methods() -> list[str]:
    """Every method the rules study knows."""
    return [*RULES.names(), *(f"{r}+isc" for r in RULES.names()), *BASELINES]


def rules_study_jobs(maneuver: Maneuver, design: Design | NominalDesign,
                     model: VehicleConfig, *, methods: list[str], seeds: int,
                     trials: int, plant: PlantChoice, tolerance_m: float = 0.12) -> list[Job]:
    """Every method on the same ``seeds`` plant seeds (``plant.seed``, ``plant.seed + 1``, …)."""
    design_table, model_table = job_design(design, model)
    return [
        Job(key=f"{method}-seed-{plant.seed + k:04d}", kind=RuleRunJob.kind, spec=RuleRunJob(
            maneuver=maneuver.spec(), design=design_table, model=model_table,
            plant={**plant.to_table(), "seed": plant.seed + k}, method=method, trials=trials,
            tolerance_m=tolerance_m).to_table())
        for method in methods for k in range(seeds)
    ]


def summarize_rules(results: list[dict[str, Any]], methods: list[str],
                    failed_jobs: dict[str, list[str]] | None = None) -> list[dict[str, Any]]:
    """Per method: median trials to tolerance, share staying below, last-10 mean, failures, wall time.

    ``failed_jobs`` maps a method to the errors of its jobs that raised; they count as failed runs
    and are listed, never dropped. Every method in ``methods`` gets a row.
    """
    failed_jobs = failed_jobs or {}
    rows = []
    for method in methods:
        runs = [r for r in results if r["method"] == method]
        errors = failed_jobs.get(method, [])
        ttt = [r["trials_to_tolerance"] if r["trials_to_tolerance"] is not None else math.inf for r in runs]
        ttt += [math.inf] * len(errors)
        shares = [r["share_below_after"] for r in runs if not math.isnan(r["share_below_after"])]
        rows.append({
            "method": method,
            "runs": len(runs) + len(errors),
            "median_trials_to_tolerance": float(np.median(ttt)) if ttt else math.nan,
            "reached": sum(1 for t in ttt if math.isfinite(t)),
            "share_below_after": float(np.mean(shares)) if shares else math.nan,
            "last10_mean_m": float(np.mean([r["last10_mean_m"] for r in runs])) if runs else math.nan,
            "failures": sum(1 for r in runs if r["failed"]) + len(errors),
            "job_errors": errors,
            "wall_s": float(np.mean([r["wall_s"] for r in runs])) if runs else math.nan,
        })
    return rows
