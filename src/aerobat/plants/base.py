"""The plant protocol: anything that can fly a program and report what happened.

The learning loop only ever sees this: a program goes in, a :class:`Trial` comes
out. Plants are the nominal model, the simulated arena, RotorPy, or hardware.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np

__all__ = ["Plant", "Trial", "TrialStatus"]

TrialStatus = Literal["ok", "no_trigger", "crashed", "aborted"]


@dataclass(frozen=True)
class Trial:
    """Outcome of flying one program.

    Attributes
    ----------
    status : ``ok`` (final state measured), ``no_trigger`` (maneuver never started;
        no error available), ``crashed`` (left the volume), ``aborted`` (anything else:
        upload failure, non-finite states…).
    message : human-readable explanation.
    final_state : (N_STATE,) estimated state at the maneuver's end (NaN unless ``ok``).
    times_s : (M,) measurement times relative to the maneuver start [s].
    states : (M, N_STATE) measured states at those times (the measurement rate).
    start_state : (N_STATE,) measured state at the maneuver start (for initial-state compensation).
    info : plant-specific extras (attempts, latencies…), JSON-ready.
    """

    status: TrialStatus
    message: str
    final_state: np.ndarray
    times_s: np.ndarray
    states: np.ndarray
    start_state: np.ndarray
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "ok"


@runtime_checkable
class Plant(Protocol):
    """Flies programs. ``name`` identifies it in records."""

    name: str

    def fly(self, program: Any) -> Trial: ...
