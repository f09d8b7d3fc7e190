"""The vehicle library at a glance: each preset's envelope and which flips it can be designed to fly.

``aerobat vehicles`` prints these; ``aerobat vehicles --flips`` adds the flip grid (a 2D
design per flip count and rate, about a second each). A flip that cannot be designed
says why: the design's failure message names the vehicle limits its parameters sit on
(β̲ or β̄ for a collective, the stage limits) and the error left over.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from aerobat.core.design import design
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.maneuvers.flip import Axis
from aerobat.quadrotor.simulate import NominalModel
from aerobat.quadrotor.vehicle import VehicleConfig, preset, preset_names

__all__ = ["FlipFeasibility", "flip_feasibility", "vehicle_envelope", "vehicle_library"]


def vehicle_envelope(config: VehicleConfig) -> dict[str, Any]:
    """JSON-ready envelope of a vehicle: mass, thrust-to-weight, β̲/β̄, eq 27 accelerations, motor rates."""
    v = config.vehicle
    g = v.gravity_m_s2
    return {
        "name": config.name,
        "summary": str(config.source.get("summary", config.source.get("citation", ""))),
        "mass_kg": v.mass_kg,
        "thrust_to_weight": v.collective_max_m_s2 / g,
        "collective_reduced_min_m_s2": v.collective_reduced_min_m_s2,
        "collective_reduced_max_m_s2": v.collective_reduced_max_m_s2,
        "collective_reduced_min_g": v.collective_reduced_min_m_s2 / g,
        "collective_reduced_max_g": v.collective_reduced_max_m_s2 / g,
        "max_roll_acceleration_rad_s2": v.max_roll_acceleration_rad_s2,
        "max_pitch_acceleration_rad_s2": v.max_pitch_acceleration_rad_s2,
        "motor_rate_up_per_s": v.motor_rate_up_per_s,
        "motor_rate_down_per_s": v.motor_rate_down_per_s,
        "effects": not config.effects.neutral,
    }


def vehicle_library() -> list[VehicleConfig]:
    """Every preset, the default first."""
    return [preset(name) for name in preset_names()]


@dataclass(frozen=True)
class FlipFeasibility:
    """Whether a flip can be designed on a vehicle, and why not.

    Attributes
    ----------
    flips, max_rate_deg_s, axis, dims : the flip.
    feasible : the design converged.
    duration_s : hover to hover [s] (NaN if not feasible).
    reason : the design's words: the limits in the way and the error left over (empty if feasible).
    """

    flips: int
    max_rate_deg_s: float
    axis: str
    dims: int
    feasible: bool
    duration_s: float
    reason: str

    def to_table(self) -> dict[str, Any]:
        return {"flips": self.flips, "max_rate_deg_s": self.max_rate_deg_s, "axis": self.axis, "dims": self.dims,
                "feasible": self.feasible, "duration_s": self.duration_s if self.feasible else None,
                "reason": self.reason}


def _reason(message: str) -> str:
    """The part of a design failure message that says why: violated limits, else the largest error."""
    for marker in ("violated limits: ", "largest error "):
        if marker in message:
            start = message.index(marker)
            return message[start:]
    return message


def flip_feasibility(config: VehicleConfig, flips: Sequence[int] = (1, 2, 3),
                     rates_deg_s: Sequence[float] = (720.0, 1080.0, 1440.0, 1800.0), *,
                     axis: Axis = "roll", dims: int = 2) -> list[FlipFeasibility]:
    """Design each flip (count × rate) on ``config``'s nominal model; one result per flip."""
    model = NominalModel(config)
    out = []
    for n in flips:
        for rate in rates_deg_s:
            flip = MultiFlip(vehicle=config.vehicle, flips=int(n), max_rate_rad_s=math.radians(rate), axis=axis,
                             dims=dims)
            result = design(flip, model)  # type: ignore[arg-type]
            out.append(FlipFeasibility(int(n), float(rate), axis, dims, bool(result.converged),
                                       float(result.duration_s) if result.converged else math.nan,
                                       "" if result.converged else _reason(result.message)))
    return out
