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

Each is a :class:`~aerobat.plants.spec.PlantSpec` in :data:`PLANTS`; a package adds its own
through the ``aerobat.plants`` entry-point group.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from aerobat.config import dataclass_from_table, dataclass_to_table
from aerobat.core.plant import Plant, StatefulPlant, Trial, TrialStatus
from aerobat.plants.arena import Arena, ArenaParams, load_arena
from aerobat.plants.nominal import NominalPlant
from aerobat.plants.spec import PLANTS, DesignModel, PlantChoice, PlantSpec
from aerobat.quadrotor.feedback import DEFAULT_SCHEME, FeedbackScheme
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = [
    "PLANTS",
    "Arena",
    "ArenaParams",
    "NominalPlant",
    "Plant",
    "PlantChoice",
    "DesignModel",
    "PlantSpec",
    "StatefulPlant",
    "Trial",
    "TrialStatus",
    "load_arena",
]


def _rotorpy(config: VehicleConfig, settings: Any, seed: int, feedback: Any = None,
            design_model: VehicleConfig | None = None) -> Plant:
    from aerobat.plants.rotorpy import RotorPyPlant

    return RotorPyPlant(config, settings=settings, seed=seed, feedback=feedback, design_model=design_model)


def _rotorpy_load(path: str | Path) -> Any:
    from aerobat.plants.rotorpy import load_rotorpy_settings

    return load_rotorpy_settings(path)


def _rotorpy_from_table(table: Any, source: str) -> Any:
    from aerobat.plants.rotorpy import settings_from_table

    return settings_from_table(table, source=source)


def _rotorpy_to_table(settings: Any) -> dict[str, Any]:
    from aerobat.plants.rotorpy import settings_to_table

    return settings_to_table(settings)


def _rotorpy_default() -> Any:
    from aerobat.plants.rotorpy import RotorPySettings

    return RotorPySettings()


def _betaflight(config: VehicleConfig, settings: Any, seed: int, feedback: Any = None) -> Plant:
    from aerobat.plants.betaflight.plant import BetaflightPlant

    return BetaflightPlant(config, settings, seed=seed, feedback=feedback)


def _betaflight_firmware_model(config: VehicleConfig, settings: Any) -> tuple[Any, dict[str, Any]]:
    from aerobat.plants.betaflight.design_model import firmware_design_model, model_table

    model = firmware_design_model(config, settings)
    return model, model_table(model)


def _fc_firmware_model(config: VehicleConfig, settings: Any) -> tuple[Any, dict[str, Any]]:
    return _betaflight_firmware_model(config, settings.betaflight)


def _betaflight_cores(settings: Any) -> int:
    from aerobat.plants.betaflight.params import instance_cores

    return instance_cores(settings)


def _betaflight_load(path: str | Path) -> Any:
    from aerobat.plants.betaflight.params import load_betaflight

    return load_betaflight(path)


def _betaflight_from_table(table: Any, source: str) -> Any:
    from aerobat.plants.betaflight.params import BetaflightParams

    return dataclass_from_table(BetaflightParams, table, source=source)


def _betaflight_to_table(settings: Any) -> dict[str, Any]:
    from aerobat.plants.betaflight.params import params_to_table

    return params_to_table(settings)


def _betaflight_default() -> Any:
    from aerobat.plants.betaflight.params import BetaflightParams

    return BetaflightParams()


def _fc(config: VehicleConfig, settings: Any, seed: int, feedback: Any = None) -> Plant:
    from aerobat.plants.fc.plant import build_fc_plant

    return build_fc_plant(config, settings, seed=seed, feedback=feedback)


def _fc_load(path: str | Path) -> Any:
    from aerobat.plants.fc.settings import load_fc

    return load_fc(path)


def _fc_from_table(table: Any, source: str) -> Any:
    from aerobat.plants.fc.settings import fc_settings_from_table

    return fc_settings_from_table(table, source)


def _fc_to_table(settings: Any) -> dict[str, Any]:
    from aerobat.plants.fc.settings import fc_settings_to_table

    return fc_settings_to_table(settings)


def _fc_default() -> Any:
    from aerobat.plants.fc.settings import FcSettings

    return FcSettings()


_ALL_SCHEMES = tuple(FeedbackScheme)


def _nominal(config: VehicleConfig, settings: Any, seed: int, feedback: Any = None) -> Plant:
    return NominalPlant(config)  # the reference is its own flight: every correction would be zero


def _arena(config: VehicleConfig, settings: Any, seed: int, feedback: Any = None,
           design_model: VehicleConfig | None = None) -> Plant:
    return Arena(config, settings, seed=seed, feedback=feedback, design_model=design_model)


PLANTS.register("nominal", PlantSpec(
    "nominal", "the design model itself: continuous time, no noise",
    _nominal, feedback=_ALL_SCHEMES))
PLANTS.register("arena", PlantSpec(
    "arena", "a simulated arena: a true vehicle unlike the model, sensors, lossy links, the Fig. 8 supervisor",
    _arena,
    load_settings=load_arena,
    settings_from_table=lambda table, source: dataclass_from_table(ArenaParams, table, source=source),
    settings_to_table=dataclass_to_table, default_settings=ArenaParams, option="--arena",
    feedback=_ALL_SCHEMES, default_feedback=DEFAULT_SCHEME, design_model=True))
PLANTS.register("rotorpy", PlantSpec(
    "rotorpy", "RotorPy's Hummingbird (an independent simulator), supervised like the arena",
    _rotorpy, load_settings=_rotorpy_load, settings_from_table=_rotorpy_from_table,
    settings_to_table=_rotorpy_to_table, default_settings=_rotorpy_default,
    requires=(("rotorpy", "rotorpy"),), option="--rotorpy", feedback=_ALL_SCHEMES,
    # measured (docs/results.md, Feedback): with the default rule, tracking is worse than the open
    # loop on RotorPy (last-10 0.051 vs 0.041 m); it wins only with --rule broyden (0.012 m)
    default_feedback=FeedbackScheme.NONE, design_model=True))
PLANTS.register("betaflight", PlantSpec(
    "betaflight", "a 5-inch racer flown by Betaflight 4.6's own firmware (SITL in lockstep) in the arena",
    _betaflight, load_settings=_betaflight_load, settings_from_table=_betaflight_from_table,
    settings_to_table=_betaflight_to_table, default_settings=_betaflight_default, option="--betaflight",
    feedback=_ALL_SCHEMES, default_feedback=DEFAULT_SCHEME, cores=_betaflight_cores,
    firmware_model=_betaflight_firmware_model))
PLANTS.register("fc", PlantSpec(
    "fc", "a Betaflight flight controller over MSP on the wall clock: a board on a serial port with motion "
          "capture, or the real firmware rehearsed in real time",
    _fc, load_settings=_fc_load, settings_from_table=_fc_from_table, settings_to_table=_fc_to_table,
    default_settings=_fc_default, requires=(("serial", "fc"),), option="--fc", feedback=_ALL_SCHEMES,
    # the paper flies open loop; the pilot-side feedback runs at the radio rate on motion capture
    default_feedback=FeedbackScheme.NONE, firmware_model=_fc_firmware_model))
