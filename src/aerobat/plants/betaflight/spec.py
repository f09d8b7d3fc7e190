"""The Betaflight plant's entry in the plant registry (``--plant betaflight``).

Light at import: the plant, its settings and the firmware design model are imported by the functions
that need them, so that listing plants starts no firmware and compiles nothing.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from aerobat.core.plant import Plant
from aerobat.plants.betaflight.sampling import SAMPLING
from aerobat.plants.betaflight.warm import warm_design_model, warm_world
from aerobat.plants.lab_warm import warm_lab_kernels
from aerobat.plants.spec import Kernels, PlantSpec
from aerobat.quadrotor.feedback import DEFAULT_SCHEME, Feedback, FeedbackScheme
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["SPEC"]


def _build(config: VehicleConfig, settings: Any, *, seed: int, feedback: Feedback,
           design_model: VehicleConfig | None) -> Plant:
    from aerobat.plants.betaflight.plant import BetaflightPlant

    return BetaflightPlant(config, settings, seed=seed, feedback=feedback, design_model=design_model)


def _firmware_model(config: VehicleConfig, settings: Any) -> tuple[Any, dict[str, Any]]:
    from aerobat.plants.fpv.design_model import firmware_model

    return firmware_model(config, settings)


def _with_tune(settings: Any, tune: Any) -> Any:
    """The plant's settings with a real quad's tune, flown by the SITL (``--tune FILE``)."""
    import dataclasses

    return dataclasses.replace(settings, tune=tune)


def _replayer(settings: Any, *, tune: Any, props_out: bool, seed: int = 0) -> Any:
    from aerobat.plants.betaflight.replay import LogReplayer

    return LogReplayer(settings, tune=tune, props_out=props_out, seed=seed)


def _cores(settings: Any) -> int:
    from aerobat.plants.fpv.params import instance_cores

    return instance_cores(settings)


def _load(path: str | Path) -> Any:
    from aerobat.plants.fpv.params import load_betaflight

    return load_betaflight(path)


def _from_table(table: Any, source: str) -> Any:
    from aerobat.config import dataclass_from_table
    from aerobat.plants.fpv.params import BetaflightParams

    return dataclass_from_table(BetaflightParams, table, source=source)


def _to_table(settings: Any) -> dict[str, Any]:
    from aerobat.plants.fpv.params import params_to_table

    return params_to_table(settings)


def _default() -> Any:
    from aerobat.plants.fpv.params import BetaflightParams

    return BetaflightParams()


SPEC = PlantSpec(
    "betaflight", "a 5-inch racer flown by Betaflight 4.6's own firmware (SITL in lockstep) in the arena",
    _build, load_settings=_load, settings_from_table=_from_table, settings_to_table=_to_table,
    default_settings=_default, option="--betaflight", feedback=tuple(FeedbackScheme),
    default_feedback=DEFAULT_SCHEME, cores=_cores, firmware_model=_firmware_model, robustness=SAMPLING,
    kernels=(Kernels("plants", warm_lab_kernels), Kernels("plants", warm_world),
             Kernels("firmware", warm_design_model)),
    replay=_replayer, tune=_with_tune)
