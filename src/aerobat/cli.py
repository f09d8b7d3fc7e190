"""The ``aerobat`` command.

Every command turns bad input into a one-line ``aerobat: error: …`` message and
exit status 2 (``--debug`` shows the traceback instead); a solver or plant that
fails exits with status 1 and says why.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from .config import ConfigError

__all__ = ["main"]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2


class CommandFailed(RuntimeError):
    """A command ran but its result is a failure (non-converged solve, crashed plant…)."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, documented exit code
        self.exit(EXIT_USAGE, f"aerobat: error: {message}\n")


def _console(json_mode: bool):
    from rich.console import Console

    return Console(stderr=json_mode, highlight=False)


# ------------------------------------------------------------------ simulate


def _cmd_simulate(args: argparse.Namespace) -> int:
    import numpy as np

    from .program import load_program
    from .simulate import final_state_summary, simulate
    from .vehicle import vehicle_from_name_or_file

    program = load_program(args.program)
    config = vehicle_from_name_or_file(args.vehicle)
    traj = simulate(program, config, mode=args.mode)
    if not np.all(np.isfinite(traj.final_state)):
        raise CommandFailed("simulation produced non-finite states")
    summary = final_state_summary(traj.final_state, traj.duration_s)
    if args.plot:
        from .plotting import plot_trajectory

        plot_trajectory(traj.times_s, traj.states, traj.commands, args.plot,
                        title=f"{program.name or Path(args.program).stem} on {config.name}")
    if args.json:
        print(json.dumps(summary))
    else:
        _print_state_table(summary, title=f"{args.program} on {config.name} ({args.mode})")
        if args.plot:
            print(f"plot written to {args.plot}")
    return EXIT_OK


def _print_state_table(summary: dict[str, Any], *, title: str) -> None:
    import math

    from rich.table import Table

    fs = summary["final_state"]
    table = Table(title=title)
    table.add_column("quantity")
    for axis in ("x / φ", "y / θ", "z / ψ"):
        table.add_column(axis, justify="right")
    table.add_row("position [m]", *(f"{v:+.4f}" for v in fs["position_m"]))
    table.add_row("velocity [m/s]", *(f"{v:+.4f}" for v in fs["velocity_m_s"]))
    table.add_row("Euler ZYX [°]", *(f"{math.degrees(v):+.2f}" for v in fs["euler_zyx_rad"]))
    table.add_row("rotation, unwrapped [°]", *(f"{math.degrees(v):+.2f}" for v in fs["rotation_angle_rad"]))
    _console(False).print(table)
    print(f"duration: {summary['duration_s']:.4f} s")


# ----------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="aerobat", description="Design and learn fast open-loop quadrocopter maneuvers.")
    parser.add_argument("--debug", action="store_true", help="show tracebacks for errors")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    sim = sub.add_parser("simulate", help="play a program on the nominal model")
    sim.add_argument("program", help="program TOML file")
    sim.add_argument("--vehicle", default="hummingbird", help="preset name or vehicle TOML file")
    sim.add_argument("--mode", choices=("continuous", "sampled"), default="continuous",
                     help="continuous-time model or 800 Hz onboard zero-order hold")
    sim.add_argument("--plot", metavar="FILE.png", help="write a figure")
    sim.add_argument("--json", action="store_true", help="print one JSON object")
    sim.set_defaults(func=_cmd_simulate)

    for register in _EXTRA_COMMANDS:
        register(sub)
    return parser


# Later modules register their commands here (kept in one list so `aerobat --help` shows all).
_EXTRA_COMMANDS: list[Callable[[Any], None]] = []


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except KeyboardInterrupt:
        print("aerobat: interrupted", file=sys.stderr)
        return 130
    except (ConfigError, ValueError, FileNotFoundError, IsADirectoryError, PermissionError, OSError) as exc:
        if args.debug:
            raise
        print(f"aerobat: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except CommandFailed as exc:
        if args.debug:
            raise
        print(f"aerobat: failed: {exc}", file=sys.stderr)
        return EXIT_FAILED


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
