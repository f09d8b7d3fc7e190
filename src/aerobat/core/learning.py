"""Adaptive learning (Sect. 3 step 3, Sect. 5): p ← p − γ·C·e on any plant.

The learning core sees only parameter vectors, error vectors and trials: it
imports nothing about quadrocopters. :class:`Learner` is the method as an
ask/tell object — ``ask()`` the parameters to fly, ``tell(trial)`` what happened —
so a caller that flies trials its own way (a stored session, a study, a real
vehicle driven by hand) runs exactly the same algorithm as :func:`learn`, which
just loops over a plant. The learner's whole state (counters, parameters, the
update rule's state) is a JSON-ready table, so a session resumes exactly.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aerobat.config import check_int, short_repr
from aerobat.core.bounds import ITERATIONS, MAX_ITERATIONS
from aerobat.core.design import Design
from aerobat.core.maneuver import Maneuver, bounds_arrays, check_maneuver, error_scales, position_indices
from aerobat.core.notes import IterationNote, NoteKind, message_with_notes
from aerobat.core.outcomes import Iteration, IterationStatus, SessionStatus, iteration_json, session_document, step_to
from aerobat.core.plant import Plant, Trial, TrialStatus
from aerobat.core.rules.base import PaperRule, UpdateRule
from aerobat.core.rules.registry import RuleChoice, make_rule
from aerobat.errors import ConfigError, DesignFailed

__all__ = [
    "MAX_ATTEMPTS",
    "ITERATIONS",
    "MAX_ITERATIONS",
    "Iteration",
    "IterationStatus",
    "Learner",
    "Session",
    "SessionStatus",
    "constraint_scale",
    "learn",
    "step_to",
]


@dataclass(frozen=True)
class Session:
    """A learning run: its records, the final parameters and how it ended."""

    maneuver: Maneuver
    design: Design
    plant_name: str
    iterations: tuple[Iteration, ...]
    final_params: np.ndarray
    status: SessionStatus
    message: str
    wall_s: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", SessionStatus(self.status))

    @property
    def measured(self) -> list[Iteration]:
        """The iterations whose trial measured a final state, in order."""
        return [it for it in self.iterations if it.measured]

    def position_errors_m(self) -> np.ndarray:
        """(n_measured,) norm of the position components of each measured error [m]."""
        idx = position_indices(self.maneuver.errors)
        return np.array([float(np.linalg.norm(it.error[idx])) for it in self.measured])

    def __repr__(self) -> str:
        pos = self.position_errors_m()
        last = f", last position error {pos[-1]:.3g} m" if pos.size else ""
        return (f"Session({self.maneuver.name!r} on {self.plant_name!r}: {self.status.value}, "
                f"{len(self.measured)} measured of {len(self.iterations)} trials{last})")

    def plot(self, ax: Any = None, *, tolerance_m: float | None = None) -> Any:
        """Position error over the measured iterations on ``ax`` (a new figure if None); returns the figure."""
        from aerobat.core.figures import plot_position_errors

        return plot_position_errors(self.position_errors_m(), ax=ax, tolerance_m=tolerance_m,
                                    title=f"{self.maneuver.name} on {self.plant_name}")

    def to_json_dict(self) -> dict[str, Any]:
        """The session as plain JSON types: its status, parameters and every iteration."""
        return session_document(
            maneuver=self.maneuver.spec(), plant=self.plant_name,
            error_names=[e.name for e in self.maneuver.errors], error_units=[e.unit for e in self.maneuver.errors],
            parameter_names=[p.name for p in self.maneuver.parameters],
            parameter_units=[p.unit for p in self.maneuver.parameters], p_nominal=self.design.p_nominal.tolist(),
            iterations=[iteration_json(it) for it in self.iterations], final_params=self.final_params.tolist(),
            status=self.status.value, message=self.message, wall_s=self.wall_s)


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


@dataclass
class Learner:
    """The learning method as an ask/tell object.

    Parameters
    ----------
    maneuver, design : what to learn and its nominal design (p⁰, C).
    rule : update rule; default the paper's, with ``design.correction`` and γ = max(1/i, 0.1).
    params : parameters of the next trial (default p⁰).
    correction, index : counters of corrections made and trials recorded so far.
    measured : measured trials so far.
    absurd_limit : a measured error beyond this many error scales is rejected, not learned from.
    pinned_warning_after : warn once a parameter sits at a bound for this many corrections in a row.
    hold_pinned : hold parameters that sit at a bound and are pushed further out, instead of letting
        them scale the whole correction to zero (``False`` is the paper's literal Sect. 4.2 rule).
    """

    maneuver: Maneuver
    design: Design
    rule: UpdateRule | None = None
    params: np.ndarray | None = None
    correction: int = 0
    index: int = 0
    measured: int = 0
    absurd_limit: float = 200.0
    pinned_warning_after: int = 8
    hold_pinned: bool = True
    pinned_streak: np.ndarray | None = None
    warned: set[int] = field(default_factory=set)

    def __post_init__(self) -> None:
        check_maneuver(self.maneuver)
        if not isinstance(self.design, Design):
            raise ConfigError(f"Learner: design must be a Design (from aerobat.design()), got "
                              f"{type(self.design).__name__}")
        if isinstance(self.rule, str | RuleChoice):
            self.rule = make_rule(self.rule, self.design)  # a name: "tsvd", "kalman", …
        if self.rule is None:
            if not np.all(np.isfinite(self.design.correction)):
                raise ConfigError("the design's correction matrix is not finite (rank-deficient or failed design)")
            self.rule = PaperRule(self.design.correction)
        if not isinstance(self.rule, UpdateRule):
            raise ConfigError(f"Learner: rule must be an UpdateRule or a rule name, got {type(self.rule).__name__}")
        try:
            self.params = np.array(self.design.p_nominal if self.params is None else self.params, dtype=float)
        except (TypeError, ValueError, OverflowError):
            raise ConfigError(f"start parameters: expected {len(self.maneuver.parameters)} numbers, got "
                              f"{short_repr(self.params)}") from None
        if self.params.shape != (len(self.maneuver.parameters),):
            raise ConfigError(f"start parameters: expected {len(self.maneuver.parameters)} values, "
                              f"got shape {self.params.shape}")
        if not self.maneuver.is_valid(self.params):
            raise ConfigError("start parameters violate the maneuver's constraints")
        if self.pinned_streak is None:
            self.pinned_streak = np.zeros(self.params.size, dtype=int)
        self._lower, self._upper = bounds_arrays(self.maneuver.parameters)
        self._scales = error_scales(self.maneuver.errors)

    # ------------------------------------------------------------ ask / tell
    def ask(self) -> np.ndarray:
        """The parameters to fly next (a copy)."""
        assert self.params is not None
        return self.params.copy()

    def program(self) -> Any:
        """The program to fly next: ``maneuver.program(ask())``."""
        return self.maneuver.program(self.ask())

    def tell(self, trial: Trial) -> Iteration:
        """Record the trial flown with :meth:`ask`'s parameters; correct if it was measured."""
        assert self.params is not None and self.rule is not None and self.pinned_streak is not None
        params = self.params
        self.index += 1
        status = TrialStatus(trial.status)
        n_par, n_err = params.size, len(self.maneuver.errors)
        nothing = np.zeros(n_par)
        if not status.measured:
            return Iteration(self.index, 0, IterationStatus.of_trial(status), params.copy(), np.full(n_err, np.nan),
                             0.0, 0.0, nothing, trial.message, trial)
        error = self.maneuver.error(trial.final_state)
        problem = self._absurd(error)
        if problem:
            return Iteration(self.index, 0, IterationStatus.REJECTED, params.copy(), error, 0.0, 0.0, nothing,
                             problem, trial)
        self.measured += 1
        self.correction += 1
        step, gamma = self.rule.propose(self.correction, params, error, trial)
        notes: list[IterationNote] = []
        lower, upper = self._lower, self._upper
        if self.hold_pinned:
            # a parameter already at a bound, pushed further out, would make the Sect. 4.2 scale
            # zero for the whole correction; hold just that parameter and correct with the rest
            # "at" a bound within the same 1e-9 the pinned check below uses: a design's trust-region
            # solve leaves a pinned parameter a hair inside its bound, which would scale the step to ~0
            near_lower = np.isfinite(lower) & (params - lower <= 1e-9 * np.maximum(1.0, np.abs(lower)))
            near_upper = np.isfinite(upper) & (upper - params <= 1e-9 * np.maximum(1.0, np.abs(upper)))
            held = (near_lower & (step < 0)) | (near_upper & (step > 0))
            if held.any() and not held.all():
                step = np.where(held, 0.0, step)
                notes += [IterationNote.held(self.maneuver.parameters[k].name) for k in np.nonzero(held)[0]]
        scale = constraint_scale(self.maneuver, params, step)
        applied = scale * step
        at_bound = (np.abs(params + applied - lower) < 1e-9 * np.maximum(1.0, np.abs(lower))) | (
            np.abs(params + applied - upper) < 1e-9 * np.maximum(1.0, np.abs(upper)))
        self.pinned_streak = np.where(at_bound, self.pinned_streak + 1, 0)
        for k in np.nonzero(self.pinned_streak >= self.pinned_warning_after)[0]:
            if k not in self.warned:
                self.warned.add(int(k))
                spec = self.maneuver.parameters[k]
                notes.append(IterationNote(
                    NoteKind.PINNED_AT_BOUND, spec.name, f"{spec.name} ({spec.description}) pinned at a bound for "
                    f"{self.pinned_streak[k]} corrections: maneuver poorly formulated or infeasible here"))
        self.rule.observe(params, error, applied)
        self.params = params + applied
        return Iteration(self.index, self.correction, IterationStatus.OK, params.copy(), error, gamma, scale,
                         applied, message_with_notes(trial.message, notes), trial, tuple(notes))

    def _absurd(self, error: np.ndarray) -> str | None:
        if not np.all(np.isfinite(error)):
            return "non-finite measurement"
        worst = int(np.argmax(np.abs(error) / self._scales))
        if abs(error[worst]) > self.absurd_limit * self._scales[worst]:
            spec = self.maneuver.errors[worst]
            return (f"absurd measurement: {spec.name} = {error[worst]:+.3g} {spec.unit} "
                    f"(> {self.absurd_limit:g} × {spec.scale:g})")
        return None

    # ------------------------------------------------------------ state
    def state(self) -> dict[str, Any]:
        """JSON-ready state after the last :meth:`tell` (counters, parameters, the rule's state)."""
        assert self.params is not None and self.rule is not None and self.pinned_streak is not None
        return {
            "params": [float(v) for v in self.params],
            "correction": self.correction,
            "index": self.index,
            "measured": self.measured,
            "pinned_streak": [int(v) for v in self.pinned_streak],
            "warned": sorted(self.warned),
            "rule": self.rule.state(),
        }

    def load_state(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state` (the rule must be built as the saved one was)."""
        assert self.rule is not None
        try:
            params = np.array(state["params"], dtype=float)
            streak = np.array(state.get("pinned_streak", [0] * params.size), dtype=int)
            if params.shape != self.params.shape or streak.shape != params.shape:  # type: ignore[union-attr]
                raise ValueError(f"expected {self.params.size} parameters")  # type: ignore[union-attr]
            self.params = params
            self.correction = int(state["correction"])
            self.index = int(state["index"])
            self.measured = int(state["measured"])
            self.pinned_streak = streak
            self.warned = {int(k) for k in state.get("warned", [])}
            self.rule.load_state(state.get("rule", {}))
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(f"learner state: {type(exc).__name__}: {exc}") from None


MAX_ATTEMPTS = 3 * MAX_ITERATIONS + 10
"""The most trials one :func:`learn` call flies, lost and rejected ones included (its default cap at
:data:`MAX_ITERATIONS`)."""


def learn(
    maneuver: Maneuver,
    design: Design,
    plant: Plant,
    *,
    iterations: int,
    rule: UpdateRule | None = None,
    learner: Learner | None = None,
    start_params: np.ndarray | None = None,
    max_attempts: int | None = None,
    on_iteration: Callable[[Iteration], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
    force: bool = False,
    **options: Any,
) -> Session:
    """Fly, measure, correct, repeat (Sect. 3, step 3).

    Parameters
    ----------
    maneuver, design : what to learn and its nominal design (p⁰, C).
    plant : anything implementing :class:`~aerobat.core.plant.Plant`.
    iterations : number of measured trials (``ok``) to learn from, in :data:`ITERATIONS` (1 … :data:`MAX_ITERATIONS`).
    rule : update rule; default the paper's, with ``design.correction`` and γ = max(1/i, 0.1).
    learner : continue this learner instead of starting a new one (``rule`` and ``start_params``
        must then be None).
    start_params : start from these parameters instead of p⁰.
    max_attempts : cap on trials including lost and rejected ones (default 3 × iterations + 10; at most
        :data:`MAX_ATTEMPTS`).
    on_iteration : called with every record as soon as it exists (stores, progress output).
    should_stop : polled between trials; True ends the session as ``interrupted``.
    force : learn even from a design that did not converge (``aerobat learn --force``).
    options : :class:`Learner` options (``absurd_limit``, ``pinned_warning_after``, ``hold_pinned``).

    Notes
    -----
    A crashed or aborted trial ends the session with that status; lost triggers and lost
    contact are flown again; absurd measurements are rejected and flown again.

    Raises
    ------
    DesignFailed
        ``design`` did not converge (its p⁰ misses the target on the model) and ``force`` is not set.
    """
    if not isinstance(force, bool):
        raise ConfigError(f"force = {short_repr(force)}: expected True or False")
    if not isinstance(design, Design):
        raise ConfigError(f"design: expected a Design (from aerobat.design()), got {type(design).__name__} "
                          f"{short_repr(design)}")
    if not force and not design.converged:
        raise DesignFailed(f"design failed, nothing to learn: {design.message} (learn(..., force=True) learns from "
                           f"it anyway)", design)
    iterations = ITERATIONS.check("iterations", iterations)
    if not callable(getattr(plant, "fly", None)):
        raise ConfigError(f"plant: expected a plant (with fly(program), e.g. Arena(config)), got "
                          f"{type(plant).__name__} {short_repr(plant)}")
    if max_attempts is not None:
        check_int("max_attempts", max_attempts, low=1, high=MAX_ATTEMPTS)
    if learner is None:
        learner = Learner(maneuver, design, rule=rule, params=start_params, **options)
    elif rule is not None or start_params is not None or options:
        raise ConfigError("learn(learner=…) continues that learner: pass no rule, start_params or options")
    records: list[Iteration] = []
    max_attempts = max_attempts if max_attempts is not None else 3 * int(iterations) + 10
    measured = 0
    attempts = 0
    status, message = SessionStatus.COMPLETED, f"{iterations} measured iteration{'' if iterations == 1 else 's'}"
    started = time.perf_counter()
    while measured < iterations:
        if should_stop is not None and should_stop():
            status, message = SessionStatus.INTERRUPTED, (f"interrupted after {measured} measured "
                                                           f"iteration{'' if measured == 1 else 's'}")
            break
        if attempts >= max_attempts:
            status = SessionStatus.FAILED
            message = f"gave up after {attempts} trials with only {measured} measurements"
            break
        attempts += 1
        record = learner.tell(plant.fly(learner.program()))
        records.append(record)
        if on_iteration:
            on_iteration(record)
        if record.status in (IterationStatus.CRASHED, IterationStatus.ABORTED):
            status = SessionStatus(record.status.value)
            message = f"stopped: trial {record.index} {record.status.value}: {record.message}"
            break
        if record.measured:
            measured += 1
    return Session(maneuver, design, getattr(plant, "name", type(plant).__name__), tuple(records),
                   learner.ask(), status, message, time.perf_counter() - started)
