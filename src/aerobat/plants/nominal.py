"""The nominal plant: flies the design model exactly (continuous time, no noise)."""

from __future__ import annotations

import numpy as np

from aerobat.config import check_number, check_type
from aerobat.core.plant import Trial, TrialStatus
from aerobat.plants.spec import PlantSpec
from aerobat.quadrotor.feedback import Feedback, FeedbackScheme
from aerobat.quadrotor.program import Program
from aerobat.quadrotor.simulate import DEFAULT_MAX_STEP_S, check_max_step, simulate
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["SPEC", "NominalPlant"]


class NominalPlant:
    """The paper's model as a plant: ``fly`` returns the simulated final state exactly.

    Like every plant, it reports its trajectory at a measurement rate (``sample_rate_hz``,
    default 200 Hz like the arena's motion capture, start and end included), not at every
    integration step; the final state is the integrator's, unrounded.
    """

    name = "nominal"
    deterministic = True  # nothing random, nothing kept between trials (aerobat.core.plant.DeterministicPlant)

    def __init__(self, config: VehicleConfig, *, max_step_s: float = DEFAULT_MAX_STEP_S,
                 sample_rate_hz: float = 200.0) -> None:
        self.sample_rate_hz = check_number("sample_rate_hz", sample_rate_hz, low=0.0, high=1e6, low_inclusive=False,
                                           unit="Hz")
        self.config = check_type("config", config, VehicleConfig, "a VehicleConfig (e.g. aerobat.hummingbird())")
        self.max_step_s = check_max_step(max_step_s)

    def fly(self, program: Program) -> Trial:
        """Fly ``program`` on the nominal model: a noiseless trial whose final state is the model's."""
        check_type("program", program, Program, "a Program")
        traj = simulate(program, self.config, max_step_s=self.max_step_s)
        final = traj.final_state
        picks = np.unique(np.concatenate([
            np.searchsorted(traj.times_s, np.arange(0.0, traj.times_s[-1], 1.0 / self.sample_rate_hz)),
            [len(traj.times_s) - 1],
        ]))
        times, states = traj.times_s[picks], traj.states[picks]
        if not np.all(np.isfinite(final)):
            return Trial(TrialStatus.ABORTED, "non-finite state in the nominal simulation", np.full_like(final, np.nan),
                         times, states, traj.states[0])
        return Trial(TrialStatus.OK, "nominal model", final.copy(), times, states, traj.states[0].copy())


def _build(config: VehicleConfig, settings: object, *, seed: int, feedback: Feedback,
           design_model: VehicleConfig | None) -> NominalPlant:
    # the reference is its own flight, so every feedback correction is zero; it flies the nominal vehicle it
    # is built around (``config``), noiseless, whatever the seed and whichever model the programs came from
    del settings, seed, feedback, design_model
    return NominalPlant(config)


SPEC = PlantSpec("nominal", "the design model itself: continuous time, no noise", _build,
                 feedback=tuple(FeedbackScheme), in_studies=False)
"""The nominal plant's entry in the plant registry (``--plant nominal``)."""
