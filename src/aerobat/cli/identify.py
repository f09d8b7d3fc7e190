"""``aerobat identify``: fly the identification sequence on a plant, fit the model, write a vehicle file.

The run is :func:`aerobat.experiments.identify.identify` (or ``refit_session`` with
``--from-session``); this module turns options into its arguments and prints.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from aerobat.cli.common import (
    add_db_option,
    add_plant_options,
    bounded_int,
    console,
    finite_float,
    old_spelling,
    open_store,
    plant_choice_from_args,
    session_ref,
)
from aerobat.cli.sessions import refuse_overwrite
from aerobat.errors import ConfigError, IdentificationFailed

__all__ = ["register"]


def _options(args: argparse.Namespace) -> Any:
    from aerobat.quadrotor.identification import FitOptions

    return FitOptions(max_position_rms_m=args.max_position_rms_mm / 1000.0,
                      max_angle_rms_rad=math.radians(args.max_angle_rms_deg))


def _cmd_identify(args: argparse.Namespace) -> int:
    from aerobat.experiments.identify import identify, refit_session, write_identified_vehicle
    from aerobat.plotting import save_figure
    from aerobat.plotting.identification import plot_identification
    from aerobat.quadrotor.vehicle import vehicle_from_name_or_file

    if args.out is None:
        raise ConfigError("the following arguments are required: --output")
    out = Path(args.out)
    figure = Path(args.figure) if args.figure else out.with_suffix(".png")
    if figure == out:
        raise ConfigError(f"--figure {figure}: the same file as --output")
    options = _options(args)
    say = console(args.json).print
    with open_store(args) as store:
        refuse_overwrite(out, store_path=Path(store.path), force=args.force, option="--output")
        if args.from_session is not None:
            run = refit_session(store, args.from_session, options=options, name=args.name or out.stem)
            say(f"fitting session {run.session_id} of {store.path} again ({len(run.flights)} stored flights)")
        else:
            prior = vehicle_from_name_or_file(args.vehicle)
            if args.feedback not in (None, "none"):
                raise ConfigError(f"--feedback {args.feedback}: identification flies the open loop (feedback "
                                  "would hide the dynamics it measures)")
            plant = plant_choice_from_args(args)
            plant.spec.check_available()

            def on_flight(flight: Any) -> None:
                r = flight.result
                again = f" (attempt {flight.attempt})" if flight.attempt > 1 else ""
                text = "ok" if r.ok else f"{r.status.value}: {r.message}"
                say(f"  {flight.number:2d}  {flight.trial.name}{again}: {text}")

            say(f"identifying on the {plant.kind} plant (seed {plant.seed}), prior {prior.name}; "
                f"every flight goes to {store.path}")
            try:
                run = identify(plant, prior, store=store, flips=not args.no_flips,
                               max_angle_rad=math.radians(args.max_angle_deg), max_attempts=args.max_attempts,
                               max_flights=args.max_flights, options=options, on_flight=on_flight,
                               command=args.argv, name=args.name or out.stem)
            except IdentificationFailed as exc:
                raise IdentificationFailed(f"{exc} (the flights are stored in {store.path}; fly the missing trials "
                                           f"again with a new `aerobat identify`)") from None
    fit = run.fit
    assert fit is not None
    save_figure(plot_identification(fit), figure)
    if args.json:
        print(json.dumps({
            "session_id": run.session_id, "plant": run.plant.to_table(), "flights": len(run.flights),
            "notes": list(run.notes) + list(fit.notes), "parameters": fit.parameter_rows(),
            "derived": {k: {"value": v, "sigma": s} for k, (v, s) in fit.derived().items()},
            "position_rms_m": fit.position_rms_m, "angle_rms_rad": fit.angle_rms_rad,
            "acceptable": fit.acceptable, "problems": list(fit.problems),
            "out": str(out) if fit.acceptable else None, "figure": str(figure)}))
    else:
        _print_fit(run, fit)
    write_identified_vehicle(run, out)  # raises IdentificationFailed if the fit is not acceptable
    if not args.json:
        say(f"vehicle written to {out} (figure {figure}); use it with --vehicle {out}")
    return 0


def _print_fit(run: Any, fit: Any) -> None:
    from rich.table import Table

    out = console()
    table = Table(title=f"identified on {run.plant.kind} (seed {run.plant.seed}): {len(fit.trials)} trials, "
                        f"{len(run.flights)} flights")
    for name, justify in (("parameter", "left"), ("value", "right"), ("± 1σ", "right"), ("prior", "right"),
                          ("unit", "left")):
        table.add_column(name, justify=justify)  # type: ignore[arg-type]
    for row in fit.parameter_rows():
        table.add_row(row["name"], f"{row['value']:.5g}", f"{row['sigma']:.2g}" if row["fitted"] else "fixed",
                      f"{row['prior']:.5g}", row["unit"])
    out.print(table)
    derived = Table(title="the identified vehicle")
    for name in ("quantity", "value", "± 1σ"):
        derived.add_column(name, justify="left" if name == "quantity" else "right")
    for name, (value, sigma) in fit.derived().items():
        derived.add_row(name, f"{value:.5g}", f"{sigma:.2g}")
    out.print(derived)
    out.print(f"residual: {fit.position_rms_m * 1e3:.2f} mm and {math.degrees(fit.angle_rms_rad):.3f}° RMS "
              f"(scaled {fit.residual_scale:.2f}); {fit.evaluations} evaluations in {fit.wall_s:.1f} s")
    for trial in fit.trials:
        out.print(f"  {trial.trial.name}: {trial.position_rms_m * 1e3:.2f} mm, "
                  f"{math.degrees(trial.angle_rms_rad):.3f}° RMS")
    for note in list(run.notes) + list(fit.notes):
        out.print(f"note: {note}")
    for problem in fit.problems:
        out.print(f"problem: {problem}")


def register(sub: Any) -> None:
    p = sub.add_parser("identify", help="identify the nominal model of the vehicle a plant flies, write a vehicle "
                                        "file", formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    add_plant_options(p)
    p.add_argument("--output", dest="out", default=None, metavar="FILE.toml",
                   help="the identified vehicle file to write (required)")
    old_spelling(p, "--out", "out")
    p.add_argument("--vehicle", default="hummingbird",
                   help="prior: the vehicle you believe you have (preset name or vehicle TOML file); the trials are "
                        "built on it and the plant is built around it")
    p.add_argument("--figure", default=None, metavar="FILE.png",
                   help="measured against fitted responses (default: --output with .png)")
    p.add_argument("--name", default=None, help="the identified vehicle's name (default: --output's stem)")
    p.add_argument("--no-flips", action="store_true", help="leave out the two slow flips (720°/s)")
    p.add_argument("--max-angle-deg", type=finite_float(3.0, 68.0, "deg"), default=28.6,
                   help="largest attitude a rate doublet may reach")
    p.add_argument("--max-attempts", type=bounded_int(1, 10), default=2,
                   help="flights per trial when its trigger is lost, the plant stops answering or it is aborted")
    p.add_argument("--max-flights", type=bounded_int(1, 100), default=12, help="flights in all")
    p.add_argument("--max-position-rms-mm", type=finite_float(0.01, 10000.0, "mm"), default=20.0,
                   help="refuse a fit whose position residual is larger (RMS)")
    p.add_argument("--max-angle-rms-deg", type=finite_float(0.001, 170.0, "deg"), default=3.0,
                   help="refuse a fit whose attitude residual is larger (RMS)")
    p.add_argument("--from-session", metavar="SESSION", type=session_ref,
                   help="fit a stored identification session again instead of flying (id or 'last')")
    p.add_argument("--force", action="store_true", help="replace --output if it exists")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    add_db_option(p)
    p.set_defaults(func=_cmd_identify)
