"""The simulated flying-machine arena: true vehicle, sensing, links and supervisor."""

from aerobat.plants.arena.arena import Arena
from aerobat.plants.arena.params import ArenaParams, load_arena, save_arena

__all__ = ["Arena", "ArenaParams", "load_arena", "save_arena"]
