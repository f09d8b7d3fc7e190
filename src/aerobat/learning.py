"""Adaptive learning (Sect. 3 step 3, Sect. 5): p ← p − γ·C·e on any plant.

The learning core sees only parameter vectors, error vectors and trials: it
imports nothing about quadrocopters. Update rules and step-size schedules are
pluggable protocols; the paper's rule is :class:`CorrectionRule` with
:class:`PaperSchedule`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from .design import Design
from .maneuvers.base import Maneuver, bounds_arrays
from .plants.base import Plant, Trial

__all__ = [
    "ConstantSchedule",
    "CorrectionRule",
    "Iteration",
    "PaperSchedule",
    "Schedule",
    "Session",
    "UpdateRule",
    "constraint_scale",
    "learn",
]


# ------------------------------------------------------------------ schedules


class Schedule(Protocol):
    def gamma(self, i: int) -> float:
        """Step size for the i-th correction (i starts at 1)."""
        ...


@dataclass(frozen=True)
class PaperSchedule:
    """γ_i = max(1/i, γ_min), the paper's mixed strategy (γ_min = 0.1)."""

    minimum: float = 0.1

    def gamma(self, i: int) -> float:
        return max(1.0 / i, self.minimum)


@dataclass(frozen=True)
class ConstantSchedule:
    """γ_i = γ."""

    value: float = 1.0

    def gamma(self, i: int) -> float:
        return self.value


# ------------------------------------------------------------------ update rules


class UpdateRule(Protocol):
    """Proposes a parameter change from one trial's outcome."""

    name: str

    def propose(self, i: int, params: np.ndarray, error: np.ndarray, trial: Trial) -> tuple[np.ndarray, float]:
        """(Δp before constraint scaling, γ used) for correction number ``i`` (from 1)."""
        ...

    def observe(self, params: np.ndarray, error: np.ndarray, step: np.ndarray) -> None:
        """Told the step that was actually applied (after constraint scaling)."""
        ...

    def state(self) -> dict[str, Any]:
        """JSON-ready internal state, so a session can be resumed."""
        ...


@dataclass
class CorrectionRule:
    """The paper's rule: Δp = −γ_i·C·e (eq 4)."""

    correction: np.ndarray
    schedule: Schedule = field(default_factory=PaperSchedule)
    name: str = "paper"

    def propose(self, i: int, params: np.ndarray, error: np.ndarray, trial: Trial) -> tuple[np.ndarray, float]:
        gamma = self.schedule.gamma(i)
        return -gamma * (self.correction @ error), gamma

    def observe(self, params: np.ndarray, error: np.ndarray, step: np.ndarray) -> None:
        return None

    def state(self) -> dict[str, Any]:
        return {}


# ---------------------------------------------------------------- records


@dataclass(frozen=True)
class Iteration:
    """One trial and what learning did with it.

    Attributes
    ----------
    index : 1-based record number (every trial, including lost ones).
    correction : 1-based number of the correction this trial drove (0 if none).
    status : the trial's status, or ``rejected`` (non-finite/absurd measurement).
    params : (n_par,) parameters flown.
    error : (n_err,) measured error (NaN if none).
    gamma : step size used (0 if no correction).
    scale : constraint scaling applied to the correction (1 = none, Sect. 4.2).
    message : the plant's or learner's explanation.
    trial : the trial itself (measured trajectory and final state).
    """

    index: int
    correction: int
    status: str
    params: np.ndarray
    error: np.ndarray
    gamma: float
    scale: float
    message: str
    trial: Trial | None = None

    def to_json_dict(self) -> dict[str, Any]:
        return {
            "i": self.index,
            "correction": self.correction,
            "status": self.status,
            "params": [float(v) for v in self.params],
            "error": [float(v) if math.isfinite(v) else None for v in self.error],
            "gamma": self.gamma,
            "scale": self.scale,
            "message": self.message,
        }


@dataclass(frozen=True)
class Session:
    """A learning run: its records, the final parameters and how it ended."""

    maneuver: Maneuver
    design: Design
    plant_name: str
    iterations: tuple[Iteration, ...]
    final_params: np.ndarray
    status: str
    message: str
    wall_s: float

    @property
    def measured(self) -> list[Iteration]:
        return [it for it in self.iterations if it.status == "ok"]

    def to_json_dict(self) -> dict[str, Any]:
        return {
            "maneuver": self.maneuver.spec(),
            "plant": self.plant_name,
            "error_names": [e.name for e in self.maneuver.errors],
            "error_units": [e.unit for e in self.maneuver.errors],
            "parameter_names": [p.name for p in self.maneuver.parameters],
            "parameter_units": [p.unit for p in self.maneuver.parameters],
            "p_nominal": self.design.p_nominal.tolist(),
            "iterations": [it.to_json_dict() for it in self.iterations],
            "final_params": self.final_params.tolist(),
            "status": self.status,
            "message": self.message,
            "wall_s": self.wall_s,
        }


# ------------------------------------------------------------------- core


def constraint_scale(maneuver: Maneuver, params: np.ndarray, step: np.ndarray) -> float:
    """Largest s ∈ [0, 1] with params + s·step valid (Sect. 4.2: scale the correction down)."""
    lower, upper = bounds_arrays(maneuver.parameters)
    s = 1.0
    for k in range(params.size):
        if step[k] > 0 and math.isfinite(upper[k]):
            s = min(s, max(0.0, (upper[k] - params[k]) / step[k]))
        elif step[k] < 0 and math.isfinite(lower[k]):
            s = min(s, max(0.0, (lower[k] - params[k]) / step[k]))
    candidate = params + s * step
    candidate = np.clip(candidate, lower, upper)
    halvings = 0
    while not maneuver.is_valid(candidate) and halvings < 30:
        s *= 0.5
        candidate = np.clip(params + s * step, lower, upper)
        halvings += 1
    return s if maneuver.is_valid(candidate) else 0.0


def _absurd(maneuver: Maneuver, error: np.ndarray, limit: float) -> str | None:
    if not np.all(np.isfinite(error)):
        return "non-finite measurement"
    scales = np.array([e.scale for e in maneuver.errors])
    worst = int(np.argmax(np.abs(error) / scales))
    if abs(error[worst]) > limit * scales[worst]:
        spec = maneuver.errors[worst]
        return f"absurd measurement: {spec.name} = {error[worst]:+.3g} {spec.unit} (> {limit:g} × {spec.scale:g})"
    return None


def learn(
    maneuver: Maneuver,
    design: Design,
    plant: Plant,
    *,
    iterations: int,
    rule: UpdateRule | None = None,
    start_params: np.ndarray | None = None,
    start_correction: int = 0,
    start_index: int = 0,
    max_attempts: int | None = None,
    absurd_limit: float = 200.0,
    pinned_warning_after: int = 8,
    hold_pinned: bool = True,
    on_iteration: Callable[[Iteration], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> Session:
    """Fly, measure, correct, repeat (Sect. 3, step 3).

    Parameters
    ----------
    maneuver, design : what to learn and its nominal design (p⁰, C).
    plant : anything implementing :class:`~aerobat.plants.base.Plant`.
    iterations : number of measured trials (``ok``) to learn from.
    rule : update rule; default the paper's, with ``design.correction`` and γ = max(1/i, 0.1).
    start_params : resume from these parameters instead of p⁰.
    start_correction, start_index : counters to continue from when resuming.
    max_attempts : cap on trials including lost and rejected ones (default 3 × iterations).
    absurd_limit : a measured error beyond this many error scales is rejected, not learned from.
    pinned_warning_after : warn once a parameter sits at a bound for this many corrections in a row.
    hold_pinned : hold parameters that sit at a bound and are pushed further out, instead of letting
        them scale the whole correction to zero (``False`` is the paper's literal Sect. 4.2 rule).
    on_iteration : called with every record as soon as it exists (stores, progress bars).
    should_stop : polled between trials; True ends the session as ``interrupted``.
    """
    if iterations < 0:
        raise ValueError(f"iterations = {iterations} must be >= 0")
    rule = rule or CorrectionRule(design.correction)
    if not np.all(np.isfinite(design.correction)):
        raise ValueError("the design's correction matrix is not finite (rank-deficient or failed design)")
    params = np.array(design.p_nominal if start_params is None else start_params, dtype=float)
    if not maneuver.is_valid(params):
        raise ValueError("start parameters violate the maneuver's constraints")
    lower, upper = bounds_arrays(maneuver.parameters)
    records: list[Iteration] = []
    correction = start_correction
    index = start_index
    max_attempts = max_attempts if max_attempts is not None else 3 * iterations + 10
    measured = 0
    pinned_streak = np.zeros(params.size, dtype=int)
    warned: set[int] = set()
    status, message = "completed", f"{iterations} measured iterations"
    started = time.perf_counter()
    attempts = 0
    while measured < iterations:
        if should_stop is not None and should_stop():
            status, message = "interrupted", f"interrupted after {measured} measured iterations"
            break
        if attempts >= max_attempts:
            status = "failed"
            message = f"gave up after {attempts} trials with only {measured} measurements"
            break
        attempts += 1
        index += 1
        trial = plant.fly(maneuver.program(params))
        nan_error = np.full(len(maneuver.errors), np.nan)
        if trial.status == "no_trigger":
            rec = Iteration(index, 0, "no_trigger", params.copy(), nan_error, 0.0, 0.0, trial.message, trial)
            records.append(rec)
            if on_iteration:
                on_iteration(rec)
            continue
        if trial.status in ("crashed", "aborted"):
            rec = Iteration(index, 0, trial.status, params.copy(), nan_error, 0.0, 0.0, trial.message, trial)
            records.append(rec)
            if on_iteration:
                on_iteration(rec)
            status = trial.status
            message = f"stopped: trial {index} {trial.status}: {trial.message}"
            break
        error = maneuver.error(trial.final_state)
        problem = _absurd(maneuver, error, absurd_limit)
        if problem:
            rec = Iteration(index, 0, "rejected", params.copy(), error, 0.0, 0.0, problem, trial)
            records.append(rec)
            if on_iteration:
                on_iteration(rec)
            continue
        measured += 1
        correction += 1
        step, gamma = rule.propose(correction, params, error, trial)
        note = trial.message
        if hold_pinned:
            # a parameter already at a bound, pushed further out, would make the Sect. 4.2 scale
            # zero for the whole correction; hold just that parameter and correct with the rest
            held = ((params <= lower) & (step < 0)) | ((params >= upper) & (step > 0))
            if held.any() and not held.all():
                step = np.where(held, 0.0, step)
                note += "; held at a bound: " + ", ".join(maneuver.parameters[k].name for k in np.nonzero(held)[0])
        scale = constraint_scale(maneuver, params, step)
        applied = scale * step
        at_bound = (np.abs(params + applied - lower) < 1e-9 * np.maximum(1.0, np.abs(lower))) | (
            np.abs(params + applied - upper) < 1e-9 * np.maximum(1.0, np.abs(upper)))
        pinned_streak = np.where(at_bound, pinned_streak + 1, 0)
        for k in np.nonzero(pinned_streak >= pinned_warning_after)[0]:
            if k not in warned:
                warned.add(int(k))
                spec = maneuver.parameters[k]
                note += (f"; warning: {spec.name} ({spec.description}) pinned at a bound for "
                         f"{pinned_streak[k]} corrections: maneuver poorly formulated or infeasible here")
        rec = Iteration(index, correction, "ok", params.copy(), error, gamma, scale, note, trial)
        records.append(rec)
        if on_iteration:
            on_iteration(rec)
        rule.observe(params, error, applied)
        params = params + applied
    return Session(maneuver, design, getattr(plant, "name", type(plant).__name__), tuple(records), params,
                   status, message, time.perf_counter() - started)
