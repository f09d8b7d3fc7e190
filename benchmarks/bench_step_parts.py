"""What one lockstep step costs the driver, part by part, without the firmware (issue 27).

A benchmark, not a test: compiled loops time the physics of one 8 kHz step in the air
(:func:`aerobat.plants.betaflight.physics.advance` and ``store_motors``: RK4 and the next state
packet) and one standard normal draw from the flight's generator (a radio frame of 32 steps
draws ~200 of them). These are the driver's share of a step that the firmware's own work
(0.6–1.1 µs a step, docs/performance.md) must cover for the two to overlap::

    .venv/bin/python benchmarks/bench_step_parts.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numba as nb
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_betaflight as bench  # noqa: E402

from aerobat.plants.betaflight.physics import C_CONTACT, advance, store_motors  # noqa: E402
from aerobat.plants.betaflight.plant import BetaflightPlant  # noqa: E402


@nb.njit(cache=False)
def _physics(n, x, motors, plant, aux, pending, counters, noise, packet, scratch):  # pragma: no cover - compiled
    for i in range(n):
        counters[C_CONTACT] = 0
        advance(x, plant, aux, pending, counters, noise[i % noise.shape[0]], packet, scratch)
        store_motors(motors, pending, counters[0])
        x[2] = 5.0  # stay in the air
    return 0


@nb.njit(cache=False)
def _normals(n, rng, out):  # pragma: no cover - compiled
    for k in range(n):
        out[k % out.shape[0]] = rng.standard_normal()
    return 0


def _best_of(runs: int, call: object, n: int) -> float:
    best = float("inf")
    for _ in range(runs):
        started = time.perf_counter()
        call()  # type: ignore[operator]
        best = min(best, (time.perf_counter() - started) / n)
    return best


def main() -> None:
    plant = BetaflightPlant(bench.CONFIG, bench._params(8000, "shm"), seed=1)
    with plant.open_flight() as flight:
        x = flight.x.copy()
        args = (flight.plant, flight.aux, flight.pending.copy(), flight.counters.copy())
        packet, scratch = flight.packet.copy(), flight.scratch.copy()
    x[2] = 5.0
    motors = np.array([0.5] * 4 + [0.0] * 15, dtype=np.float32)
    noise = np.random.default_rng(2).standard_normal((32, 6))
    n = 200_000
    _physics(10, x, motors, *args, noise, packet, scratch)
    physics = _best_of(5, lambda: _physics(n, x, motors, *args, noise, packet, scratch), n)
    rng, out = np.random.default_rng(3), np.zeros(64)
    _normals(10, rng, out)
    normal = _best_of(5, lambda: _normals(1_000_000, rng, out), 1_000_000)
    print(f"physics of one step in the air (advance + store_motors): {1e6 * physics:.3f} µs")
    print(f"one standard normal draw (numba Generator): {1e9 * normal:.1f} ns; a frame's 204: "
          f"{204e6 * normal:.2f} µs")


if __name__ == "__main__":
    main()
