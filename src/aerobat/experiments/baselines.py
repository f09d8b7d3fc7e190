"""Model-free baselines for the rules study: CMA-ES and Bayesian optimization of the final-state error.

Both need optional packages (``pip install 'aerobat[baselines]'``; ``make`` installs
them). :func:`check_methods` tells, before a study submits a single job, which
method lacks its package.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from aerobat.core.design import Design
from aerobat.core.learning import SessionStatus
from aerobat.core.maneuver import Maneuver, bounds_arrays, error_scales, parameter_scales
from aerobat.core.plant import Plant, TrialStatus
from aerobat.errors import require

__all__ = ["BASELINES", "Baseline", "check_methods", "run_baseline"]


@dataclass(frozen=True)
class Baseline:
    """A model-free method: its name, what it is, and the package it needs."""

    name: str
    summary: str
    module: str
    extra: str = "baselines"

    def check_available(self) -> None:
        require(self.module, extra=self.extra, purpose=f"the {self.name} baseline ({self.summary})")


BASELINES = {
    "cma": Baseline("cma", "CMA-ES", "cma"),
    "bayesopt": Baseline("bayesopt", "Bayesian optimization", "bayes_opt"),
}


def check_methods(methods: list[str]) -> None:
    """Raise :class:`~aerobat.errors.MissingDependency` for the first baseline whose package is missing."""
    for method in methods:
        if method in BASELINES:
            BASELINES[method].check_available()


def _weighted_cost(maneuver: Maneuver, error: np.ndarray) -> float:
    return float(np.linalg.norm(error / error_scales(maneuver.errors)))


def _fly_measured(plant: Plant, maneuver: Maneuver, params: np.ndarray, max_retries: int = 20) -> np.ndarray | None:
    """Fly until a trial is measured (lost triggers are retried, as learning does); None on a crash."""
    for _ in range(max_retries):
        trial = plant.fly(maneuver.program(params))
        if trial.status is TrialStatus.OK:
            error = maneuver.error(trial.final_state)
            if np.all(np.isfinite(error)):
                return error
        elif not trial.status.retry:
            return None
    return None


def run_baseline(method: str, maneuver: Maneuver, design: Design, plant: Plant, trials: int,
                 seed: int) -> dict[str, Any]:
    """CMA-ES or Bayesian optimization of the weighted final-state error, one trial per evaluation.

    Both search in scaled coordinates (parameter / its scale) around p⁰ within the
    parameter bounds, with their libraries' default settings otherwise (CMA-ES: default
    population 4 + 3 ln n; Bayesian optimization: default GP and acquisition, p⁰ probed
    first). The search width is ours to choose: σ₀ = 0.25 scales for CMA-ES and a box of
    ±1.5 scales for Bayesian optimization — with σ₀ = 1 scale (±20 ms on the coast
    duration, ±36° of flip angle) the first triple-flip samples already crash.

    Returns ``{"errors": [...], "status": "completed" | "crashed"}``.
    """
    lower, upper = bounds_arrays(maneuver.parameters)
    scales = parameter_scales(maneuver.parameters)
    p0 = np.asarray(design.p_nominal, dtype=float)
    lo = np.maximum((lower - p0) / scales, -1.5)
    hi = np.minimum((upper - p0) / scales, 1.5)
    errors: list[np.ndarray] = []
    status = SessionStatus.COMPLETED

    def evaluate(z: np.ndarray) -> float | None:
        params = np.clip(p0 + scales * np.asarray(z, dtype=float), lower, upper)
        error = _fly_measured(plant, maneuver, params)
        if error is None:
            return None
        errors.append(error)
        return _weighted_cost(maneuver, error)

    if method == "cma":
        cma = require("cma", extra="baselines", purpose="the cma baseline (CMA-ES)")
        es = cma.CMAEvolutionStrategy(np.zeros(p0.size), 0.25, {"bounds": [list(lo), list(hi)], "seed": seed + 1,
                                                              "verbose": -9})
        while len(errors) < trials and not es.stop():
            candidates = es.ask()
            values = []
            for z in candidates:
                if len(errors) >= trials:
                    break
                v = evaluate(z)
                if v is None:
                    status = SessionStatus.CRASHED
                    break
                values.append(v)
            if status is not SessionStatus.COMPLETED or len(values) < len(candidates):
                break
            es.tell(candidates, values)
    elif method == "bayesopt":
        bayes_opt = require("bayes_opt", extra="baselines", purpose="the bayesopt baseline (Bayesian optimization)")
        names = [p.name for p in maneuver.parameters]
        optimizer = bayes_opt.BayesianOptimization(
            f=None, pbounds={n: (float(a), float(b)) for n, a, b in zip(names, lo, hi, strict=True)},
            random_state=seed, verbose=0, allow_duplicate_points=True)
        point: dict[str, Any] = {n: 0.0 for n in names}
        while len(errors) < trials:
            v = evaluate(np.array([point[n] for n in names]))
            if v is None:
                status = SessionStatus.CRASHED
                break
            optimizer.register(params=point, target=-v)
            point = optimizer.suggest()
    else:
        raise ValueError(f"unknown model-free method {method!r}")
    return {"errors": errors, "status": status.value}
