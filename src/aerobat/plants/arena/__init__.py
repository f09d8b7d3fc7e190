"""The simulated flying-machine arena: true vehicle, sensing, links and supervisor."""

from aerobat.plants.arena.arena import Arena
from aerobat.plants.arena.params import ArenaParams, load_arena, save_arena
from aerobat.plants.arena.spec import SPEC

__all__ = ["SPEC", "Arena", "ArenaParams", "load_arena", "save_arena"]
