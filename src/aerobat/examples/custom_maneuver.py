"""A user-written maneuver: a fast vertical hop from hover to hover 1 m higher.

Run it: ``.venv/bin/python examples/custom_maneuver.py``. It shows everything a maneuver
needs — parameters with bounds, errors with scales, a program builder, an error
function — and then designs and learns it on the simulated arena.

Input shape: the reduced-envelope maximum collective β̄ for ``p0`` seconds, then a
brake collective for ``p1`` seconds, then hover (with a short thrust ramp-down).
Two parameters, two errors (z, vz): a square Jacobian, C = J⁻¹.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from aerobat import Arena, NominalModel, Program, RampDown, Switch, VehicleParams, hummingbird, learn
from aerobat.core.maneuver import ErrorKind, ErrorSpec, ParameterSpec, check_parameters
from aerobat.core.testing import check_maneuver, check_plant
from aerobat.quadrotor.dynamics import POS, VEL, hover_state


@dataclass(frozen=True, kw_only=True)
class VerticalHop:
    vehicle: VehicleParams
    height_m: float = 1.0
    brake_collective_m_s2: float = 5.0
    name: str = "vertical hop"
    parameters: tuple = field(init=False)
    errors: tuple = field(init=False)

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
        p0, p1 = params
        top = self.vehicle.collective_reduced_max_m_s2
        return Program(
            switches=(Switch(time_s=0.0, channel="collective", value=top),
                      Switch(time_s=float(p0), channel="collective", value=self.brake_collective_m_s2)),
            duration_s=float(p0 + p1) + 0.05,
            ramp_down=RampDown(collective_s=0.05),
            hover_collective_m_s2=self.vehicle.gravity_m_s2,
            name=self.name,
        )

    def initial_state(self) -> np.ndarray:
        return hover_state(self.vehicle)

    def error(self, final_state: np.ndarray) -> np.ndarray:
        return np.array([final_state[POS][2] - self.height_m, final_state[VEL][2]])

    def spec(self) -> dict:
        return {"kind": "vertical_hop", "height_m": self.height_m, "brake_collective_m_s2": self.brake_collective_m_s2}


def main() -> None:
    config = hummingbird()
    hop = VerticalHop(vehicle=config.vehicle)
    nominal = check_maneuver(hop, model=NominalModel(config))  # the protocol's promises, and a design
    assert nominal is not None
    print(nominal.summary())
    check_plant(Arena(config, seed=0), hop, params=nominal.p_nominal)
    session = learn(hop, nominal, Arena(config, seed=1), iterations=10)
    for it in session.measured:
        print(f"{it.index:2d}  z error {it.error[0]:+.3f} m   vz error {it.error[1]:+.3f} m/s")


if __name__ == "__main__":
    main()
