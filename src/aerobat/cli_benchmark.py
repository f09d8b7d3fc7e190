"""``aerobat benchmark``: time-optimal translation benchmarks (Sect. 9; Ritz et al. 2011)."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from .cli import EXIT_OK, CommandFailed, _console, _parse_pair

__all__ = ["register"]


def _limits(args: argparse.Namespace):
    from .timeoptimal import BenchmarkLimits

    defaults = BenchmarkLimits()
    return BenchmarkLimits(
        f_min_m_s2=defaults.f_min_m_s2 if args.f_min is None else args.f_min,
        f_max_m_s2=defaults.f_max_m_s2 if args.f_max is None else args.f_max,
        max_rate_rad_s=args.max_rate_rad_s,
        gravity_m_s2=defaults.gravity_m_s2,
    )


def _cmd_translation(args: argparse.Namespace) -> int:
    from rich.table import Table

    from .timeoptimal import plot_solution, solve_translation

    if not math.isfinite(args.final_angle_rad):
        raise ValueError(f"--final-angle-rad {args.final_angle_rad}: must be finite")
    y, z = _parse_pair(args.to, "--to")
    solution = solve_translation(y, z, final_angle_rad=args.final_angle_rad, limits=_limits(args))
    if args.plot and solution.ok:
        plot_solution(solution, args.plot)
    if args.json:
        print(json.dumps(solution.to_json_dict()))
    else:
        console = _console(False)
        console.print(f"time-optimal hover-to-hover (0, 0) → ({y:g}, {z:g}) m, "
                      f"final angle {args.final_angle_rad:g} rad")
        console.print(f"status: {solution.status} — {solution.message}")
        if solution.ok:
            console.print(f"T* = {solution.duration_s:.4f} s "
                          f"(transcription {solution.transcription_duration_s:.4f} s), "
                          f"boundary error {solution.boundary_error:.1e}")
            for title, arcs, unit in (("thrust", solution.thrust_arcs, "m/s²"), ("rate", solution.rate_arcs, "rad/s")):
                table = Table(title=f"{title} arcs")
                for col in ("kind", "start [s]", "end [s]", f"value [{unit}]"):
                    table.add_column(col)
                for arc in arcs:
                    table.add_row(arc.kind, f"{arc.start_s:.4f}", f"{arc.end_s:.4f}", f"{arc.value:+.4f}")
                console.print(table)
        if args.plot and solution.ok:
            console.print(f"plot written to {args.plot}")
    if not solution.ok:
        raise CommandFailed(solution.message)
    return EXIT_OK


def _parse_range(text: str, option: str) -> tuple[float, float, int]:
    parts = text.split(":")
    try:
        a, b, n = float(parts[0]), float(parts[1]), int(parts[2])
    except (ValueError, IndexError):
        raise ValueError(f"{option} {text!r}: expected A:B:N (metres, metres, count)") from None
    if len(parts) != 3 or not (math.isfinite(a) and math.isfinite(b)) or not 1 <= n <= 200:
        raise ValueError(f"{option} {text!r}: expected finite A:B and 1 <= N <= 200")
    return a, b, n


def _cmd_map(args: argparse.Namespace) -> int:
    """Minimum time over a grid of targets, one job per target on the execution layer
    (local pool or Dask), each result committed to the store as it arrives (``--resume``)."""
    import dataclasses

    import numpy as np

    from .cli_study import _run_jobs
    from .execution import Job
    from .store import Store
    from .timeoptimal import plot_map, write_map_csv

    ya, yb, yn = _parse_range(args.y, "--y")
    za, zb, zn = _parse_range(args.z, "--z")
    ys, zs = np.linspace(ya, yb, yn), np.linspace(za, zb, zn)
    limits = dataclasses.asdict(_limits(args))
    jobs = [Job(key=f"y{i:03d}-z{j:03d}", kind="benchmark", spec={"y_m": float(y), "z_m": float(z), "limits": limits})
            for j, z in enumerate(zs) for i, y in enumerate(ys)]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    spec = {"ys_m": ys.tolist(), "zs_m": zs.tolist(), "limits": limits}

    def record(store, study_id, job, result) -> None:
        store.record_study_job(study_id, job.key, job.spec, result)

    study_id, ran, skipped = _run_jobs(args, "map", spec, jobs, record)
    with Store(args.db) as store:
        results = store.study_results(study_id)
    grid = np.full((zn, yn), np.nan)
    for j in range(zn):
        for i in range(yn):
            value = results.get(f"y{i:03d}-z{j:03d}", {}).get("duration_s")
            grid[j, i] = value if isinstance(value, float) else np.nan
    write_map_csv(out, ys, zs, grid)
    figure = out.with_suffix(".png")
    plot_map(figure, ys, zs, grid)
    failed = int(np.isnan(grid).sum())
    _console(False).print(f"study {study_id}: {yn * zn} targets ({ran} solved now, {skipped} already done), "
                          f"{failed} failed; CSV {out}, contour plot {figure}")
    return EXIT_OK


def register(sub) -> None:
    bench = sub.add_parser("benchmark", help="time-optimal translation benchmarks")
    bsub = bench.add_subparsers(dest="benchmark", required=True, parser_class=type(bench))

    def limits(p: argparse.ArgumentParser) -> None:
        p.add_argument("--f-min", type=float, default=None, help="minimum collective [m/s²] (default eq 47: 4.80)")
        p.add_argument("--f-max", type=float, default=None, help="maximum collective [m/s²] (default eq 47: 20.70)")
        p.add_argument("--max-rate-rad-s", type=float, default=10.0, help="rate limit [rad/s]")

    tr = bsub.add_parser("translation", help="minimum-time hover-to-hover motion to one target")
    tr.add_argument("--to", required=True, help="target Y,Z [m]")
    tr.add_argument("--final-angle-rad", type=float, default=0.0, help="final attitude (2π: translate with a flip)")
    limits(tr)
    tr.add_argument("--json", action="store_true")
    tr.add_argument("--plot", metavar="FILE.png")
    tr.set_defaults(func=_cmd_translation)

    mp = bsub.add_parser("map", help="minimum time over a grid of targets")
    mp.add_argument("--y", required=True, help="A:B:N grid of Y targets [m]")
    mp.add_argument("--z", required=True, help="A:B:N grid of Z targets [m]")
    mp.add_argument("--workers", type=int, default=None, help="local worker processes (default: all cores)")
    mp.add_argument("--scheduler", default=None,
                    help="Dask scheduler address tcp://HOST:PORT (default: $DASK_SCHEDULER_ADDRESS, else local)")
    mp.add_argument("--db", default=None, help="experiment store (default ./aerobat.sqlite)")
    mp.add_argument("--resume", default=None, metavar="STUDY", help="continue a map: solve only the missing targets")
    mp.add_argument("--out", default="out/benchmark_map.csv", help="CSV file (a .png contour plot goes beside it)")
    limits(mp)
    mp.set_defaults(func=_cmd_map)
