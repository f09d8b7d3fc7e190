"""The benchmark map: minimum time of the time-optimal benchmark over a grid of targets (Sect. 9)."""

from __future__ import annotations

import csv
import io
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from aerobat.experiments.job import Job
from aerobat.experiments.job_specs import BenchmarkJob

__all__ = ["map_csv", "map_grid", "map_jobs"]

Grid = Sequence[float] | np.ndarray
"""Target coordinates along one axis [m]."""


def _key(i: int, j: int) -> str:
    return f"y{i:03d}-z{j:03d}"


def map_jobs(ys_m: Grid, zs_m: Grid, limits: Mapping[str, float]) -> list[Job]:
    """One benchmark solve per target (y, z)."""
    return [Job(key=_key(i, j), kind=BenchmarkJob.kind,
                spec=BenchmarkJob(y_m=float(y), z_m=float(z), limits=dict(limits)).to_table())
            for j, z in enumerate(zs_m) for i, y in enumerate(ys_m)]


def map_grid(results: Mapping[str, Mapping[str, Any]], ys_m: Grid, zs_m: Grid) -> np.ndarray:
    """(len(zs), len(ys)) minimum times; NaN where the solve failed or its job did not finish."""
    grid = np.full((len(zs_m), len(ys_m)), np.nan)
    for j in range(len(zs_m)):
        for i in range(len(ys_m)):
            value = results.get(_key(i, j), {}).get("duration_s")
            grid[j, i] = value if isinstance(value, float) else np.nan
    return grid


def map_csv(ys_m: Grid, zs_m: Grid, durations: np.ndarray) -> str:
    """The map as CSV text with columns ``y_m, z_m, duration_s`` (``nan`` where no time)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["y_m", "z_m", "duration_s"])
    for i, z in enumerate(zs_m):
        for j, y in enumerate(ys_m):
            writer.writerow([repr(float(y)), repr(float(z)), repr(float(durations[i, j]))])
    return buffer.getvalue()
