"""The update-rule protocol, step-size schedules, and the paper's rule (eq 4).

An update rule turns one measured trial into a parameter change. It is stateful
(noise estimates, histories, refined Jacobians), and its whole state is a
JSON-ready table: ``state()`` after a trial, ``load_state(table)`` into a fresh
rule of the same kind continues exactly where it left off. That is how a stored
session resumes, bit for bit, without replaying its history.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from aerobat.core.plant import Trial

__all__ = ["ConstantSchedule", "PaperRule", "PaperSchedule", "Schedule", "UpdateRule"]


@runtime_checkable
class Schedule(Protocol):
    """A step size for each correction."""

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


@runtime_checkable
class UpdateRule(Protocol):
    """Proposes a parameter change from one trial's outcome; its state saves and loads exactly."""

    name: str

    def propose(self, i: int, params: np.ndarray, error: np.ndarray, trial: Trial | None) -> tuple[np.ndarray, float]:
        """(Δp before constraint scaling, γ used) for correction number ``i`` (from 1)."""
        ...

    def observe(self, params: np.ndarray, error: np.ndarray, step: np.ndarray) -> None:
        """Told the step that was actually applied (after holding and constraint scaling)."""
        ...

    def state(self) -> dict[str, Any]:
        """JSON-ready internal state after the last trial."""
        ...

    def load_state(self, state: dict[str, Any]) -> None:
        """Continue from a state that :meth:`state` returned (on a rule built the same way)."""
        ...


@dataclass
class PaperRule:
    """The paper's rule: Δp = −γ_i·C·e (eq 4), stateless."""

    correction: np.ndarray
    schedule: Schedule = field(default_factory=PaperSchedule)
    name: str = "paper"

    def propose(self, i: int, params: np.ndarray, error: np.ndarray, trial: Trial | None) -> tuple[np.ndarray, float]:
        gamma = self.schedule.gamma(i)
        return -gamma * (self.correction @ error), gamma

    def observe(self, params: np.ndarray, error: np.ndarray, step: np.ndarray) -> None:
        return None

    def state(self) -> dict[str, Any]:
        return {"rule": self.name}

    def load_state(self, state: dict[str, Any]) -> None:
        return None
