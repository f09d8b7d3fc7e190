"""What learning records: one trial's :class:`Iteration`, and how trials and sessions end.

The records are the learning core's values that the store keeps and hands back, so they
live apart from the method itself (:mod:`aerobat.core.learning`), which imports them.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from aerobat.core.codec import Form, decode, decode_value, encode
from aerobat.core.notes import IterationNote
from aerobat.core.plant import Trial, TrialStatus

__all__ = ["Iteration", "IterationStatus", "SessionStatus", "iteration_json", "session_document", "step_to"]


class IterationStatus(StrEnum):
    """What learning did with one trial."""

    OK = "ok"
    REJECTED = "rejected"
    NO_TRIGGER = "no_trigger"
    LOST = "lost"
    CRASHED = "crashed"
    ABORTED = "aborted"

    @property
    def meaning(self) -> str:
        """One sentence on what this outcome means."""
        if self is IterationStatus.OK:
            return "measured and learned from"
        if self is IterationStatus.REJECTED:
            return "measured, but the measurement was absurd (non-finite or far beyond the error scales): not used"
        return TrialStatus(self.value).meaning

    @property
    def measured(self) -> bool:
        """A final state was measured and learned from."""
        return self is IterationStatus.OK

    @property
    def retry(self) -> bool:
        """The trial was lost (no trigger, no contact) and its parameters flown again (:attr:`TrialStatus.retry`)."""
        return self is not IterationStatus.REJECTED and TrialStatus(self.value).retry

    @classmethod
    def of_trial(cls, status: TrialStatus) -> IterationStatus:
        return cls(TrialStatus(status).value)


class SessionStatus(StrEnum):
    """How a learning session stands or ended."""

    RUNNING = "running"
    COMPLETED = "completed"
    INTERRUPTED = "interrupted"
    CRASHED = "crashed"
    ABORTED = "aborted"
    FAILED = "failed"

    @property
    def meaning(self) -> str:
        """One sentence on what this status means for the session."""
        return {
            SessionStatus.RUNNING: "learning (or its process was killed: the store shows that as 'killed')",
            SessionStatus.COMPLETED: "every requested measured iteration is done",
            SessionStatus.INTERRUPTED: "stopped on request after the trial in flight; resumable",
            SessionStatus.CRASHED: "a trial crashed the vehicle; resumable once the cause is fixed",
            SessionStatus.ABORTED: "a trial was aborted; resumable once the cause is fixed",
            SessionStatus.FAILED: "gave up (too many lost trials, or an error while recording); resumable",
        }[self]


@dataclass(frozen=True)
class Iteration:
    """One trial and what learning did with it.

    Attributes
    ----------
    index : 1-based record number (every trial, including lost ones).
    correction : 1-based number of the correction this trial drove (0 if none).
    status : :class:`IterationStatus`.
    params : (n_par,) parameters flown.
    error : (n_err,) measured error (NaN if none).
    gamma : step size used (0 if no correction).
    scale : constraint scaling applied to the correction (1 = none, Sect. 4.2).
    step : (n_par,) the step actually applied after this trial (held parameters and
        constraint scaling included; zeros if no correction).
    message : the plant's or learner's explanation, its notes included (in words).
    trial : the trial itself (measured trajectory and final state).
    notes : what learning noted about the correction (:class:`~aerobat.core.notes.IterationNote`:
        parameters held or pinned at a bound).
    """

    index: int
    correction: int
    status: IterationStatus
    params: np.ndarray
    error: np.ndarray
    gamma: float
    scale: float
    step: np.ndarray
    message: str
    trial: Trial | None = None
    notes: tuple[IterationNote, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", IterationStatus(self.status))
        object.__setattr__(self, "notes", tuple(self.notes))

    @property
    def warnings(self) -> tuple[str, ...]:
        """The notes that are warnings, in words."""
        return tuple(note.text for note in self.notes if note.kind.warning)

    @property
    def next_params(self) -> np.ndarray:
        """(n_par,) the parameters after this iteration's correction."""
        return self.params + self.step

    @property
    def measured(self) -> bool:
        """True when the trial of this iteration measured a final state (it was not lost)."""
        return self.status is IterationStatus.OK

    def __repr__(self) -> str:
        return f"Iteration({self.index}, {self.status.value!r}, correction={self.correction}, gamma={self.gamma:.3g})"

    def to_json_dict(self) -> dict[str, Any]:
        """The iteration as plain JSON types (arrays as lists; the core's codec), as ``session.json`` keeps it."""
        return iteration_json(self)

    @classmethod
    def from_json_dict(cls, table: dict[str, Any]) -> Iteration:
        """The iteration :meth:`to_json_dict` wrote (without its trial), ``next_params`` exactly as written.

        A table without ``notes`` (written before iterations carried them) gives none.
        """
        params = decode_value(np.ndarray, table["params"], Form.JSON)
        step = step_to(params, decode_value(np.ndarray, table["next_params"], Form.JSON))
        return decode(cls, table, form=Form.JSON, keys=_JSON_KEYS, params=params,  # type: ignore[no-any-return]
                      step=step)


_JSON_FIELDS = ("index", "correction", "status", "params", "next_params", "error", "gamma", "scale", "message",
                "notes")
"""What ``session.json`` keeps of an iteration (``next_params`` for the step: exact, and what a reader wants)."""
_JSON_KEYS = {"index": "i"}
"""Fields kept under another key."""


def iteration_json(record: Any) -> dict[str, Any]:
    """An iteration as ``session.json`` keeps it: an :class:`Iteration`, or a stored record of one (a frozen
    dataclass with the same fields, :class:`aerobat.store.records.IterationRecord`), through the codec."""
    return encode(record, _JSON_FIELDS, form=Form.JSON, keys=_JSON_KEYS)


def session_document(*, maneuver: dict[str, Any], plant: str, error_names: list[str], error_units: list[str],
                     parameter_names: list[str], parameter_units: list[str], p_nominal: list[float],
                     iterations: list[dict[str, Any]], final_params: list[float], status: str, message: str,
                     **more: Any) -> dict[str, Any]:
    """The one shape of a session as JSON, whether it comes from memory
    (:meth:`aerobat.core.learning.Session.to_json_dict`) or from the store
    (:func:`aerobat.experiments.reports.session_json`): the keys both have, then ``more`` (what the
    source knows besides). ``iterations`` are :func:`iteration_json` tables."""
    return {"maneuver": maneuver, "plant": plant, "error_names": error_names, "error_units": error_units,
            "parameter_names": parameter_names, "parameter_units": parameter_units, "p_nominal": p_nominal,
            "iterations": iterations, "final_params": final_params, "status": status, "message": message, **more}


def step_to(params: np.ndarray, target: np.ndarray) -> np.ndarray:
    """A step ``s`` with ``params + s == target`` bit for bit (``target - params``, nudged where that rounds off)."""
    step = np.asarray(target, dtype=float) - params
    for _ in range(4):
        off = params + step != target
        if not off.any():
            break
        step = np.where(off, np.nextafter(step, np.where(params + step < target, np.inf, -np.inf)), step)
    return step
