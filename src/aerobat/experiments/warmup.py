"""Compile aerobat's kernels ahead of the first command: ``python -m aerobat.experiments.warmup``.

aerobat's simulation kernels are compiled by numba on first use and cached on disk
(in ``__pycache__`` next to the sources, or under ``NUMBA_CACHE_DIR`` when it is set).
Compiling them all takes 10–20 s, which the first ``aerobat learn`` would otherwise
spend silently before its first trial. ``make setup`` runs this module once, so every
later command loads the compiled code from the cache.

It runs each compiled entry point once, on tiny inputs, through the public functions
the commands use, so it compiles exactly the variants (argument types) they need:
continuous and sampled playback, the parallel batch, and a complete arena trial.
"""

from __future__ import annotations

import time

__all__ = ["warm_up"]


def warm_up() -> float:
    """Compile (or load from numba's cache) every kernel a command uses; returns the seconds it took."""
    start = time.perf_counter()
    from aerobat.plants.arena import Arena
    from aerobat.quadrotor.program import Program, Switch
    from aerobat.quadrotor.simulate import NominalModel, simulate, simulate_batch
    from aerobat.quadrotor.vehicle import hummingbird

    config = hummingbird()
    program = Program(switches=(Switch(time_s=0.0, channel="rate_p", value=1.0),), duration_s=0.05)
    simulate(program, config)
    simulate(program, config, mode="sampled")
    simulate_batch([program, program], config)
    NominalModel(config).final_states([program])
    Arena(config, seed=0).fly(program)
    return time.perf_counter() - start


def main() -> None:
    print(f"aerobat: compiled kernels ready ({warm_up():.1f} s)", flush=True)


if __name__ == "__main__":
    main()
