"""aerobat: design and learn fast open-loop quadrocopter maneuvers.

Implements and extends Lupashin & D'Andrea, *Adaptive fast open-loop maneuvers
for quadrocopters*, Autonomous Robots 2012.

The names below are imported lazily, on first use, so that commands which never
simulate (``aerobat sessions``, ``aerobat show``) start without loading numba.
"""

from __future__ import annotations

import importlib
from typing import Any

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

_HOME = {
    "Program": "program", "RampDown": "program", "Switch": "program", "load_program": "program",
    "save_program": "program", "Trajectory": "simulate", "simulate": "simulate", "simulate_batch": "simulate",
    "ControllerParams": "vehicle", "VehicleConfig": "vehicle", "VehicleParams": "vehicle",
    "hummingbird": "vehicle", "load_vehicle": "vehicle", "save_vehicle": "vehicle",
}


def __getattr__(name: str) -> Any:
    module = _HOME.get(name)
    if module is None:
        raise AttributeError(f"module 'aerobat' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
