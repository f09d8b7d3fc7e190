"""What ``aerobat setup`` compiles for the pilot both Betaflight plants fly with
(:attr:`aerobat.plants.PlantSpec.kernels`)."""

from __future__ import annotations

import numpy as np

__all__ = ["warm_sticks"]


def warm_sticks() -> None:
    """The pilot's compiled sticks: the program's ACRO rates and the ANGLE-mode position hold."""
    from aerobat.plants.fpv.pilot import N_LIMITS, angle_sticks, program_sticks

    limits = np.ones(N_LIMITS)
    sticks = np.zeros(4)
    program_sticks(np.array([9.81, 0.0, 0.0, 0.0]), limits, sticks)
    angle_sticks(np.zeros(3), np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), np.zeros(3),
                 np.ones(4), limits, 1.0 / 50.0, sticks)
