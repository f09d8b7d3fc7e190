"""Plants: things that fly programs and report trials (the learning loop sees only this).

====================  ===============================================================
``nominal``           the design model itself (:class:`NominalPlant`)
``arena``             a simulated flying-machine arena whose vehicle is not the model
                      (:class:`~aerobat.plants.arena.Arena`, settings ``--arena FILE``)
``rotorpy``           RotorPy's Hummingbird, supervised like the arena
                      (:class:`~aerobat.plants.rotorpy.RotorPyPlant`, ``--rotorpy FILE``)
``betaflight``        a 5-inch racer flown by Betaflight 4.6 (SITL in lockstep) in the arena
                      (:class:`~aerobat.plants.betaflight.plant.BetaflightPlant`, ``--betaflight FILE``)
``fc``                a Betaflight flight controller over MSP on the wall clock: a board on a
                      serial port, or the real firmware rehearsed in real time
                      (:class:`~aerobat.plants.fc.plant.FlightControllerPlant`, ``--fc FILE``)
====================  ===============================================================

Each plant's package exports its own :class:`~aerobat.plants.spec.PlantSpec` as ``SPEC``; the
registry :data:`PLANTS` is the list :data:`BUILT_IN` below (a new built-in plant is one line there),
and a package outside aerobat adds its own through the ``aerobat.plants`` entry-point group.
"""

from __future__ import annotations

import importlib

from aerobat.core.plant import Plant, StatefulPlant, Trial, TrialStatus
from aerobat.plants.arena import Arena, ArenaParams, load_arena
from aerobat.plants.nominal import NominalPlant
from aerobat.plants.spec import PLANTS, DesignModel, PlantChoice, PlantFactory, PlantSpec

__all__ = [
    "BUILT_IN",
    "PLANTS",
    "Arena",
    "ArenaParams",
    "DesignModel",
    "NominalPlant",
    "Plant",
    "PlantChoice",
    "PlantFactory",
    "PlantSpec",
    "StatefulPlant",
    "Trial",
    "TrialStatus",
    "load_arena",
    "replaying_plants",
    "sampled_plants",
    "studied_plants",
    "tuned_plants",
]

BUILT_IN = (
    "aerobat.plants.nominal",
    "aerobat.plants.arena",
    "aerobat.plants.rotorpy",
    "aerobat.plants.betaflight",
    "aerobat.plants.fc",
)
"""The built-in plants' modules, in listing order; each exports its ``SPEC``."""

for _module in BUILT_IN:
    _spec: PlantSpec = importlib.import_module(_module).SPEC
    PLANTS.register(_spec.name, _spec)


def sampled_plants() -> tuple[str, ...]:
    """The registered plants a robustness study can sample: their spec says how (``PlantSpec.robustness``)."""
    return tuple(name for name, spec in PLANTS.items() if spec.robustness is not None)


def tuned_plants() -> tuple[str, ...]:
    """The registered plants that fly a real quad's firmware tune (``PlantSpec.tune``, ``--tune FILE``)."""
    return tuple(name for name, spec in PLANTS.items() if spec.tune is not None)


def studied_plants() -> tuple[str, ...]:
    """The registered plants the comparative studies (rules, feedback) offer (``PlantSpec.in_studies``)."""
    return tuple(name for name, spec in PLANTS.items() if spec.in_studies)


def replaying_plants() -> tuple[str, ...]:
    """The registered plants that replay a blackbox log through their firmware (``PlantSpec.replay``)."""
    return tuple(name for name, spec in PLANTS.items() if spec.replay is not None)
