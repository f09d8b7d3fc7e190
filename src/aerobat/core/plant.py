"""The plant protocol: anything that can fly a program and report what happened.

The learning loop only ever sees this: a program goes in, a :class:`Trial` comes
out. Plants are the nominal model, the simulated arena, RotorPy, Betaflight's
firmware in the loop, or hardware. A plant never raises for a trial that went
wrong: the trial's :class:`TrialStatus` says what happened, its message why.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["DeterministicPlant", "MaybeRepeatablePlant", "Plant", "Signals", "StatefulPlant", "Trial", "TrialStatus",
           "is_deterministic", "repeats_exactly"]


class TrialStatus(StrEnum):
    """How one flight ended."""

    OK = "ok"
    NO_TRIGGER = "no_trigger"
    CRASHED = "crashed"
    ABORTED = "aborted"
    LOST = "lost"

    @property
    def meaning(self) -> str:
        """One sentence on what this trial status means."""
        return _TRIAL_MEANINGS[self]

    @property
    def measured(self) -> bool:
        """A final state was measured."""
        return self is TrialStatus.OK

    @property
    def retry(self) -> bool:
        """Nothing was learned and nothing is wrong with the parameters: fly them again."""
        return self in (TrialStatus.NO_TRIGGER, TrialStatus.LOST)


_TRIAL_MEANINGS = {
    TrialStatus.OK: "the final state was measured",
    TrialStatus.NO_TRIGGER: "the maneuver never started (lost trigger); no error available, flown again",
    TrialStatus.CRASHED: "the vehicle left the flight volume or hit the ground",
    TrialStatus.ABORTED: "the trial was aborted (upload failure, non-finite state, supervisor limit)",
    TrialStatus.LOST: "the plant stopped answering (firmware or simulator died); restarted and flown again",
}


@dataclass(frozen=True)
class Signals:
    """What a plant sampled inside itself while it flew the maneuver, beside the measured states.

    A flight controller in the loop has signals no motion capture sees: its rate set point,
    its PID terms, its motor commands. A plant that has them returns them here, a row per
    sample, so they are stored with the trial and exported beside its trajectory.

    Attributes
    ----------
    times_s : (K,) sample times relative to the maneuver start [s].
    names : (C,) one name per column, its unit in the name (``setpoint_roll_deg_s``).
    values : (K, C) the samples.
    """

    times_s: np.ndarray
    names: tuple[str, ...]
    values: np.ndarray

    def __post_init__(self) -> None:
        times = np.asarray(self.times_s, dtype=np.float64).reshape(-1)
        values = np.asarray(self.values, dtype=np.float64)
        names = tuple(str(n) for n in self.names)
        if values.shape != (times.size, len(names)):
            raise ValueError(f"signals: values {values.shape}, expected {(times.size, len(names))} "
                             f"(one row per time, one column per name)")
        if len(set(names)) != len(names) or not all(names):
            raise ValueError(f"signals: names must be distinct and non-empty, not {names}")
        object.__setattr__(self, "times_s", times)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "values", values)

    def column(self, name: str) -> np.ndarray:
        """The samples of one signal."""
        try:
            return self.values[:, self.names.index(name)]
        except ValueError:
            raise KeyError(f"no signal {name!r}; there are {', '.join(self.names)}") from None


@dataclass(frozen=True)
class Trial:
    """Outcome of flying one program.

    Attributes
    ----------
    status : how the flight ended (:class:`TrialStatus`).
    message : human-readable explanation.
    final_state : (N_STATE,) estimated state at the maneuver's end (NaN unless ``ok``).
    times_s : (M,) measurement times relative to the maneuver start [s].
    states : (M, N_STATE) measured states at those times (the measurement rate).
    start_state : (N_STATE,) measured state at the maneuver start (for initial-state compensation).
    info : plant-specific extras (attempts, latencies…), JSON-ready.
    signals : what the plant sampled inside itself during the maneuver (:class:`Signals`: a flight
        controller's set point, PID terms and motors), None for a plant that has none.
    """

    status: TrialStatus
    message: str
    final_state: np.ndarray
    times_s: np.ndarray
    states: np.ndarray
    start_state: np.ndarray
    info: dict[str, Any] = field(default_factory=dict)
    signals: Signals | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", TrialStatus(self.status))

    @property
    def ok(self) -> bool:
        """True when the trial measured a final state."""
        return self.status is TrialStatus.OK

    def __repr__(self) -> str:
        return f"Trial(status={self.status.value!r}, message={self.message!r}, samples={len(self.times_s)})"


@runtime_checkable
class Plant(Protocol):
    """Flies programs. ``name`` identifies it in records."""

    name: str

    def fly(self, program: Any) -> Trial: ...


@runtime_checkable
class StatefulPlant(Plant, Protocol):
    """A plant whose hidden state (random generators, drift, battery) can be saved and restored.

    A resumed session restores the state saved after its last trial, so it flies the
    same trials an uninterrupted session would have flown.
    """

    def get_state(self) -> dict[str, Any]: ...

    def set_state(self, state: dict[str, Any]) -> None: ...


@runtime_checkable
class MaybeRepeatablePlant(Plant, Protocol):
    """A plant that says whether its trials repeat bit for bit from the same seed and state.

    A plant without ``repeatable`` repeats exactly (every simulated one). A plant on the wall clock
    (a real flight controller, or the real firmware rehearsed in real time) declares
    ``repeatable = False``: its saved state still resumes its generators and counters, but timing
    decides every trial, so a resumed session is not exact and the conformance kit does not ask
    for a repeat.
    """

    repeatable: bool


@runtime_checkable
class DeterministicPlant(Plant, Protocol):
    """A plant with nothing random and nothing that changes from trial to trial (the nominal model): with
    ``deterministic = True`` a resumed session on it continues exactly without any stored state."""

    deterministic: bool


def is_deterministic(plant: Any) -> bool:
    """True if the plant declares it has no randomness and no state (:class:`DeterministicPlant`)."""
    return isinstance(plant, DeterministicPlant) and bool(plant.deterministic)


def repeats_exactly(plant: Any) -> bool:
    """True unless the plant declares its trials never repeat bit for bit (:class:`MaybeRepeatablePlant`)."""
    return not isinstance(plant, MaybeRepeatablePlant) or bool(plant.repeatable)
