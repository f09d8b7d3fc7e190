"""Plants: things that fly programs and report trials (the learning loop sees only this)."""

from .arena import Arena, ArenaParams, load_arena
from .base import Plant, Trial, TrialStatus
from .nominal import NominalPlant

__all__ = ["Arena", "ArenaParams", "NominalPlant", "Plant", "Trial", "TrialStatus", "load_arena"]
