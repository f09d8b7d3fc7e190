"""aerobat: design and learn fast open-loop quadrocopter maneuvers.

Implements and extends Lupashin & D'Andrea, *Adaptive fast open-loop maneuvers
for quadrocopters*, Autonomous Robots 2012.
"""

from .program import Program, RampDown, Switch, load_program, save_program
from .simulate import Trajectory, simulate, simulate_batch
from .vehicle import ControllerParams, VehicleConfig, VehicleParams, hummingbird, load_vehicle, save_vehicle

__all__ = [
    "ControllerParams",
    "Program",
    "RampDown",
    "Switch",
    "Trajectory",
    "VehicleConfig",
    "VehicleParams",
    "hummingbird",
    "load_program",
    "load_vehicle",
    "save_program",
    "save_vehicle",
    "simulate",
    "simulate_batch",
]

__version__ = "0.1.0"
