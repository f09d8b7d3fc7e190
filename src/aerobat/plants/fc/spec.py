"""The flight controller's entry in the plant registry (``--plant fc``); pyserial is imported by a build."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from aerobat.core.plant import Plant
from aerobat.plants.fpv.warm import warm_sticks
from aerobat.plants.lab_warm import warm_lab_kernels
from aerobat.plants.spec import Kernels, PlantSpec
from aerobat.quadrotor.feedback import Feedback, FeedbackScheme
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["SPEC"]


def _build(config: VehicleConfig, settings: Any, *, seed: int, feedback: Feedback,
           design_model: VehicleConfig | None) -> Plant:
    from aerobat.plants.fc.plant import build_fc_plant

    return build_fc_plant(config, settings, seed=seed, feedback=feedback, design_model=design_model)


def _firmware_model(config: VehicleConfig, settings: Any) -> tuple[Any, dict[str, Any]]:
    from aerobat.plants.fpv.design_model import firmware_model

    return firmware_model(config, settings.betaflight)


def _load(path: str | Path) -> Any:
    from aerobat.plants.fc.settings import load_fc

    return load_fc(path)


def _from_table(table: Any, source: str) -> Any:
    from aerobat.plants.fc.settings import fc_settings_from_table

    return fc_settings_from_table(table, source)


def _to_table(settings: Any) -> dict[str, Any]:
    from aerobat.plants.fc.settings import fc_settings_to_table

    return fc_settings_to_table(settings)


def _default() -> Any:
    from aerobat.plants.fc.settings import FcSettings

    return FcSettings()


SPEC = PlantSpec(
    "fc", "a Betaflight flight controller over MSP on the wall clock: a board on a serial port with motion "
          "capture, or the real firmware rehearsed in real time",
    _build, load_settings=_load, settings_from_table=_from_table, settings_to_table=_to_table,
    default_settings=_default, requires=(("serial", "fc"),), option="--fc", feedback=tuple(FeedbackScheme),
    # the paper flies open loop; the pilot-side feedback runs at the radio rate on motion capture
    default_feedback=FeedbackScheme.NONE, firmware_model=_firmware_model, in_studies=False,
    # the supervisor and the pilot's sticks fly the board; a rehearsal's world is the lockstep plant's,
    # whose kernels that plant's own spec compiles (setup compiles every registered plant's)
    kernels=(Kernels("plants", warm_lab_kernels), Kernels("plants", warm_sticks)))
