"""Initial-state compensation (Sect. 11): learn from the error the start-state scatter does not explain."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from aerobat.core.plant import Trial
from aerobat.core.rules.base import UpdateRule
from aerobat.core.rules.scaled import json_array, json_floats, required_array
from aerobat.errors import ConfigError

__all__ = ["DeviationFn", "InitialStateCompensation"]

DeviationFn = Callable[[Trial, np.ndarray], np.ndarray]
"""``deviation(trial, params) -> (n_dev,)``: the measured start-state deviation of one trial."""


class InitialStateCompensation:
    """Removes the part of each error explained by the measured start-state deviation (item 4).

    e_c = e − gain·S·(δ − δ̄), where S (n_err × n_dev) is the model's sensitivity of the
    final error to the initial state, δ = ``deviation(trial, params)`` the measured
    deviation of this trial's start from the maneuver's nominal initial state and δ̄
    the mean of all deviations seen so far (``center=True``, the default). The inner
    rule learns from e_c, so trial-to-trial start-state scatter stops driving
    corrections. A non-finite δ leaves the error as it is.

    Rules with a history (:class:`KalmanRule`) take the uncentred term S·δ per trial
    through ``propose_compensated`` and re-centre their whole history on the latest
    mean; for the others the wrapper centres each trial on the running mean.

    Why centred: learning must still zero the *raw* mean error, flown from the start
    states the plant actually delivers. Any constant part of δ — a biased deviation
    estimate, or a hover controller that settles consistently off the nominal start —
    is part of the offset d that learning should absorb; subtracting S·δ itself would
    instead drive the raw error to −S·mean(δ). (Measured on the arena: uncentred, the
    raw last-10 error of the paper's rule went from 0.07 m to 0.12 m.)
    """

    def __init__(self, inner: UpdateRule, sensitivity: np.ndarray, deviation: DeviationFn, *,
                 gain: float | np.ndarray = 1.0, center: bool = True, name: str | None = None) -> None:
        self.inner = inner
        self.S = np.asarray(sensitivity, dtype=float)
        self.deviation = deviation
        self.gain = np.asarray(gain, dtype=float)
        self.center = bool(center)
        self.name = name or f"{getattr(inner, 'name', 'rule')}+isc"
        self.deviation_sum = np.zeros(self.S.shape[1])
        self.deviation_count = 0
        self.last_deviation: np.ndarray | None = None
        self.last_compensation: np.ndarray | None = None
        self._last_error: np.ndarray | None = None

    def compensate(self, params: np.ndarray, error: np.ndarray, trial: Trial) -> np.ndarray:
        """The compensated error e_c for one trial (and the running mean of δ updated)."""
        delta = np.asarray(self.deviation(trial, np.asarray(params, dtype=float)), dtype=float)
        self.last_deviation = delta
        if delta.shape != (self.S.shape[1],) or not np.all(np.isfinite(delta)):
            self.last_compensation = np.zeros(self.S.shape[0])
            return np.asarray(error, dtype=float)
        self.deviation_sum += delta
        self.deviation_count += 1
        if self.center:
            delta = delta - self.deviation_sum / self.deviation_count
        comp = self.S @ (self.gain * delta)
        self.last_compensation = comp
        return np.asarray(error, dtype=float) - comp

    def propose(self, i: int, params: np.ndarray, error: np.ndarray, trial: Trial | None) -> tuple[np.ndarray, float]:
        if trial is None:
            raise ConfigError(f"{self.name}: initial-state compensation needs each trial's measured start")
        native = getattr(self.inner, "propose_compensated", None)
        if native is not None and self.center:
            # the inner rule keeps its history and re-centres all of it on the latest mean
            delta = np.array(self.deviation(trial, np.asarray(params, dtype=float)), dtype=np.float64)
            self.last_deviation = delta
            ok = delta.shape == (self.S.shape[1],) and bool(np.all(np.isfinite(delta)))
            comp = self.S @ (self.gain * delta) if ok else None
            if ok:
                self.deviation_sum += delta
                self.deviation_count += 1
            self.last_compensation = comp
            self._last_error = np.asarray(error, dtype=float) if comp is None else np.asarray(error) - comp
            return native(i, params, error, trial, comp)
        compensated = self.compensate(params, error, trial)
        self._last_error = compensated
        return self.inner.propose(i, params, compensated, trial)

    def observe(self, params: np.ndarray, error: np.ndarray, step: np.ndarray) -> None:
        self.inner.observe(params, self._last_error if self._last_error is not None else error, step)

    def state(self) -> dict[str, Any]:
        return {"rule": self.name, "inner": self.inner.state(), "deviation_sum": json_floats(self.deviation_sum),
                "deviation_count": self.deviation_count, "last_deviation": json_floats(self.last_deviation),
                "last_compensation": json_floats(self.last_compensation)}

    def load_state(self, state: dict[str, Any]) -> None:
        loader = getattr(self.inner, "load_state", None)
        if loader is not None:
            loader(state.get("inner", {}))
        if "deviation_sum" in state:
            self.deviation_sum = required_array(state["deviation_sum"], (self.S.shape[1],))
            self.deviation_count = int(state.get("deviation_count", 0))
        self.last_deviation = json_array(state.get("last_deviation"))
        self.last_compensation = json_array(state.get("last_compensation"))
