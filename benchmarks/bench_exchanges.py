"""Issue 27's three targets for each lockstep exchange, in one run (docs/performance.md, "Issue 27 on a quiet machine").

Benchmarks, not tests: they measure and print, they never fail on a number. For each exchange it
runs ``bench_compiled_at_rest()``, ``bench_trials(8000)`` (seeds 1–3) and ``bench_parallel(rounds=3)``
from ``bench_betaflight.py`` and prints one markdown row per figure, the 1-minute load before and
after, and the raw figures as JSON on standard error::

    .venv/bin/python benchmarks/bench_exchanges.py                 # UDP, then shared memory (adaptive spin)
    .venv/bin/python benchmarks/bench_exchanges.py --no-spin shm   # shared memory, pure futex waits

``--no-spin`` flies with ``firmware.spin_us = 0`` (both sides sleep on the futex at once), in this
process and, through ``AEROBAT_BENCH_SPIN_US`` in the environment, in the parallel bench's
spawned workers.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

if "--no-spin" in sys.argv:
    os.environ["AEROBAT_BENCH_SPIN_US"] = "0"

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_betaflight as bench  # noqa: E402


def measure(exchange: str) -> dict[str, Any]:
    """The three figures of one exchange: on the floor, whole trials, two instances ÷ one."""
    return {"load_before": os.getloadavg()[0], "at_rest": bench.bench_compiled_at_rest(exchange=exchange),
            "trials": bench.bench_trials(8000, exchange=exchange),
            "parallel": bench.bench_parallel(rounds=3, exchange=exchange), "load_after": os.getloadavg()[0]}


def rows(name: str, m: dict[str, Any]) -> list[str]:
    """Markdown rows of one exchange's figures."""
    rest, trials, pair = m["at_rest"], m["trials"], m["parallel"]
    factors = ", ".join(f"{t['factor']:.1f}" for t in trials["trials"])
    return [
        f"| {name} | on the floor: steps/s; wall ÷ firmware CPU | {rest['steps_s']:,.0f}; "
        f"{rest['wall_per_firmware_cpu']:.2f} (firmware {rest['firmware_us_per_step']:.1f} µs CPU per step, "
        f"{1e6 * rest['firmware_spin_s'] / rest['steps']:.1f} µs of it spinning) |",
        f"| {name} | triple-flip trial, real-time factor (median; seeds 1–3) | {trials['factor_median']:.1f}× "
        f"({factors}); bit-identical: {trials['bit_identical']}; calls into the compiled loop: "
        f"{trials['trials'][0]['compiled_calls']} |",
        f"| {name} | triple-flip trial, wall ÷ firmware CPU (median) | {trials['overhead_median']:.2f} |",
        f"| {name} | triple-flip trial, wall ÷ firmware CPU less its spinning (median) | "
        f"{trials['overhead_work_median']:.2f} |",
        f"| {name} | 2 trials side by side ÷ 1 alone (median of 3) | {pair['ratio_median']:.2f}× ("
        + ", ".join(f"{r:.2f}" for r in pair["ratios"])
        + f"); one alone {min(pair['single_steps_s']):,.0f}–{max(pair['single_steps_s']):,.0f} steps/s, two "
          f"{min(pair['pair_steps_s']):,.0f}–{max(pair['pair_steps_s']):,.0f}; seed 1 alike alone and in "
          f"parallel: {pair['seed_identical_in_parallel']} |",
        f"| {name} | 1-minute load before / after | {m['load_before']:.1f} / {m['load_after']:.1f} |",
    ]


def main() -> None:
    exchanges = [a for a in sys.argv[1:] if a in ("udp", "shm")] or ["udp", "shm"]
    spin = "no spin" if os.environ.get("AEROBAT_BENCH_SPIN_US") == "0" else "adaptive spin"
    results = {}
    print("| exchange | what (8 kHz) | measured |\n|---|---|---|")
    for exchange in exchanges:
        name = "UDP" if exchange == "udp" else f"shared memory, {spin}"
        results[exchange] = measure(exchange)
        print("\n".join(rows(name, results[exchange])), flush=True)
    print(json.dumps(results, indent=1, default=str), file=sys.stderr)


if __name__ == "__main__":
    main()
