"""The nominal plant: flies the design model exactly (continuous time, no noise)."""

from __future__ import annotations

import numpy as np

from ..program import Program
from ..simulate import DEFAULT_MAX_STEP_S, simulate
from ..vehicle import VehicleConfig
from .base import Trial

__all__ = ["NominalPlant"]


class NominalPlant:
    """The paper's model as a plant: ``fly`` returns the simulated final state exactly."""

    name = "nominal"

    def __init__(self, config: VehicleConfig, *, max_step_s: float = DEFAULT_MAX_STEP_S) -> None:
        self.config = config
        self.max_step_s = max_step_s

    def fly(self, program: Program) -> Trial:
        traj = simulate(program, self.config, max_step_s=self.max_step_s)
        final = traj.final_state
        if not np.all(np.isfinite(final)):
            return Trial("aborted", "non-finite state in the nominal simulation", np.full_like(final, np.nan),
                         traj.times_s, traj.states, traj.states[0])
        return Trial("ok", "nominal model", final.copy(), traj.times_s, traj.states, traj.states[0].copy())
