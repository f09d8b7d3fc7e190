"""Timing benchmark of aerobat.quadrotor.timeoptimal (plain script, no pytest).

Usage::

    python benchmarks/bench_timeoptimal.py            # 5 solves of (5, 5)
    python benchmarks/bench_timeoptimal.py --map      # + 21 x 21 map over [-10, 10]^2
    python benchmarks/bench_timeoptimal.py --map --workers 4 --out /tmp/map

Prints markdown tables.  "cold" solves clear every cached CasADi graph first
(so they include graph building); "warm" solves reuse the cached solvers.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import aerobat.quadrotor.timeoptimal as to
from aerobat.experiments import LocalExecutor, run_study
from aerobat.experiments.studies import map_csv, map_grid, map_jobs
from aerobat.plotting import save_figure
from aerobat.plotting.benchmarks import plot_map, plot_solution
from aerobat.store import Store


def _time_solves(n: int, cold: bool) -> tuple[list[float], to.TimeOptimalSolution]:
    times = []
    sol = None
    for _ in range(n):
        if cold:
            to.clear_caches()
        t0 = time.perf_counter()
        sol = to.solve_translation(5.0, 5.0)
        times.append(time.perf_counter() - t0)
    assert sol is not None
    return times, sol


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=5, help="solves per row (default 5)")
    parser.add_argument("--map", action="store_true", help="also time a 21 x 21 benchmark map")
    parser.add_argument("--workers", type=int, default=2, help="processes for --map (default 2)")
    parser.add_argument("--out", type=Path, default=None, help="write map CSV/PNG here")
    args = parser.parse_args(argv)

    # warm up imports (scipy, casadi plugin loading) outside the timings
    to.solve_translation(1.0, 1.0)

    rows = []
    for label, cold in (("cold (incl. graph building)", True), ("warm (cached graphs)", False)):
        times, sol = _time_solves(args.repeats, cold)
        rows.append((label, times, sol))
    print("### solve_translation(5, 5)\n")
    print("| mode | runs | median s | min s | max s | T* s | transcription T s | status |")
    print("|---|---|---|---|---|---|---|---|")
    for label, times, sol in rows:
        print(
            f"| {label} | {len(times)} | {statistics.median(times):.3f} | {min(times):.3f} | "
            f"{max(times):.3f} | {sol.duration_s:.6f} | {sol.transcription_duration_s:.6f} | {sol.status} |"
        )
    sol = rows[0][2]
    print("\n### arcs of (5, 5)\n")
    print("| input | kind | start s | end s | value |")
    print("|---|---|---|---|---|")
    for name, arcs in (("thrust", sol.thrust_arcs), ("rate", sol.rate_arcs)):
        for a in arcs:
            print(f"| {name} | {a.kind} | {a.start_s:.6f} | {a.end_s:.6f} | {a.value:.5g} |")

    if args.map:
        ys = np.linspace(-10.0, 10.0, 21)
        zs = np.linspace(-10.0, 10.0, 21)
        done = [0]

        def progress(k: int, total: int, job: object, outcome: object) -> None:
            done[0] = k
            if k % 50 == 0 or k == total:
                print(f"  map: {k}/{total}", file=sys.stderr)

        import dataclasses
        import tempfile

        t0 = time.perf_counter()
        pool = LocalExecutor(args.workers)
        with tempfile.TemporaryDirectory() as tmp, Store(Path(tmp) / "map.sqlite") as store:
            outcome = run_study(store, "map", {"ys": ys.tolist(), "zs": zs.tolist()},
                                map_jobs(ys, zs, dataclasses.asdict(to.BenchmarkLimits())), executor=pool,
                                progress=progress)
        pool.close()
        grid = map_grid(outcome.results, ys, zs)
        elapsed = time.perf_counter() - t0
        n_fail = int(np.sum(~np.isfinite(grid)))
        finite = grid[np.isfinite(grid)]
        print("\n### benchmark map 21 x 21 over [-10, 10]^2 (a study on the execution layer)\n")
        print("| workers | targets | wall s | s / target | failed | T* min s | T* max s |")
        print("|---|---|---|---|---|---|---|")
        print(
            f"| {args.workers} | {grid.size} | {elapsed:.1f} | {elapsed / grid.size:.3f} | {n_fail} | "
            f"{finite.min() if finite.size else math.nan:.4f} | {finite.max() if finite.size else math.nan:.4f} |"
        )
        if args.out is not None:
            args.out.mkdir(parents=True, exist_ok=True)
            (args.out / "timeoptimal_map.csv").write_text(map_csv(ys, zs, grid))
            save_figure(plot_map(ys, zs, grid), args.out / "timeoptimal_map.png")
            save_figure(plot_solution(sol), args.out / "timeoptimal_5_5.png")
            print(f"\nwrote {args.out}/timeoptimal_map.csv, timeoptimal_map.png, timeoptimal_5_5.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
