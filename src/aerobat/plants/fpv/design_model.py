"""The firmware design model of a Betaflight plant: the firmware it runs, around the vehicle the user believes.

:func:`firmware_config` reads the values the design model needs
(:data:`aerobat.quadrotor.firmware.config.READ`) from the firmware's resolved configuration:
Betaflight 4.6's defaults (the build's own table), aerobat's ``settings.toml`` and, when the
plant flies a pilot's tune, the tune as :func:`aerobat.firmware.betaflight.translate.translate` applies it.
:func:`firmware_design_model` builds the :class:`~aerobat.quadrotor.firmware.FirmwareModel`:

* the firmware as configured;
* the ground station as the plant runs it: the same stick map (rate curves inverted, the pilot's
  collective → throttle) and radio rate;
* the vehicle the user believes: the rigid body of the design vehicle (``--vehicle``: mass and
  inertia), the plant's airframe as written (default or ``--betaflight FILE``: rotor layout,
  thrust curve, motor lag, rotor inertia, output delay) with no centre-of-mass offset and equal
  motors — what nobody knows before flying —, and its drag: the design vehicle's identified
  terms if it has them, else the airframe's ``[aerodynamics]`` (the published 5-inch racer's).

The world the plant flies is not touched: its airframe keeps its offset and uneven motors, its
aerodynamics, sensors, wind and radio.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from aerobat.config import dataclass_to_table
from aerobat.firmware.betaflight.settings import BetaflightSettings, load_settings
from aerobat.plants.fpv.params import BetaflightParams
from aerobat.plants.fpv.pilot import StickMap
from aerobat.quadrotor.firmware import Fidelity, FirmwareConfig, FirmwareModel
from aerobat.quadrotor.firmware.config import ASSUMED, READ
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["firmware_config", "firmware_design_model", "firmware_model", "model_table", "plant_settings"]


def plant_settings(params: BetaflightParams) -> BetaflightSettings:
    """The firmware settings the plant runs: ``settings.toml``, the tune on top when there is one, and the mixer's
    yaw the way the airframe's propellers turn."""
    settings = load_settings()
    if params.tune is not None:
        from aerobat.firmware.betaflight.translate import translate

        settings = settings.with_tune(translate(params.tune))
    return settings.with_props(params.airframe.props_out)


def firmware_config(settings: BetaflightSettings, *, gyro_rate_hz: int) -> FirmwareConfig:
    """The values of :data:`~aerobat.quadrotor.firmware.config.READ` as the firmware runs them."""
    values = {name: settings.resolved(name) for name in (*READ, *ASSUMED)}
    airmode = any(c.strip().upper() == "FEATURE AIRMODE" for c in settings.commands)
    source = f"Betaflight 4.6.0, aerobat settings revision {settings.revision}"
    if settings.tune is not None:
        source += f", tune {settings.tune.tune.source}"
    return FirmwareConfig.from_mapping(values, airmode=airmode, gyro_rate_hz=gyro_rate_hz, source=source)


def firmware_design_model(config: VehicleConfig, params: BetaflightParams, *,
                          settings: BetaflightSettings | None = None,
                          fidelity: Fidelity | str = Fidelity.DESIGN) -> FirmwareModel:
    """The design model for a Betaflight plant with ``params``, designing for the vehicle ``config``."""
    settings = settings if settings is not None else plant_settings(params)
    vehicle = config.vehicle
    airframe = dataclasses.replace(
        params.airframe, mass_kg=vehicle.mass_kg,
        inertia_kg_m2=(vehicle.inertia_xx_kg_m2, vehicle.inertia_yy_kg_m2, vehicle.inertia_zz_kg_m2),
        com_offset_m=(0.0, 0.0, 0.0), thrust_gains=(1.0, 1.0, 1.0, 1.0))
    pilot = params.pilot
    sticks = StickMap.from_settings(settings, params.airframe, pilot.vehicle_mass_kg).limits(
        max_tilt_rad=math.radians(pilot.max_tilt_deg), max_climb_m_s=pilot.max_climb_m_s,
        gravity_m_s2=vehicle.gravity_m_s2)
    drag = _drag(config, params)
    firmware = firmware_config(settings, gyro_rate_hz=params.firmware.gyro_rate_hz)
    return FirmwareModel(firmware, airframe, sticks, radio_rate_hz=params.radio.rate_hz,
                         gravity_m_s2=vehicle.gravity_m_s2, aerodynamics=drag, fidelity=fidelity,
                         description=f"{firmware.source}; airframe {airframe.mass_kg:g} kg "
                                     f"(motors ±{airframe.motor_x_m:g}/±{airframe.motor_y_m:g} m)")


def _drag(config: VehicleConfig, params: BetaflightParams) -> dict[str, object]:
    """The drag the user believes: the design vehicle's identified terms, else the airframe's ``[aerodynamics]``."""
    effects = config.effects
    identified = (effects.body_drag_n_s2_m2, effects.rotor_drag_s_m, effects.rotor_drag_axial_s_m)
    if any(identified):
        return {"body_drag_n_s2_m2": effects.body_drag_n_s2_m2, "rotor_drag_s_m": effects.rotor_drag_s_m,
                "rotor_drag_axial_s_m": effects.rotor_drag_axial_s_m}
    aero = params.aerodynamics
    if not aero.enabled:
        return {}
    return {"body_drag_n_s2_m2": aero.body_drag_n_s2_m2, "rotor_drag_s_m": aero.rotor_drag_s_m,
            "rotational_damping_n_m_s": aero.rotational_damping_n_m_s}


def model_table(model: FirmwareModel) -> dict[str, Any]:
    """The model's stored form: what it is built from (firmware values, airframe, radio, drag, fidelity)."""
    airframe = dataclass_to_table(model.airframe)
    if not model.airframe.props_out:  # props in: the stored form before props_out existed
        airframe.pop("props_out", None)
    for name in ("battery_reference_v", "battery_rest_v"):  # TOML has no null
        if getattr(model.airframe, name) is None:
            airframe.pop(name, None)
    if model.airframe.battery_sag_v == 0.0:  # no sag: the stored form before the battery model
        airframe.pop("battery_sag_v", None)
    return {"kind": "firmware", "description": model.description, "fidelity": model.fidelity.value,
            "firmware": model.firmware.to_table(), "airframe": airframe,
            "radio_rate_hz": 1.0 / model.radio_period_s,
            "aerodynamics": {k: list(v) if isinstance(v, tuple) else v for k, v in model.aerodynamics.items()}}


def firmware_model(config: VehicleConfig, settings: BetaflightParams) -> tuple[FirmwareModel, dict[str, Any]]:
    """The design model with the flight controller ``settings`` (a plant's params) give, around ``config``,
    and the model's stored form (both Betaflight plants' :attr:`~aerobat.plants.PlantSpec.firmware_model`)."""
    model = firmware_design_model(config, settings)
    return model, model_table(model)
