"""The simulated flying-machine arena: true vehicle, sensing, links and supervisor."""

from .arena import Arena
from .params import ArenaParams, load_arena, save_arena

__all__ = ["Arena", "ArenaParams", "load_arena", "save_arena"]
