"""The timings README.md and docs/scaling.md quote, measured on this machine: ``python scripts/timings.py``.

Two measurements, each printed with what it depends on (cores, CPU model, the load average
while it ran: other processes on the same cores slow both):

- **compile**: ``python -m aerobat.experiments.warmup`` into an empty numba cache (what
  ``make setup`` does once), wall time;
- **study**: ``aerobat study robustness flip --flips 3 --dims 3 --trials 30`` over ``--vehicles``
  sampled vehicles with each ``--workers`` count, wall time and sessions per second, into a
  throw-away store.

Options: ``--vehicles N`` (default 1000, as docs/scaling.md), ``--workers 1,2``,
``--skip-compile``, ``--skip-study``. It takes about 2 min for the compile and, at the default
size, a few minutes per worker count on 2 cores.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def _timed(argv: list[str], env: dict[str, str], cwd: Path) -> tuple[float, tuple[float, float], int]:
    """(wall seconds, (load average before, after), exit status) of one command."""
    before = os.getloadavg()[0]
    start = time.perf_counter()
    status = subprocess.run(argv, env=env, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            check=False).returncode
    return time.perf_counter() - start, (before, os.getloadavg()[0]), status


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    parser.add_argument("--vehicles", type=int, default=1000, metavar="N")
    parser.add_argument("--workers", default="1,2", metavar="LIST")
    parser.add_argument("--skip-compile", action="store_true")
    parser.add_argument("--skip-study", action="store_true")
    args = parser.parse_args(argv)
    print(f"machine: {os.cpu_count()} cores, {_cpu()}, Python {platform.python_version()}")
    print("| what | wall time | load average before → after | notes |")
    print("|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if not args.skip_compile:
            env = {**os.environ, "NUMBA_CACHE_DIR": str(folder / "numba-cache")}  # an empty cache: a full compile
            wall, load, status = _timed([sys.executable, "-m", "aerobat.experiments.warmup"], env, folder)
            print(f"| compile the kernels (warmup, empty cache) | {wall:.0f} s | {load[0]:.1f} → {load[1]:.1f} | "
                  f"exit {status} |")
        if not args.skip_study:
            for workers in (int(w) for w in args.workers.split(",")):
                db = folder / f"study-{workers}.sqlite"
                command = [sys.executable, "-m", "aerobat.cli", "study", "robustness", "flip", "--flips", "3",
                           "--dims", "3", "--vehicles", str(args.vehicles), "--trials", "30",
                           "--workers", str(workers), "--db", str(db), "--out", str(folder / f"out-{workers}")]
                wall, load, status = _timed(command, dict(os.environ), folder)
                print(f"| {args.vehicles} vehicles, {workers} worker{'s' if workers != 1 else ''} | {wall:.1f} s | "
                      f"{load[0]:.1f} → {load[1]:.1f} | {args.vehicles / wall:.1f} sessions/s, exit {status} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
