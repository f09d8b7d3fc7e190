"""The built-in job kinds: pure functions of a JSON specification, so a job runs the same anywhere.

A learning job's specification carries everything it needs — the maneuver's spec,
the design (computed once per study), the nominal vehicle, the plant with its
settings and seed, the method — and its result carries every iteration, so the
study's process stores each run as a session, linked to the study.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from aerobat.core.design import Design, design
from aerobat.core.learning import Iteration, SessionStatus, learn
from aerobat.core.maneuver import ErrorKind, Maneuver, position_indices
from aerobat.core.registry import from_spec
from aerobat.core.rules import RuleChoice
from aerobat.errors import ConfigError
from aerobat.experiments.baselines import BASELINES, run_baseline
from aerobat.experiments.job import job_kind
from aerobat.experiments.job_specs import BenchmarkJob, DesignJob, LearnJob, RuleRunJob
from aerobat.experiments.setup import build_rule
from aerobat.plants import PlantChoice
from aerobat.quadrotor.dynamics import POS
from aerobat.quadrotor.simulate import NominalModel, simulate
from aerobat.quadrotor.vehicle import VehicleConfig, vehicle_from_table

__all__ = ["benchmark_job", "design_job", "learn_job", "learning_setup", "rule_run_job"]


def learning_setup(spec: LearnJob | RuleRunJob) -> tuple[Maneuver, Design, VehicleConfig, PlantChoice]:
    """(maneuver, design, nominal vehicle, plant choice) of a learning job."""
    maneuver = from_spec(spec.maneuver, source="job maneuver")
    model = vehicle_from_table(spec.model, source="job model")
    result = Design.from_json_dict(maneuver, spec.design)
    plant = PlantChoice.from_table(spec.plant, source="job plant")
    return maneuver, result, model, plant


def _records(iterations: tuple[Iteration, ...]) -> list[dict[str, Any]]:
    return [it.to_json_dict() for it in iterations]


def _position_errors(maneuver: Maneuver, errors: list[np.ndarray]) -> list[float]:
    idx = position_indices(maneuver.errors)
    return [float(np.linalg.norm(np.asarray(e)[idx])) for e in errors]


@job_kind("learn")
def learn_job(table: dict[str, Any]) -> dict[str, Any]:
    """One learning run (a robustness study's vehicle, :class:`LearnJob`): the design travels in the spec."""
    start = time.perf_counter()
    spec = LearnJob.from_table(table)
    maneuver, result, model, plant_choice = learning_setup(spec)
    choice = RuleChoice.parse(spec.rule, source="job rule")
    session = learn(maneuver, result, plant_choice.build(model), iterations=int(spec.iterations),
                    rule=build_rule(choice, result, model))
    errors = _position_errors(maneuver, [it.error for it in session.measured])
    tol = float(spec.tolerance_m)
    first_below = next((k + 1 for k, e in enumerate(errors) if e < tol), None)
    last = errors[-10:] if errors else [math.nan]
    return {
        "status": session.status.value,
        "message": session.message,
        "position_errors_m": errors,
        "first_error_m": errors[0] if errors else math.nan,
        "final_error_m": float(np.mean(last)),
        "trials_to_tolerance": first_below,
        "success": bool(session.status is SessionStatus.COMPLETED and float(np.mean(last)) <= tol),
        "final_params": session.final_params.tolist(),
        "lost_trials": sum(1 for it in session.iterations if it.status.retry),
        "properties": spec.properties,
        "iterations": _records(session.iterations),
        "wall_s": time.perf_counter() - start,
    }


@job_kind("design")
def design_job(table: dict[str, Any]) -> dict[str, Any]:
    """Nominal design of one maneuver (:class:`DesignJob`): feasibility, duration, apex height, conditioning."""
    spec = DesignJob.from_table(table)
    maneuver = from_spec(spec.maneuver, source="job maneuver")
    model = vehicle_from_table(spec.model, source="job model")
    result = design(maneuver, NominalModel(model))
    continued_from: list[float] = []
    if not result.converged and spec.continuation:
        result, continued_from = _continued(spec, model, result)
    apex = lowest = math.nan
    if result.converged:
        traj = simulate(maneuver.program(result.p_nominal), model)
        apex = float(traj.states[:, POS][:, 2].max())
        lowest = float(traj.states[:, POS][:, 2].min())
    return {
        "status": result.status.value,
        "message": result.message,
        "converged": result.converged,
        "duration_s": result.duration_s if result.converged else math.nan,
        "apex_m": apex,
        "lowest_m": lowest,
        "condition_number": result.condition_number if result.converged else math.nan,
        "residual_norm": result.residual_norm,
        "p_nominal": result.p_nominal.tolist(),
        "continued_from_deg_s": continued_from,
    }


CONTINUATION_STEPS = (0.25, 0.5)
"""A flip whose design fails from its guess is tried again from its neighbours: the same flip at these
fractions below and above its maximum rate, designed from their own guesses."""


def _continued(spec: DesignJob, model: Any, failed: Any) -> tuple[Any, list[float]]:
    """A design of ``spec``'s flip that failed from its guess (eqs 37–39), tried again from the mean p⁰ of
    the same flip at a lower and a higher maximum rate (each of :data:`CONTINUATION_STEPS`) when both
    converge: the guess, not the flip, may be what failed. ``(design, [lower, upper] rates [deg/s])``, or
    the failed design and ``[]``."""
    base = dict(spec.maneuver)
    if not isinstance(base.get("max_rate_rad_s"), int | float):
        return failed, []  # not a flip: nothing to continue along
    rate = float(base["max_rate_rad_s"])
    for step in CONTINUATION_STEPS:
        neighbours = []
        for factor in (1.0 - step, 1.0 + step):
            try:
                neighbour = from_spec({**base, "max_rate_rad_s": rate * factor}, source="job maneuver")
            except ConfigError:  # beyond the flip's own bounds on the rate
                break
            found = design(neighbour, NominalModel(model))
            if not found.converged:
                break
            neighbours.append(found)
        if len(neighbours) < 2:
            continue
        maneuver = from_spec(base, source="job maneuver")
        guess = 0.5 * (neighbours[0].p_nominal + neighbours[1].p_nominal)
        result = design(maneuver, NominalModel(model), p_guess=guess)
        if result.converged:
            return result, [round(math.degrees(rate * (1 - step)), 6), round(math.degrees(rate * (1 + step)), 6)]
    return failed, []


@job_kind("benchmark")
def benchmark_job(table: dict[str, Any]) -> dict[str, Any]:
    """One time-optimal solve (a point of a benchmark map, :class:`BenchmarkJob`)."""
    from aerobat.quadrotor.timeoptimal import BenchmarkLimits, solve_translation

    spec = BenchmarkJob.from_table(table)
    limits = BenchmarkLimits(**spec.limits)
    solution = solve_translation(float(spec.y_m), float(spec.z_m), limits=limits)
    return {"status": solution.status.value, "message": solution.message,
            "duration_s": solution.duration_s if solution.ok else math.nan}


@job_kind("rule_run")
def rule_run_job(table: dict[str, Any]) -> dict[str, Any]:
    """One method (update rule or model-free baseline) learning one maneuver on one plant seed (:class:`RuleRunJob`)."""
    start = time.perf_counter()
    spec = RuleRunJob.from_table(table)
    maneuver, result, model, plant_choice = learning_setup(spec)
    plant = plant_choice.build(model)
    method = spec.method
    trials = int(spec.trials)
    iterations: list[dict[str, Any]] = []
    if method in BASELINES:
        outcome = run_baseline(method, maneuver, result, plant, trials, int(plant_choice.seed))
        errors, status = outcome["errors"], SessionStatus(outcome["status"])
    else:
        choice = RuleChoice.parse(method, source="job method")
        session = learn(maneuver, result, plant, iterations=trials, rule=build_rule(choice, result, model))
        errors, status = [it.error for it in session.measured], session.status
        iterations = _records(session.iterations)
    pos = _position_errors(maneuver, errors)
    tol = float(spec.tolerance_m)
    first = next((k + 1 for k, e in enumerate(pos) if e < tol), None)
    later = pos[first:] if first is not None else []
    last = pos[-10:] if pos else [math.nan]
    diverged = bool(pos and np.mean(last) > pos[0])
    angle_idx = [k for k, e in enumerate(maneuver.errors) if e.kind is ErrorKind.ANGLE]
    tail = np.array([np.asarray(e)[angle_idx] for e in errors[-10:]]) if errors and angle_idx else None
    labels: dict[str, Any] = {key: getattr(spec, key) for key in ("scenario", "scheme")
                              if getattr(spec, key) is not None}
    return {
        **labels,
        "last10_angle_deg": ([] if tail is None else np.degrees(np.mean(np.abs(tail), axis=0)).tolist()),
        "method": method,
        "status": status.value,
        "position_errors_m": pos,
        "trials_to_tolerance": first,
        "share_below_after": (float(np.mean([e < tol for e in later])) if later
                              else (math.nan if first is None else 1.0)),
        "last10_mean_m": float(np.mean(last)),
        "failed": bool(status is not SessionStatus.COMPLETED or diverged or len(pos) < trials),
        "iterations": iterations,
        "wall_s": time.perf_counter() - start,
    }
