"""Learning through Betaflight in 30 trials (slow: about a minute per maneuver).

The numbers in docs/results.md come from ``scripts/results_betaflight.py learn`` (seeds 1–3);
these tests hold seed 1 to the issue's bar.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from aerobat.core.design import design
from aerobat.core.learning import learn
from aerobat.core.maneuver import ErrorKind
from aerobat.plants.betaflight.plant import BetaflightPlant
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel
from aerobat.quadrotor.vehicle import fpv5

pytestmark = pytest.mark.slow
FPV = fpv5()


def learn_flip(**flip: object) -> tuple[np.ndarray, np.ndarray, object]:
    maneuver = MultiFlip(vehicle=FPV.vehicle, **flip)  # type: ignore[arg-type]
    session = learn(maneuver, design(maneuver, NominalModel(FPV)), BetaflightPlant(FPV, seed=1), iterations=30)
    assert session.status.value == "completed", session.message
    errors = np.array([it.error for it in session.measured])
    pos = [i for i, e in enumerate(maneuver.errors) if e.kind is ErrorKind.POSITION]
    ang = [i for i, e in enumerate(maneuver.errors) if e.kind is ErrorKind.ANGLE]
    return np.linalg.norm(errors[:, pos], axis=1), np.degrees(np.abs(errors[-10:][:, ang])), session


def test_3d_triple_flip_at_1800_deg_s_learns_through_betaflight(firmware: tuple[Path, Path]) -> None:
    position, angles, session = learn_flip(flips=3, max_rate_rad_s=math.radians(1800), dims=3)
    assert len(session.iterations) == 30  # every trial measured (and each one stored by a stored session)
    assert position[0] > 0.3  # the nominal design misses on the firmware
    assert position[-10:].mean() <= 0.15 and position[-10:].mean() <= 0.2 * position[0]
    assert angles.max() <= 3.0


def test_2d_single_flip_learns_through_betaflight(firmware: tuple[Path, Path]) -> None:
    position, angles, _ = learn_flip(flips=1, max_rate_rad_s=math.radians(800), dims=2)
    assert position[-10:].mean() <= 0.15 and position[-10:].mean() < position[0]
    assert angles.mean(axis=0).max() <= 3.0


def test_3d_pitch_double_flip_learns_through_betaflight(firmware: tuple[Path, Path]) -> None:
    position, angles, _ = learn_flip(flips=2, max_rate_rad_s=math.radians(1800), dims=3, axis="pitch")
    assert position[-10:].mean() <= 0.15 and position[-10:].mean() <= 0.2 * position[0]
    assert angles.mean(axis=0).max() <= 3.0
