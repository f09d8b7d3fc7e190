"""A maneuver written in Python by a user: a vertical hop (used by tests/quadrotor/test_maneuver_files.py).

It shows the plugin contract: a class called with ``vehicle=``, a ``spec()`` that names its
``module`` (so any process can rebuild it), and ``from_spec`` registered for its kind.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aerobat import Program, RampDown, Switch, VehicleParams
from aerobat.config import dataclass_from_table, dataclass_to_table
from aerobat.core.maneuver import ErrorKind, ErrorSpec, ParameterSpec, check_parameters
from aerobat.core.registry import MANEUVERS
from aerobat.quadrotor.dynamics import POS, VEL, hover_state


@dataclass(frozen=True, kw_only=True)
class VerticalHop:
    vehicle: VehicleParams
    height_m: float = 1.0
    name: str = "vertical hop (plugin)"
    parameters: tuple = field(init=False, repr=False, compare=False)
    errors: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "parameters", (
            ParameterSpec(name="p0", description="climb duration", unit="s", lower=0.0, upper=2.0, scale=0.02),
            ParameterSpec(name="p1", description="brake duration", unit="s", lower=0.0, upper=2.0, scale=0.02),
        ))
        object.__setattr__(self, "errors", (
            ErrorSpec(name="z", unit="m", scale=0.05, kind=ErrorKind.POSITION),
            ErrorSpec(name="vz", unit="m/s", scale=0.05, kind=ErrorKind.VELOCITY),
        ))

    def guess(self) -> np.ndarray:
        return np.array([0.3, 0.3])

    def is_valid(self, params: np.ndarray) -> bool:
        return check_parameters(self.parameters, params) is None

    def duration_s(self, params: np.ndarray) -> float:
        return float(params[0] + params[1]) + 0.05

    def program(self, params: np.ndarray) -> Program:
        p0, p1 = (float(v) for v in params)
        top = self.vehicle.collective_reduced_max_m_s2
        return Program(switches=(Switch(time_s=0.0, channel="collective", value=top),
                                 Switch(time_s=p0, channel="collective", value=5.0)),
                       duration_s=p0 + p1 + 0.05, ramp_down=RampDown(collective_s=0.05),
                       hover_collective_m_s2=self.vehicle.gravity_m_s2, name=self.name)

    def initial_state(self) -> np.ndarray:
        return hover_state(self.vehicle)

    def error(self, final_state: np.ndarray) -> np.ndarray:
        return np.array([final_state[POS][2] - self.height_m, final_state[VEL][2]])

    def spec(self) -> dict[str, Any]:
        return {"kind": "test_hop", "module": __name__, "height_m": self.height_m,
                "vehicle": dataclass_to_table(self.vehicle)}

    @classmethod
    def from_spec(cls, spec: Any, source: str) -> VerticalHop:
        return cls(vehicle=dataclass_from_table(VehicleParams, spec["vehicle"], source=f"{source}.vehicle"),
                   height_m=float(spec["height_m"]))


if "test_hop" not in MANEUVERS.names():
    MANEUVERS.register("test_hop", VerticalHop.from_spec)
