"""The arena's entry in the plant registry (``--plant arena``)."""

from __future__ import annotations

from typing import Any

from aerobat.config import dataclass_from_table, dataclass_to_table
from aerobat.core.plant import Plant
from aerobat.plants.arena.arena import Arena
from aerobat.plants.arena.params import ArenaParams, load_arena
from aerobat.plants.arena.sampling import SAMPLING, SCENARIOS
from aerobat.plants.arena.warm import warm_arena
from aerobat.plants.spec import Kernels, PlantSpec
from aerobat.quadrotor.feedback import DEFAULT_SCHEME, Feedback, FeedbackScheme
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["SPEC"]


def _build(config: VehicleConfig, settings: Any, *, seed: int, feedback: Feedback,
           design_model: VehicleConfig | None) -> Plant:
    return Arena(config, settings, seed=seed, feedback=feedback, design_model=design_model)


SPEC = PlantSpec(
    "arena", "a simulated arena: a true vehicle unlike the model, sensors, lossy links, the Fig. 8 supervisor",
    _build,
    load_settings=load_arena,
    settings_from_table=lambda table, source: dataclass_from_table(ArenaParams, table, source=source),
    settings_to_table=dataclass_to_table, default_settings=ArenaParams, option="--arena",
    feedback=tuple(FeedbackScheme), default_feedback=DEFAULT_SCHEME, robustness=SAMPLING, scenarios=SCENARIOS,
    kernels=(Kernels("arena", warm_arena),))
