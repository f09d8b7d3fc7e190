"""``aerobat simulate`` (a program on the nominal model) and ``aerobat fly`` (a program on a plant)."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from aerobat.cli.common import (
    CommandFailed,
    HelpFormatter,
    add_plant_options,
    bounded_int,
    check_plot_files,
    console,
    plant_choice_from_args,
)
from aerobat.core.bounds import choices_of
from aerobat.errors import ConfigError, DesignFailed
from aerobat.quadrotor.simulate import Mode

__all__ = ["register"]


def _cmd_simulate(args: argparse.Namespace) -> int:
    from aerobat.plotting import save_figure, write_text
    from aerobat.plotting.vehicle import plot_trajectory
    from aerobat.quadrotor.program import load_program
    from aerobat.quadrotor.simulate import final_state_summary, simulate
    from aerobat.quadrotor.vehicle import vehicle_from_name_or_file

    program = load_program(args.program)
    config = vehicle_from_name_or_file(args.vehicle)
    folder = check_plot_files(args, ("trajectory.png", "simulation.json"))
    traj = simulate(program, config, mode=args.mode)
    if not np.all(np.isfinite(traj.final_state)):
        raise CommandFailed("simulation produced non-finite states")
    summary = final_state_summary(traj.final_state, traj.duration_s)
    figure = None
    if folder is not None or args.plot:
        figure = save_figure(plot_trajectory(traj.times_s, traj.states, traj.commands,
                                             title=f"{program.name or Path(args.program).stem} on {config.name}"),
                             folder / "trajectory.png" if folder is not None else args.plot)
    if folder is not None:
        write_text(folder / "simulation.json", json.dumps(summary, indent=1))
    if args.json:
        print(json.dumps(summary))
    else:
        _print_state_table(summary, title=f"{args.program} on {config.name} ({args.mode})")
        if figure is not None:
            print(f"figure written to {figure}")
    return 0


def _print_state_table(summary: dict[str, Any], *, title: str) -> None:
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
    console().print(table)
    print(f"duration: {summary['duration_s']:.4f} s")


def _cmd_fly(args: argparse.Namespace) -> int:
    from aerobat.plotting import save_figure, write_text
    from aerobat.plotting.vehicle import plot_side_views
    from aerobat.quadrotor.program import load_program
    from aerobat.quadrotor.simulate import final_state_summary
    from aerobat.quadrotor.vehicle import vehicle_from_name_or_file

    config = vehicle_from_name_or_file(args.vehicle)
    if (args.program is None) == (args.maneuver_source is None):
        raise ConfigError("fly: give a program file, or --maneuver FILE.toml|package.module:Name (its nominal "
                          "design is flown), not both")
    if args.program is not None:
        program = load_program(args.program)
    else:
        from aerobat.cli.common import maneuver_from_args
        from aerobat.experiments.designing import nominal_design

        args.maneuver = None
        maneuver = maneuver_from_args(args, config)
        nominal = nominal_design(maneuver, config, plant=plant_choice_from_args(args), design_model=args.design_model)
        if not nominal.design.converged:
            raise DesignFailed(f"design failed on the {nominal.model.value} model, nothing to fly: "
                               f"{nominal.design.message}", nominal.design)
        if not args.json:
            print(f"flying the nominal design p⁰ of the {nominal.model.value} model ({nominal.description})")
        program = maneuver.program(nominal.design.p_nominal)
    folder = check_plot_files(args, ("trials.png", "trials.json"))
    choice = plant_choice_from_args(args)
    plant = choice.build(config)
    trials = []
    panels: list[tuple[str, np.ndarray, np.ndarray]] = []
    for k in range(args.trials):
        trial = plant.fly(program)
        entry: dict[str, Any] = {"status": trial.status.value, "message": trial.message}
        entry.update(final_state_summary(trial.final_state, program.duration_s) if trial.ok else
                     {"final_state": None})
        trials.append(entry)
        if not args.json:
            _print_trial(k + 1, entry)
        if (folder is not None or args.plot) and trial.states.shape[0] and len(panels) < 6:
            panels.append((f"trial {k + 1}", trial.times_s, trial.states))
    figure = None
    if panels:
        # a program names no desired final position: none is drawn (the origin would be wrong for a translation)
        figure = save_figure(plot_side_views(panels, title=f"{program.name or args.program}, "
                                             f"{_loop_words(choice)}", target=None),
                             folder / "trials.png" if folder is not None else args.plot, dpi=130)
    ok = [t for t in trials if t["final_state"] is not None]
    stats = _statistics(ok)
    if folder is not None:
        write_text(folder / "trials.json", json.dumps({"trials": trials, "statistics": stats}, indent=1))
    if args.json:
        print(json.dumps({"trials": trials, "statistics": stats}))
    elif stats:
        mean, std = stats["position_m"]["mean"], stats["position_m"]["std"]
        print(f"{len(ok)} of {len(trials)} trials measured; final position mean "
              f"[{', '.join(f'{v:+.3f}' for v in mean)}] m, spread (std) [{', '.join(f'{v:.3f}' for v in std)}] m")
    if figure is not None and not args.json:
        print(f"figure written to {figure}")
    if not ok:
        raise CommandFailed(f"no trial of {len(trials)} was measured")
    return 0


def _statistics(entries: list[dict[str, Any]]) -> dict[str, Any]:
    if not entries:
        return {}
    out = {}
    for key in ("position_m", "velocity_m_s", "rotation_angle_rad"):
        values = np.array([e["final_state"][key] for e in entries], dtype=float)
        out[key] = {"mean": values.mean(axis=0).tolist(), "std": values.std(axis=0).tolist()}
    return out


def _loop_words(choice: Any) -> str:
    """``open loop`` or ``tracking feedback``, for a figure's title."""
    scheme = choice.feedback.scheme.value
    return "open loop" if scheme == "none" else f"{scheme} feedback"


def _print_trial(k: int, entry: dict[str, Any]) -> None:
    if entry["final_state"] is None:
        print(f"trial {k}: {entry['status']}: {entry['message']}")
        return
    fs = entry["final_state"]
    pos = ", ".join(f"{v:+.3f}" for v in fs["position_m"])
    vel = ", ".join(f"{v:+.3f}" for v in fs["velocity_m_s"])
    ang = ", ".join(f"{math.degrees(v):+.1f}" for v in fs["rotation_angle_rad"])
    print(f"trial {k}: ok  position [{pos}] m  velocity [{vel}] m/s  rotation [{ang}] °")


def register(sub: Any) -> None:
    sim = sub.add_parser("simulate", help="play a program on the nominal model",
                         formatter_class=HelpFormatter)
    sim.add_argument("program", help="program TOML file (required)")
    sim.add_argument("--vehicle", default="hummingbird", help="preset name or vehicle TOML file")
    sim.add_argument("--mode", choices=choices_of(Mode), default="continuous",
                     help="continuous-time model or 800 Hz onboard zero-order hold")
    sim.add_argument("--out", metavar="DIR", default=None,
                     help="folder for trajectory.png and simulation.json (default: none written)")
    sim.add_argument("--plot", metavar="FILE.png", default=None, help=argparse.SUPPRESS)  # the earlier spelling
    sim.add_argument("--json", action="store_true", help="print one JSON object")
    sim.set_defaults(func=_cmd_simulate)

    fly = sub.add_parser("fly", help="fly a program on a plant", formatter_class=HelpFormatter)
    fly.add_argument("program", nargs="?", help="program TOML file (required unless --maneuver)")
    fly.add_argument("--maneuver", dest="maneuver_source", metavar="FILE.toml|package.module:Name", default=None,
                     help="fly this maneuver's nominal design instead of a program file (default: none)")
    fly.add_argument("--vehicle", default="hummingbird", help="design vehicle: preset name or vehicle TOML file")
    add_plant_options(fly)
    fly.add_argument("--trials", type=bounded_int(1, 100000), default=1, help="how many times to fly it")
    fly.add_argument("--json", action="store_true", help="print one JSON object")
    fly.add_argument("--out", metavar="DIR", default=None,
                     help="folder for trials.png (side views of up to 6 trials) and trials.json "
                          "(default: none written)")
    fly.add_argument("--plot", metavar="FILE.png", default=None, help=argparse.SUPPRESS)  # the earlier spelling
    fly.set_defaults(func=_cmd_fly)
