"""The envelope study: design a grid of flips (flip count × max rate) and map what is feasible."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from aerobat.experiments.job import Job, JobStatus
from aerobat.experiments.job_specs import DesignJob
from aerobat.quadrotor.vehicle import VehicleConfig, vehicle_table

__all__ = ["ENVELOPE_QUANTITIES", "envelope_grid", "envelope_jobs", "envelope_key"]

ENVELOPE_QUANTITIES = ("duration_s", "apex_m", "condition_number")
"""What each design job reports besides feasibility."""


def envelope_key(flips: int, rate_deg_s: float) -> str:
    return f"flips-{flips}-rate-{rate_deg_s:g}"


def envelope_jobs(base_spec: Mapping[str, Any], model: VehicleConfig, flips: Sequence[int],
                  rates_deg_s: Sequence[float]) -> list[Job]:
    """One design job per (flip count, max rate) of a flip specification; one that fails from its guess is
    tried again by continuation from its neighbours in rate (:func:`aerobat.experiments.jobs.design_job`)."""
    model_table = vehicle_table(model)
    return [Job(key=envelope_key(n, rate), kind=DesignJob.kind, spec=DesignJob(
        maneuver=dict(base_spec, flips=int(n), max_rate_rad_s=math.radians(rate)), model=model_table,
        continuation=True).to_table()) for n in flips for rate in rates_deg_s]


def envelope_grid(results: Mapping[str, Mapping[str, Any]], flips: Sequence[int],
                  rates_deg_s: Sequence[float]) -> tuple[np.ndarray, dict[str, np.ndarray], list[dict[str, Any]]]:
    """(feasible 0/1/NaN, {quantity: grid}, one row per cell) over flips × rates; NaN where a job failed."""
    feasible = np.full((len(flips), len(rates_deg_s)), np.nan)
    grid = {q: np.full((len(flips), len(rates_deg_s)), np.nan) for q in ENVELOPE_QUANTITIES}
    rows = []
    for i, n in enumerate(flips):
        for j, rate in enumerate(rates_deg_s):
            r = results.get(envelope_key(n, rate))
            if r is not None:
                feasible[i, j] = 1.0 if r.get("converged") else 0.0
                for q in grid:
                    value = r.get(q)
                    grid[q][i, j] = value if isinstance(value, float) else np.nan
            job = JobStatus.DONE if r is not None else JobStatus.FAILED
            rows.append({"flips": n, "max_rate_deg_s": rate, "job": job,
                         **{k: (r or {}).get(k) for k in ("converged", "status", "duration_s", "apex_m", "lowest_m",
                                                          "condition_number", "continued_from_deg_s")}})
    return feasible, grid, rows
