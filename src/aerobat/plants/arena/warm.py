"""Compile the arena's trial kernel ahead of its first trial (its spec's :attr:`~aerobat.plants.PlantSpec.kernels`).

A whole arena trial runs in one compiled supervisor with the onboard feedback inlined, so a trial in
the closed loop (the default, ``tracking``) and one in the open loop compile both variants.
"""

from __future__ import annotations

__all__ = ["warm_arena"]


def warm_arena() -> None:
    """One arena trial with the onboard feedback and one in the open loop, on a 50 ms program."""
    from aerobat.plants.arena.arena import Arena
    from aerobat.quadrotor.program import Program, Switch
    from aerobat.quadrotor.vehicle import hummingbird

    program = Program(switches=(Switch(time_s=0.0, channel="rate_p", value=1.0),), duration_s=0.05)
    Arena(hummingbird(), seed=0, feedback="tracking").fly(program)
    Arena(hummingbird(), seed=0, feedback="none").fly(program)
