"""RotorPy's entry in the plant registry (``--plant rotorpy``); ``rotorpy`` is imported only by a build."""

from __future__ import annotations

from typing import Any

from aerobat.core.plant import Plant
from aerobat.plants.lab_warm import warm_lab_kernels
from aerobat.plants.rotorpy.settings import (
    RotorPySettings,
    load_rotorpy_settings,
    settings_from_table,
    settings_to_table,
)
from aerobat.plants.spec import Kernels, PlantSpec
from aerobat.quadrotor.feedback import Feedback, FeedbackScheme
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["SPEC"]


def _build(config: VehicleConfig, settings: Any, *, seed: int, feedback: Feedback,
           design_model: VehicleConfig | None) -> Plant:
    from aerobat.plants.rotorpy.plant import RotorPyPlant

    return RotorPyPlant(config, settings=settings, seed=seed, feedback=feedback, design_model=design_model)


SPEC = PlantSpec(
    "rotorpy", "RotorPy's Hummingbird (an independent simulator), supervised like the arena",
    _build, load_settings=load_rotorpy_settings,
    settings_from_table=lambda table, source: settings_from_table(table, source=source),
    settings_to_table=settings_to_table, default_settings=RotorPySettings,
    requires=(("rotorpy", "rotorpy"),), option="--rotorpy", feedback=tuple(FeedbackScheme),
    # measured (docs/results.md, Feedback): with the default rule, tracking is worse than the open
    # loop on RotorPy (last-10 0.051 vs 0.041 m); it wins only with --rule broyden (0.012 m)
    default_feedback=FeedbackScheme.NONE, kernels=(Kernels("plants", warm_lab_kernels),))
