"""``aerobat benchmark``: time-optimal translation benchmarks (Sect. 9; Ritz et al. 2011)."""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import math
from typing import Any

import numpy as np

from aerobat.cli.common import HelpFormatter, check_plot_files, console, finite_float, old_spelling, parse_pair
from aerobat.cli.study import add_execution_options, report_failures, run_cli_study
from aerobat.errors import ConfigError, SolveFailed

__all__ = ["register"]


def _limits(args: argparse.Namespace) -> Any:
    from aerobat.quadrotor.timeoptimal import BenchmarkLimits

    defaults = BenchmarkLimits()
    return BenchmarkLimits(
        f_min_m_s2=defaults.f_min_m_s2 if args.f_min is None else args.f_min,
        f_max_m_s2=defaults.f_max_m_s2 if args.f_max is None else args.f_max,
        max_rate_rad_s=defaults.max_rate_rad_s if args.max_rate_deg_s is None else math.radians(args.max_rate_deg_s),
        gravity_m_s2=defaults.gravity_m_s2,
    )


def _require(args: argparse.Namespace, *options: tuple[str, str]) -> None:
    missing = [option for dest, option in options if getattr(args, dest, None) is None]
    if missing:
        raise ConfigError(f"the following arguments are required: {', '.join(missing)}")


def _cmd_translation(args: argparse.Namespace) -> int:
    from rich.table import Table

    from aerobat.plotting import save_figure, write_text
    from aerobat.plotting.benchmarks import plot_solution
    from aerobat.quadrotor.timeoptimal import solve_translation

    y, z = parse_pair(args.to, "--to-m")
    final_angle_rad = math.radians(args.final_angle_deg)
    if abs(y) < 1e-9 and abs(z) < 1e-9 and abs(final_angle_rad) < 1e-9:
        raise ConfigError(f"--to-m {args.to!r}: the target is the start (hover to the same hover takes no time)")
    folder = check_plot_files(args, ("translation.png", "translation.json"))  # refused before the solve
    solution = solve_translation(y, z, final_angle_rad=final_angle_rad, limits=_limits(args))
    figure = None
    if solution.ok and (folder is not None or args.plot):
        figure = save_figure(plot_solution(solution), folder / "translation.png" if folder is not None else args.plot)
    if folder is not None:
        write_text(folder / "translation.json", json.dumps(solution.to_json_dict(), indent=1))
    if args.json:
        print(json.dumps(solution.to_json_dict()))
    else:
        out = console()
        out.print(f"time-optimal hover-to-hover (0, 0) → ({y:g}, {z:g}) m, final angle {args.final_angle_deg:g}°")
        status = solution.status.value
        out.print(f"status: {status} — {solution.message.removeprefix(status + ': ')}")
        if solution.ok:
            # the command line speaks degrees (--body-rate-deg-s): so does the rate table
            for title, arcs, unit, scale in (("thrust", solution.thrust_arcs, "m/s²", 1.0),
                                             ("rate", solution.rate_arcs, "deg/s", math.degrees(1.0))):
                table = Table(title=f"{title} arcs")
                for col in ("kind", "start [s]", "end [s]", f"value [{unit}]"):
                    table.add_column(col)
                for arc in arcs:
                    table.add_row(arc.kind.value, f"{arc.start_s:.4f}", f"{arc.end_s:.4f}", f"{arc.value * scale:+.4f}")
                out.print(table)
        if figure is not None:
            where = f", solution to {folder / 'translation.json'}" if folder is not None else ""
            out.print(f"figure written to {figure}{where}")
    if not solution.ok:
        raise SolveFailed(solution.message, solution)
    return 0


def _parse_range(text: str, option: str) -> tuple[float, float, int]:
    parts = text.split(":")
    try:
        a, b, n = float(parts[0]), float(parts[1]), int(parts[2])
    except (ValueError, IndexError):
        raise ConfigError(f"{option} {text!r}: expected A:B:N (metres, metres, count)") from None
    if len(parts) != 3 or not (math.isfinite(a) and math.isfinite(b)) or not 1 <= n <= 200:
        raise ConfigError(f"{option} {text!r}: expected finite A:B and 1 <= N <= 200")
    if max(abs(a), abs(b)) > 100.0:
        raise ConfigError(f"{option} {text!r}: targets are limited to ±100 m")
    return a, b, n


def _cmd_map(args: argparse.Namespace) -> int:
    """Minimum time over a grid of targets, one job per target, each result committed as it arrives."""
    from aerobat.experiments.studies import map_csv, map_grid, map_jobs, run_study
    from aerobat.plotting import save_figure, write_text
    from aerobat.plotting.benchmarks import plot_map

    _require(args, ("y", "--y-m"), ("z", "--z-m"))
    ya, yb, yn = _parse_range(args.y, "--y-m")
    za, zb, zn = _parse_range(args.z, "--z-m")
    ys, zs = np.linspace(ya, yb, yn), np.linspace(za, zb, zn)
    limits = dataclasses.asdict(_limits(args))
    jobs = map_jobs(ys, zs, limits)
    spec = {"ys_m": ys.tolist(), "zs_m": zs.tolist(), "limits": limits}
    run = functools.partial(run_study, kind="map", spec=spec, jobs=jobs)
    outcome, out = run_cli_study(args, "map", run, written=("benchmark_map.csv", "benchmark_map.png"))
    grid = map_grid(outcome.results, ys, zs)
    csv_path = out / "benchmark_map.csv"
    write_text(csv_path, map_csv(ys, zs, grid))
    figure = save_figure(plot_map(ys, zs, grid), out / "benchmark_map.png")
    failed = int(np.isnan(grid).sum())
    report = {"study": outcome.study_id, "targets": yn * zn, "solved": yn * zn - failed, "csv": str(csv_path),
              "figure": str(figure)}
    if args.json:
        print(json.dumps(report))
    else:
        console().print(f"study {outcome.study_id}: {yn * zn} targets ({outcome.ran} solved now, {outcome.skipped} "
                        f"already done), {failed} without a time; CSV {csv_path}, contour plot {figure}")
    report_failures(outcome)
    return 0


def register(sub: Any) -> None:
    fmt = HelpFormatter
    bench = sub.add_parser("benchmark", help="time-optimal translation benchmarks", formatter_class=fmt)
    bsub = bench.add_subparsers(dest="benchmark", parser_class=type(bench), metavar="BENCHMARK")

    def limits(p: argparse.ArgumentParser) -> None:
        p.add_argument("--collective-min-m-s2", dest="f_min", type=finite_float(0.0, 1000.0, "m/s²"), default=None,
                       help="minimum collective [m/s²] (default: 4.80, eq 47)")
        old_spelling(p, "--f-min", "f_min", type=finite_float(0.0, 1000.0, "m/s²"))
        p.add_argument("--collective-max-m-s2", dest="f_max", type=finite_float(0.0, 1000.0, "m/s²"), default=None,
                       help="maximum collective [m/s²] (default: 20.70, eq 47)")
        old_spelling(p, "--f-max", "f_max", type=finite_float(0.0, 1000.0, "m/s²"))
        p.add_argument("--body-rate-deg-s", dest="max_rate_deg_s", type=finite_float(0.5, 5700.0, "deg/s"),
                       default=None, help="body-rate limit [deg/s] (default: 573, the paper's 10 rad/s)")
        old_spelling(p, "--max-rate-deg-s", "max_rate_deg_s", type=finite_float(0.5, 5700.0, "deg/s"))
        old_spelling(p, "--max-rate-rad-s", "max_rate_deg_s", type=finite_float(0.01, 100.0, "rad/s"),
                     convert=math.degrees)

    tr = bsub.add_parser("translation", help="minimum-time hover-to-hover motion to one target", formatter_class=fmt)
    tr.add_argument("--to-m", dest="to", metavar="Y,Z", default="5,5", help="target Y,Z [m]")
    old_spelling(tr, "--to", "to")
    tr.add_argument("--final-angle-deg", type=finite_float(-2300.0, 2300.0, "deg"), default=0.0,
                    help="final roll angle [deg], 360 to translate with a flip")
    old_spelling(tr, "--final-angle-rad", "final_angle_deg", type=finite_float(-40.0, 40.0, "rad"),
                 convert=math.degrees)
    limits(tr)
    tr.add_argument("--json", action="store_true", help="print one JSON object")
    tr.add_argument("--out", metavar="DIR", default=None,
                    help="folder for translation.png and translation.json (default: none written)")
    tr.add_argument("--plot", metavar="FILE.png", default=None, help=argparse.SUPPRESS)  # the earlier spelling
    tr.set_defaults(func=_cmd_translation)

    mp = bsub.add_parser("map", help="minimum time over a grid of targets", formatter_class=fmt)
    mp.add_argument("--y-m", dest="y", metavar="A:B:N", default=None, help="grid of Y targets [m] (required)")
    old_spelling(mp, "--y", "y")
    mp.add_argument("--z-m", dest="z", metavar="A:B:N", default=None, help="grid of Z targets [m] (required)")
    old_spelling(mp, "--z", "z")
    limits(mp)
    mp.add_argument("--json", action="store_true", help="print one JSON object")
    add_execution_options(mp)
    mp.set_defaults(func=_cmd_map)

