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

    stream = sys.stderr if json_mode else sys.stdout
    width = None if stream.isatty() else 160  # keep tables readable in logs and pipes
    return Console(stderr=json_mode, highlight=False, markup=False, width=width)


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


# ---------------------------------------------------------- maneuvers, plants


def _maneuver_from_args(args: argparse.Namespace, config):
    import math

    from .maneuvers import MultiFlip

    if args.maneuver == "flip":
        return MultiFlip(
            vehicle=config.vehicle,
            flips=args.flips,
            max_rate_rad_s=math.radians(args.max_rate_deg_s),
            axis=args.axis,
            dims=args.dims,
            coast_collective=args.coast,
            ramp_collective_s=args.ramp_s,
        )
    if args.maneuver == "translation":
        from .maneuvers.translation import translation_maneuver

        return translation_maneuver(config, _parse_pair(args.to, "--to"), final_angle_rad=args.final_angle_rad)
    raise ValueError(f"unknown maneuver {args.maneuver!r}")


def _parse_pair(text: str, option: str) -> tuple[float, float]:
    import math

    parts = text.split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise ValueError(f"{option} {text!r}: expected two numbers Y,Z in metres") from None
    if len(values) != 2 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{option} {text!r}: expected two finite numbers Y,Z in metres")
    return values  # type: ignore[return-value]


def _plant_from_args(args: argparse.Namespace, config):
    from .plants import Arena, ArenaParams, NominalPlant, load_arena

    if args.plant == "nominal":
        return NominalPlant(config)
    if args.plant == "arena":
        params = load_arena(args.arena) if args.arena else ArenaParams()
        return Arena(config, params, seed=args.seed)
    if args.plant == "rotorpy":
        from .plants.rotorpy import RotorPyPlant

        return RotorPyPlant(config, settings_path=getattr(args, "rotorpy", None), seed=args.seed)
    raise ValueError(f"--plant {args.plant!r}: allowed nominal, arena, rotorpy")


def _design_from_args(args: argparse.Namespace, config, maneuver):
    from .design import design
    from .simulate import NominalModel

    return design(maneuver, NominalModel(config), correction=args.correction)


# ------------------------------------------------------------------ design


def _cmd_design(args: argparse.Namespace) -> int:
    from .vehicle import vehicle_from_name_or_file

    config = vehicle_from_name_or_file(args.vehicle)
    maneuver = _maneuver_from_args(args, config)
    result = _design_from_args(args, config, maneuver)
    if args.json:
        print(json.dumps(result.to_json_dict()))
    else:
        _print_design(result)
    if not result.converged:
        raise CommandFailed(result.message)
    return EXIT_OK


def _print_design(result) -> None:
    import numpy as np
    from rich.table import Table

    console = _console(False)
    m = result.maneuver
    table = Table(title=f"design: {m.name}")
    for col in ("parameter", "meaning", "unit", "guess p^g", "nominal p⁰"):
        table.add_column(col, justify="right" if "p" in col and col != "parameter" else "left")
    for spec, g, p in zip(m.parameters, result.p_guess, result.p_nominal, strict=True):
        table.add_row(spec.name, spec.description, spec.unit, f"{g:.5g}", f"{p:.5g}")
    console.print(table)
    console.print(f"status: {result.status} — {result.message}")
    console.print(f"residual norm: {result.residual_norm:.3g}   duration (ramps included): {result.duration_s:.4f} s")
    console.print(f"condition number (scaled J): {result.condition_number:.3g}   correction: {result.correction_kind}")
    console.print("singular values: " + np.array2string(result.singular_values, precision=4))
    with np.printoptions(precision=4, suppress=False, linewidth=140):
        console.print(f"J (rows: {', '.join(e.name for e in m.errors)}):\n{result.jacobian}")
        console.print(f"C:\n{result.correction}")
    console.print(f"compute time: {result.compute_s * 1000:.0f} ms")


# ------------------------------------------------------------------ learn


def _cmd_learn(args: argparse.Namespace) -> int:
    import numpy as np
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from .learning import ConstantSchedule, CorrectionRule, PaperSchedule, learn
    from .vehicle import vehicle_from_name_or_file

    if args.iterations < 1 or args.iterations > 10000:
        raise ValueError(f"--iterations {args.iterations}: allowed 1 … 10000")
    config = vehicle_from_name_or_file(args.vehicle)
    maneuver = _maneuver_from_args(args, config)
    result = _design_from_args(args, config, maneuver)
    if not result.converged:
        raise CommandFailed(f"design failed, nothing to learn: {result.message}")
    plant = _plant_from_args(args, config)
    schedule = PaperSchedule() if args.gamma == "paper" else ConstantSchedule(_gamma_value(args.gamma))
    rule = CorrectionRule(result.correction, schedule)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    console = _console(args.json)
    pos_idx = [k for k, e in enumerate(maneuver.errors) if e.unit == "m"]
    with Progress(TextColumn("[bold]learning[/bold] {task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=console, transient=True) as progress:
        task = progress.add_task(maneuver.name, total=args.iterations)

        def on_iteration(it) -> None:
            if it.status == "ok":
                progress.advance(task)
                pos = float(np.linalg.norm(it.error[pos_idx]))
                progress.console.print(f"  {it.index:3d}  ok          position error {pos:7.3f} m  γ={it.gamma:.2f}"
                                       f"  scale={it.scale:.2f}")
            else:
                progress.console.print(f"  {it.index:3d}  {it.status:10s}  {it.message}")

        session = learn(maneuver, result, plant, iterations=args.iterations, rule=rule, on_iteration=on_iteration)
    data = session.to_json_dict()
    (out / "session.json").write_text(json.dumps(data, indent=1))
    _learning_figures(session, config, out)
    if args.json:
        print(json.dumps({k: data[k] for k in ("error_names", "parameter_names", "iterations", "final_params",
                                                "status", "message", "plant")}))
    else:
        _print_session_summary(session, out)
    if session.status not in ("completed",):
        raise CommandFailed(session.message)
    return EXIT_OK


def _gamma_value(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"--gamma {text!r}: use 'paper' or a number in (0, 1]") from None
    if not 0.0 < value <= 1.0:
        raise ValueError(f"--gamma {value}: allowed (0, 1]")
    return value


def _learning_figures(session, config, out: Path) -> None:
    from .plotting import plot_learning, plot_side_views
    from .simulate import simulate

    m = session.maneuver
    nominal = simulate(m.program(session.design.p_nominal), config)
    measured = [it for it in session.iterations if it.status == "ok" and it.trial is not None]
    panels = [("nominal (model)", nominal.times_s, nominal.states)]
    if measured:
        panels.append((f"first attempt (iteration {measured[0].index})", measured[0].trial.times_s,
                       measured[0].trial.states))
        panels.append((f"learned (iteration {measured[-1].index})", measured[-1].trial.times_s,
                       measured[-1].trial.states))
    plane = "xz" if getattr(m, "axis", "roll") == "pitch" else "yz"
    target = getattr(m, "target_yz", (0.0, 0.0))
    plot_side_views(panels, out / "side_views.png", plane=plane, title=m.name, target=target)
    data = session.to_json_dict()
    plot_learning(data["iterations"], data["error_names"], data["error_units"], data["parameter_names"],
                  data["parameter_units"], out / "learning.png", title=f"{m.name} on {session.plant_name}")


def _print_session_summary(session, out: Path) -> None:
    import numpy as np
    from rich.table import Table

    m = session.maneuver
    table = Table(title=f"{m.name} on {session.plant_name}: {session.status}")
    table.add_column("i", justify="right")
    table.add_column("status")
    table.add_column("γ", justify="right")
    table.add_column("scale", justify="right")
    for e in m.errors:
        table.add_column(f"{e.name} [{'°' if e.unit == 'rad' else e.unit}]", justify="right")
    for it in session.iterations:
        cells = [
            f"{np.degrees(v):+.2f}" if spec.unit == "rad" else f"{v:+.3f}"
            for spec, v in zip(m.errors, it.error, strict=True)
        ] if it.status == "ok" else ["—"] * len(m.errors)
        table.add_row(str(it.index), it.status, f"{it.gamma:.2f}", f"{it.scale:.2f}", *cells)
    console = _console(False)
    console.print(table)
    names = [p.name for p in m.parameters]
    console.print("p⁰:      " + "  ".join(f"{n}={v:.4g}" for n, v in zip(names, session.design.p_nominal, strict=True)))
    console.print("learned: " + "  ".join(f"{n}={v:.4g}" for n, v in zip(names, session.final_params, strict=True)))
    console.print(f"{session.message}; figures and session.json in {out}/")


# ------------------------------------------------------------------ fly


def _cmd_fly(args: argparse.Namespace) -> int:
    from .program import load_program
    from .simulate import final_state_summary
    from .vehicle import vehicle_from_name_or_file

    if args.trials < 1 or args.trials > 100000:
        raise ValueError(f"--trials {args.trials}: allowed 1 … 100000")
    program = load_program(args.program)
    config = vehicle_from_name_or_file(args.vehicle)
    plant = _plant_from_args(args, config)
    trials = []
    for k in range(args.trials):
        trial = plant.fly(program)
        entry = {"status": trial.status, "message": trial.message}
        entry.update(final_state_summary(trial.final_state, program.duration_s) if trial.ok else
                     {"final_state": None})
        trials.append(entry)
        if not args.json:
            _print_trial(k + 1, entry)
        if args.plot and k == 0 and trial.states.shape[0]:
            from .plotting import plot_side_views

            plot_side_views([("trial 1", trial.times_s, trial.states)], args.plot, title=str(args.program))
    if args.json:
        print(json.dumps({"trials": trials}))
    return EXIT_OK


def _print_trial(k: int, entry: dict[str, Any]) -> None:
    import math

    if entry["final_state"] is None:
        print(f"trial {k}: {entry['status']}: {entry['message']}")
        return
    fs = entry["final_state"]
    pos = ", ".join(f"{v:+.3f}" for v in fs["position_m"])
    vel = ", ".join(f"{v:+.3f}" for v in fs["velocity_m_s"])
    ang = ", ".join(f"{math.degrees(v):+.1f}" for v in fs["rotation_angle_rad"])
    print(f"trial {k}: ok  position [{pos}] m  velocity [{vel}] m/s  rotation [{ang}] °")


def _add_flip_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("maneuver", choices=("flip", "translation"), help="maneuver family")
    p.add_argument("--flips", type=int, default=3, help="number of flips c_N (flip)")
    p.add_argument("--max-rate-deg-s", type=float, default=1800.0, help="coast rate c_pmax [deg/s] (flip)")
    p.add_argument("--dims", type=int, choices=(2, 3), default=3, help="2D (5 parameters) or 3D (9)")
    p.add_argument("--axis", choices=("roll", "pitch"), default="roll")
    p.add_argument("--coast", choices=("min", "max"), default="min", help="coast collective β̲ or β̄")
    p.add_argument("--ramp-s", type=float, default=0.1, help="thrust ramp-down duration [s]")
    p.add_argument("--to", default="5,5", help="target Y,Z [m] (translation)")
    p.add_argument("--final-angle-rad", type=float, default=0.0, help="final roll angle (translation)")
    p.add_argument("--vehicle", default="hummingbird", help="preset name or vehicle TOML file")
    p.add_argument("--correction", choices=("tsvd", "inverse", "damped"), default="tsvd",
                   help="right inverse used for C (default tsvd, see docs/results.md)")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _add_plant_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--plant", choices=("nominal", "arena", "rotorpy"), default="arena")
    p.add_argument("--arena", metavar="FILE.toml", help="arena configuration")
    p.add_argument("--rotorpy", metavar="FILE.toml", help="RotorPy parameter overrides")
    p.add_argument("--seed", type=int, default=0, help="seed of the plant's random generator")


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

    des = sub.add_parser("design", help="nominal design: p⁰, J, C")
    _add_flip_options(des)
    des.set_defaults(func=_cmd_design)

    lrn = sub.add_parser("learn", help="design, then learn on a plant")
    _add_flip_options(lrn)
    _add_plant_options(lrn)
    lrn.add_argument("--iterations", type=int, default=30, help="measured iterations")
    lrn.add_argument("--gamma", default="paper", help="'paper' (max(1/i, 0.1)) or a constant in (0, 1]")
    lrn.add_argument("--out", default="out/learn", help="directory for figures and session.json")
    lrn.set_defaults(func=_cmd_learn)

    fly = sub.add_parser("fly", help="fly a program on a plant")
    fly.add_argument("program", help="program TOML file")
    fly.add_argument("--vehicle", default="hummingbird")
    _add_plant_options(fly)
    fly.add_argument("--trials", type=int, default=1)
    fly.add_argument("--json", action="store_true")
    fly.add_argument("--plot", metavar="FILE.png")
    fly.set_defaults(func=_cmd_fly)

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
