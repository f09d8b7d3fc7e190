"""aerobat: design and learn fast open-loop quadrocopter maneuvers.

Implements and extends Lupashin & D'Andrea, *Adaptive fast open-loop maneuvers
for quadrocopters*, Autonomous Robots 2012. The stage entry points are here::

    from aerobat import hummingbird, MultiFlip, NominalModel, design, learn, Arena

    config = hummingbird()
    flip = MultiFlip(vehicle=config.vehicle, flips=3, dims=3)
    nominal = design(flip, NominalModel(config))
    session = learn(flip, nominal, Arena(config, seed=1), iterations=30)

The layers, from the bottom: :mod:`aerobat.core` (the method, no vehicle),
:mod:`aerobat.quadrotor` (the vehicle), :mod:`aerobat.plants` (testbeds),
:mod:`aerobat.store` (the experiment store), :mod:`aerobat.experiments` (durable
sessions and studies), :mod:`aerobat.cli` (the command). Names are imported
lazily, on first use, so ``import aerobat`` is instant and loads no compiler.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.3.0"

_HOME = {
    # the method
    "design": "aerobat.core.design", "Design": "aerobat.core.design", "DesignStatus": "aerobat.core.design",
    "learn": "aerobat.core.learning", "Learner": "aerobat.core.learning", "Session": "aerobat.core.learning",
    "Iteration": "aerobat.core.learning", "SessionStatus": "aerobat.core.learning",
    "Trial": "aerobat.core.plant", "TrialStatus": "aerobat.core.plant",
    "RuleChoice": "aerobat.core.rules", "make_rule": "aerobat.core.rules", "from_spec": "aerobat.core.registry",
    # the vehicle
    "ControllerParams": "aerobat.quadrotor.vehicle", "VehicleConfig": "aerobat.quadrotor.vehicle",
    "VehicleParams": "aerobat.quadrotor.vehicle", "hummingbird": "aerobat.quadrotor.vehicle",
    "load_vehicle": "aerobat.quadrotor.vehicle", "save_vehicle": "aerobat.quadrotor.vehicle",
    "ModelEffects": "aerobat.quadrotor.vehicle", "preset": "aerobat.quadrotor.vehicle",
    "vehicle_from_name_or_file": "aerobat.quadrotor.vehicle",
    "fit_vehicle": "aerobat.quadrotor.identification", "identification_sequence": "aerobat.quadrotor.identification",
    "Program": "aerobat.quadrotor.program", "RampDown": "aerobat.quadrotor.program",
    "Switch": "aerobat.quadrotor.program", "load_program": "aerobat.quadrotor.program",
    "save_program": "aerobat.quadrotor.program",
    "Trajectory": "aerobat.quadrotor.simulate", "simulate": "aerobat.quadrotor.simulate",
    "simulate_batch": "aerobat.quadrotor.simulate", "NominalModel": "aerobat.quadrotor.simulate",
    "MultiFlip": "aerobat.quadrotor.maneuvers", "Translation": "aerobat.quadrotor.maneuvers",
    "translation_maneuver": "aerobat.quadrotor.maneuvers", "load_maneuver": "aerobat.quadrotor.maneuvers",
    "solve_translation": "aerobat.quadrotor.timeoptimal",
    # plants
    "Arena": "aerobat.plants", "ArenaParams": "aerobat.plants", "NominalPlant": "aerobat.plants",
    "PlantChoice": "aerobat.plants", "DesignModel": "aerobat.plants",
    # the store and the application
    "Store": "aerobat.store", "start_session": "aerobat.experiments", "resume_session": "aerobat.experiments",
    "run_study": "aerobat.experiments", "nominal_design": "aerobat.experiments.designing",
    "identify": "aerobat.experiments.identify",
    "write_identified_vehicle": "aerobat.experiments.identify",
}

__all__ = sorted(_HOME)


def __getattr__(name: str) -> Any:
    module = _HOME.get(name)
    if module is None:
        raise AttributeError(f"module 'aerobat' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*__all__, "__version__"])
