"""How often the firmware and the driver fall asleep in Betaflight trials over shared memory (issue 27).

A benchmark, not a test. Over spinning shared memory each side waits for the other spinning; a
wait that outlasts its spin sleeps on a futex, and the other side then pays a futex wake, and the
sleeper a wake-up of several microseconds: the cost that decides how close a trial's wall time
comes to the firmware's own CPU time. This flies ``--trials`` 3D triple flips at 8 kHz (seeds
1 …) under ``perf record -e syscalls:sys_enter_futex`` (Linux ``perf``, needs the right to trace
system calls, e.g. root) and counts the futex calls of this process (the driver) and of its
firmware processes, by operation (WAIT: the caller falls asleep; WAKE: it wakes the other)::

    .venv/bin/python benchmarks/futex_sleeps.py --trials 8

prints one line per process and operation, the steps flown and the sleeps per 1,000 steps.
"""

from __future__ import annotations

import argparse
import collections
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_betaflight as bench  # noqa: E402

from aerobat.plants.betaflight.plant import BetaflightPlant  # noqa: E402

_OPS = {0: "WAIT", 1: "WAKE"}  # FUTEX_PRIVATE_FLAG (128) is masked off
_LINE = re.compile(r"^\s*(\d+)\s.*?op: (0x[0-9a-f]+)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=8)
    args = parser.parse_args()
    if shutil.which("perf") is None:
        print("perf is not installed (Debian: linux-perf)", file=sys.stderr)
        return 2
    program = bench._triple_program()
    params = bench._params(8000, "shm")
    BetaflightPlant(bench.CONFIG, params, seed=99).fly(program)  # compiled code loaded, caches warm
    firmware_pids: set[int] = set()
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "perf.data"
        perf = subprocess.Popen(["perf", "record", "-q", "-a", "-e", "syscalls:sys_enter_futex", "-o", str(data)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        try:
            time.sleep(1.0)  # perf is recording
            if perf.poll() is not None:
                print(f"perf record failed: {perf.stderr.read() if perf.stderr else ''}", file=sys.stderr)
                return 2
            steps, started = 0, time.perf_counter()
            for seed in range(1, args.trials + 1):
                plant = BetaflightPlant(bench.CONFIG, params, seed=seed)
                original = plant.open_flight

                def open_flight(*a: object, _original=original, **k: object) -> object:
                    flight = _original(*a, **k)
                    firmware_pids.add(flight.sitl.pid)
                    return flight

                plant.open_flight = open_flight  # type: ignore[method-assign]
                trial = plant.fly(program)
                steps += trial.info["steps"]
            wall = time.perf_counter() - started
        finally:
            perf.send_signal(signal.SIGINT)
            perf.wait(timeout=60)
        script = subprocess.run(["perf", "script", "-i", str(data), "-F", "pid,trace"], capture_output=True,
                                text=True, check=True).stdout
    counts: collections.Counter[tuple[str, str]] = collections.Counter()
    for line in script.splitlines():
        match = _LINE.match(line)
        if match is None:
            continue
        pid, op = int(match.group(1)), int(match.group(2), 16) & 0x7F
        who = "driver" if pid == os.getpid() else "firmware" if pid in firmware_pids else None
        if who is not None and op in _OPS:
            counts[who, _OPS[op]] += 1
    print(f"{args.trials} trials, {steps:,} steps, {wall:.2f} s ({steps / wall:,.0f} steps/s)")
    for (who, op), n in sorted(counts.items()):
        print(f"{who:8s} FUTEX_{op}: {n:7,d} ({1000 * n / steps:.2f} per 1,000 steps)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
