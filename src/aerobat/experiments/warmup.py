"""Compile aerobat's kernels ahead of the first command: ``python -m aerobat.experiments.warmup``.

aerobat's simulation kernels are compiled by numba on first use and cached on disk
(in ``__pycache__`` next to the sources, or under ``NUMBA_CACHE_DIR`` when it is set).
Compiling them all takes one to two minutes of CPU (the arena's supervisor, with the onboard
feedback inlined, about half of it; two processes side by side take about a minute), which the
first ``aerobat learn`` would otherwise spend silently before its first trial. ``make setup``
runs this module once, so every later command loads the compiled code from the cache.

It runs each compiled entry point once, on tiny inputs, through the public functions
the commands use, so it compiles exactly the variants (argument types) they need:
continuous playback (with and without rate-loop latency) and sampled playback, the parallel
batch, a complete arena trial with the onboard feedback (the arena's default, tracking) and
one in the open loop, and the kernels the RotorPy and Betaflight plants call one by one from
Python (the onboard feedback, the supervisor's estimate and PD controller, motion capture,
the Betaflight world and pilot), with the argument types those plants pass, and the Betaflight
blackbox decoder (:mod:`aerobat.logs.blackbox_decode`). The plants' kernels are the plants' to name
(:attr:`aerobat.plants.PlantSpec.kernels`): this module names no plant.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

__all__ = ["warm_up"]


_HEARTBEAT_S = 15.0


def warm_up(workers: int = 2, progress: Callable[[str], None] | None = None,
            parts: tuple[str, ...] | None = None) -> float:
    """Compile (or load from numba's cache) every kernel a command uses; returns the seconds it took.

    The kernels fall into four groups (:data:`PARTS`), compiled in ``workers`` processes
    side by side (numba writes each cache file atomically, so a kernel two need is safe). ``parts``
    compiles only those groups (``make demo``: playback and arena; default: all). ``progress`` gets a
    line as each group is ready and, while any is still compiling, one every 15 s naming them.
    """
    say = progress or (lambda line: None)
    chosen = PARTS if parts is None else tuple(p for p in PARTS if p in parts)
    unknown = sorted(set(parts or ()) - set(PARTS))
    if unknown:
        raise ValueError(f"unknown kernel group(s) {', '.join(unknown)}; allowed: {', '.join(PARTS)}")
    start = time.perf_counter()
    if workers > 1:
        from concurrent.futures import FIRST_COMPLETED, wait

        from aerobat.experiments.lifetime import process_pool

        with process_pool(min(workers, len(chosen))) as pool:  # its workers die with this process
            pending = {pool.submit(_warm_part, part): part for part in chosen}
            while pending:
                done, _ = wait(pending, timeout=_HEARTBEAT_S, return_when=FIRST_COMPLETED)
                for future in done:
                    future.result()  # a failed compile raises here
                    say(f"  {pending.pop(future)} kernels ready ({time.perf_counter() - start:.0f} s)")
                if not done:
                    say(f"  still compiling: {', '.join(sorted(pending.values()))} "
                        f"({time.perf_counter() - start:.0f} s)")
    else:
        for part in chosen:
            _warm_part(part)
            say(f"  {part} kernels ready ({time.perf_counter() - start:.0f} s)")
    return time.perf_counter() - start


PARTS = ("playback", "arena", "plants", "firmware")
"""The kernel groups: playback (simulate, the batch, the nominal model), the arena's trial, the kernels the
RotorPy and Betaflight plants call from Python with the blackbox decoder, and the firmware design model. What
each plant compiles, and in which group, its spec says (:attr:`aerobat.plants.PlantSpec.kernels`)."""


def _warm_part(part: str) -> None:
    if part == "playback":
        _warm_playback()
    if part == "plants":  # `log info` and `identify --log` on a Betaflight log
        from aerobat.logs.blackbox_decode import warm_up as blackbox_decoder

        blackbox_decoder()
    for compile_kernels in plant_kernels(part):
        compile_kernels()


def plant_kernels(part: str) -> list[Callable[[], None]]:
    """What compiles the kernels of group ``part`` that the registered plants declare
    (:attr:`aerobat.plants.PlantSpec.kernels`; a group not in :data:`PARTS` joins ``plants``), each once."""
    from aerobat.plants import PLANTS

    chosen: list[Callable[[], None]] = []
    for _name, spec in PLANTS.items():
        for kernels in spec.kernels:
            group = kernels.group if kernels.group in PARTS else "plants"
            if group == part and kernels.compile not in chosen:
                chosen.append(kernels.compile)
    return chosen


def _warm_playback() -> None:
    """simulate (continuous, sampled, with rate-loop latency), the batch and the nominal model."""
    from aerobat.quadrotor.program import Program, Switch
    from aerobat.quadrotor.simulate import NominalModel, simulate, simulate_batch
    from aerobat.quadrotor.vehicle import ModelEffects, hummingbird

    config = hummingbird()
    program = Program(switches=(Switch(time_s=0.0, channel="rate_p", value=1.0),), duration_s=0.05)
    # an identified vehicle's rate-loop latency runs its own continuous kernel
    lagging = dataclasses.replace(config, effects=ModelEffects(rate_latency_s=(0.005, 0.005, 0.005)))
    simulate(program, config, mode="sampled")
    simulate(program, lagging)
    simulate_batch([program, program], config)
    NominalModel(config).final_states([program])


def main() -> None:
    seconds = warm_up(progress=lambda line: print(line, flush=True))
    print(f"aerobat: compiled kernels ready ({seconds:.1f} s)", flush=True)


if __name__ == "__main__":
    main()
