"""The quadrocopter maneuvers: the paper's multi-flips (Sect. 8) and near-time-optimal translations (Sect. 9).

Both are registered as maneuver kinds (``flip``, ``translation``) through the
``aerobat.maneuvers`` entry-point group, like any plugin.
"""

from aerobat.quadrotor.maneuvers.flip import FlipStages, MultiFlip, flip_from_spec
from aerobat.quadrotor.maneuvers.plugins import load_maneuver
from aerobat.quadrotor.maneuvers.staged import StagedManeuver, load_maneuver_file, staged_from_spec
from aerobat.quadrotor.maneuvers.translation import (
    Translation,
    translation_from_solution,
    translation_from_spec,
    translation_maneuver,
)

__all__ = [
    "FlipStages",
    "MultiFlip",
    "StagedManeuver",
    "Translation",
    "flip_from_spec",
    "load_maneuver",
    "load_maneuver_file",
    "staged_from_spec",
    "translation_from_solution",
    "translation_from_spec",
    "translation_maneuver",
]
