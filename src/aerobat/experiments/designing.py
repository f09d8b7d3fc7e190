"""The nominal design on the model a plant calls for: the paper's, or the flight controller that flies it.

:func:`nominal_design` is what ``design``, ``learn``, ``fly``, ``study`` and ``identify`` call. On a
plant with a firmware (``betaflight``, ``fc``) it designs, by default, on the firmware design model
(:class:`aerobat.quadrotor.firmware.FirmwareModel`): first on the paper's model (milliseconds), then
on the firmware model from the paper's p⁰ (the firmware model's guess would start far away: the
paper's rate loop and motors are not the firmware's), falling back to the maneuver's own guess if
that start does not converge. The correction matrix comes from the same model as p⁰.

:func:`design_vehicle_table` is the design model's stored form: the vehicle's table, and for a
firmware design what the model was built from (``"design_model"``), so the store says which model
designed a session and a resumed session keeps its design.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aerobat.config import check_type
from aerobat.core.design import Design, design
from aerobat.core.maneuver import Maneuver
from aerobat.errors import ConfigError
from aerobat.plants import DesignModel, PlantChoice
from aerobat.quadrotor.simulate import NominalModel
from aerobat.quadrotor.vehicle import VehicleConfig, vehicle_table

__all__ = ["DESIGN_MODEL_KEY", "LITTLE_MARGIN_SHARE", "NominalDesign", "design_model_of", "design_vehicle_table",
           "job_design", "nominal_design", "resolve_design_model", "thrust_margin_line"]

DESIGN_MODEL_KEY = "design_model"
"""The key of a design vehicle's stored table that says which model designed (absent: the paper's)."""
_PAPER_TABLE = {"kind": DesignModel.PAPER.value, "description": "the paper's model"}
LITTLE_MARGIN_SHARE = 0.15
"""A design that holds a motor at full output in more of its steps than this has little thrust margin
(measured, docs/plants.md: the default triple flip 8.6 %, first attempt 0.095 m; the ROMA F5's 2.2 %
without its pack's sag, 0.25 m; 19.5 % with it, 0.58 m)."""
_FULL_OUTPUT = 0.999


@dataclass(frozen=True)
class NominalDesign:
    """A nominal design and the model it ran on.

    Attributes
    ----------
    design : the :class:`~aerobat.core.design.Design` (p⁰, J and C from the same model).
    model : which model (:class:`~aerobat.plants.DesignModel`).
    description : that model in one line.
    table : its stored form (:func:`design_vehicle_table` keeps it with the vehicle).
    paper : the paper model's design the firmware design started from (None for a paper design).
    compute_s : wall time of both stages [s].
    full_output_share : on a model that records its motors (the firmware model), the share of p⁰'s steps
        with a motor at full output (None: not known). Much of it means little thrust margin: what the
        model does not know of the world (a centre-of-mass offset, uneven motors) then saturates a motor.
    """

    design: Design
    model: DesignModel
    description: str
    table: dict[str, Any] = field(default_factory=dict)
    paper: Design | None = None
    compute_s: float = 0.0
    full_output_share: float | None = None

    def summary(self) -> str:
        """The design's summary, then the model it ran on (:meth:`model_lines`)."""
        return "\n".join([self.design.summary(), *self.model_lines()])

    def model_lines(self) -> list[str]:
        """What a person reads about the model: which one, the paper's stage before it, the thrust margin."""
        lines = [f"  design model: {self.model.value} — {self.description}"]
        if self.paper is not None:
            lines.append(f"  started from the paper model's p⁰ ({self.paper.status.value}, {self.paper.evaluations} "
                         f"simulations); both stages {self.compute_s:.2f} s")
        if self.full_output_share is not None:
            lines.append(thrust_margin_line(self.full_output_share))
        return lines


def thrust_margin_line(full_output_share: float) -> str:
    """The line that says how much of p⁰ holds a motor at full output, with a warning above
    :data:`LITTLE_MARGIN_SHARE` (``aerobat design`` and ``aerobat learn`` print it)."""
    share = full_output_share
    return (f"  on the model, p⁰ holds a motor at full output in {share:.1%} of its steps"
            + (f"; above {LITTLE_MARGIN_SHARE:.0%} the thrust margin is small: a centre-of-mass offset or uneven "
               f"motors the model does not know will saturate a motor and cost height (docs/plants.md, the ROMA F5 "
               f"with its pack's sag)" if share > LITTLE_MARGIN_SHARE else ""))


def resolve_design_model(plant: PlantChoice | None, choice: DesignModel | str | None) -> DesignModel:
    """The design model ``choice`` names (None: the plant's default), checked against the plant."""
    if choice is None:
        return plant.spec.default_design_model if plant is not None else DesignModel.PAPER
    try:
        kind = DesignModel(choice)
    except ValueError:
        raise ConfigError(f"--design-model {choice!r}: one of {', '.join(k.value for k in DesignModel)}") from None
    if kind is DesignModel.FIRMWARE:
        if plant is None:
            raise ConfigError("--design-model firmware: name the plant whose firmware to model (--plant betaflight)")
        plant.spec.check_design_model(kind)
    return kind


def nominal_design(maneuver: Maneuver, config: VehicleConfig, *, plant: PlantChoice | None = None,
                   design_model: DesignModel | str | None = None, correction: str = "tsvd") -> NominalDesign:
    """Design ``maneuver`` for the vehicle ``config`` on the model ``design_model`` (default: the plant's).

    Parameters
    ----------
    maneuver : what to design.
    config : the vehicle the user believes (the paper's model's vehicle; the firmware model's rigid body).
    plant : the plant the design is for (None: a paper design with no plant in mind).
    design_model : ``"paper"`` or ``"firmware"`` (None: the plant's default,
        :attr:`~aerobat.plants.PlantSpec.default_design_model`).
    correction : the right inverse used for C.
    """
    check_type("config", config, VehicleConfig, "a VehicleConfig (e.g. aerobat.hummingbird())")
    if plant is not None:
        check_type("plant", plant, PlantChoice, "a PlantChoice")
    kind = resolve_design_model(plant, design_model)
    started = time.perf_counter()
    paper = design(maneuver, NominalModel(config), correction=correction)  # type: ignore[arg-type]
    if kind is DesignModel.PAPER:
        return NominalDesign(paper, kind, _PAPER_TABLE["description"], dict(_PAPER_TABLE),
                             compute_s=time.perf_counter() - started)
    assert plant is not None and plant.spec.firmware_model is not None
    plant.spec.check_available()
    model, table = plant.spec.firmware_model(config, plant.settings)
    starts = [paper.p_nominal] if paper.converged else []
    best: Design | None = None
    for start in (*starts, None):
        result = design(maneuver, model, p_guess=start, correction=correction)  # type: ignore[arg-type]
        if best is None or result.residual_norm < best.residual_norm or result.converged:
            best = result
        if result.converged:
            break
    assert best is not None
    compute_s = time.perf_counter() - started
    return NominalDesign(best, kind, str(table.get("description", "")), table, paper=paper, compute_s=compute_s,
                         full_output_share=_full_output_share(model, maneuver, best))


def _full_output_share(model: Any, maneuver: Maneuver, result: Design) -> float | None:
    """The share of p⁰'s steps with a motor at full output on ``model``, if it records its motors."""
    trajectory = getattr(model, "trajectory", None)
    if not callable(trajectory) or not np.all(np.isfinite(result.p_nominal)):
        return None
    try:
        motors = np.asarray(trajectory(maneuver.program(result.p_nominal)).motors, dtype=float)
    except (AttributeError, ValueError, ConfigError):
        return None
    if motors.ndim != 2 or motors.shape[0] == 0:
        return None
    return float(np.mean(motors.max(axis=1) >= _FULL_OUTPUT))


def design_vehicle_table(config: VehicleConfig, nominal: NominalDesign | None) -> dict[str, Any]:
    """The design model's stored form: ``config``'s table, with ``"design_model"`` for a firmware design."""
    table = vehicle_table(config)
    if nominal is not None and nominal.model is not DesignModel.PAPER:
        table[DESIGN_MODEL_KEY] = nominal.table
    return table


def design_model_of(table: Mapping[str, Any]) -> tuple[DesignModel, str]:
    """Which model designed, from a stored design vehicle table (one written before this existed: the paper's)."""
    entry = table.get(DESIGN_MODEL_KEY)
    if not isinstance(entry, Mapping):
        return DesignModel.PAPER, _PAPER_TABLE["description"]
    try:
        kind = DesignModel(str(entry.get("kind")))
    except ValueError:
        kind = DesignModel.PAPER
    return kind, str(entry.get("description", ""))


def job_design(design_result: Design | NominalDesign, config: VehicleConfig) -> tuple[dict[str, Any], dict[str, Any]]:
    """A study job's ``"design"`` and ``"model"`` entries: the design's JSON and the design model's table."""
    nominal = design_result if isinstance(design_result, NominalDesign) else None
    result = nominal.design if nominal is not None else design_result
    if not isinstance(result, Design):
        raise ConfigError(f"design: expected a Design or a NominalDesign, got {type(result).__name__}")
    return ({k: v for k, v in result.to_json_dict().items() if k != "maneuver"},
            design_vehicle_table(config, nominal))
