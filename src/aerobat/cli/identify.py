"""``aerobat identify``: fly the identification sequence on a plant, fit the model, write a vehicle file.

The run is :func:`aerobat.experiments.identify.identify` (or ``refit_session`` with
``--from-session``); this module turns options into its arguments and prints.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path
from typing import Any

from aerobat.cli.common import (
    HelpFormatter,
    add_db_option,
    add_plant_options,
    bounded_int,
    console,
    finite_float,
    old_spelling,
    open_store,
    plant_choice_from_args,
    refuse_overwrite,
    session_ref,
    text_path,
)
from aerobat.cli.json_output import json_text
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
    # every file identify writes is checked before anything flies or is stored (issue 31 D3, E2, I4): never a
    # store (whatever the links), never an existing file without --force, never a place nothing can be created
    store_path = Path(args.db) if getattr(args, "db", None) else None
    out = Path(text_path(args.out, "--output"))
    refuse_overwrite(out, store_path=store_path, force=args.force, option="--output")
    try:
        figure = Path(text_path(args.figure, "--figure")) if args.figure is not None else out.with_suffix(".png")
    except ValueError:
        raise ConfigError(f"--output {out}: not a file name; expected FILE.toml") from None
    if figure == out:
        raise ConfigError(f"--figure {figure}: the same file as --output")
    refuse_overwrite(figure, store_path=store_path, force=args.force, option="--figure")
    if not out.stem:
        raise ConfigError(f"--output {out}: not a file name; expected FILE.toml")
    if args.log:
        return _cmd_identify_log(args, out, figure)
    if args.airframe is not None:  # it was ignored, unchecked, while the flights ran
        raise ConfigError("--airframe applies only with --log (it writes the [airframe] a log's fit gives)")
    options = _options(args)
    say = console(args.json).print
    with open_store(args) as store:
        refuse_overwrite(out, store_path=Path(store.path), force=args.force, option="--output")
        if args.from_session is not None:
            run = refit_session(store, args.from_session, options=options, name=args.name or out.stem)
            say(f"fitting session {run.session_id} of {store.path} again ({len(run.flights)} stored flights)")
        else:
            prior = vehicle_from_name_or_file(args.vehicle or "hummingbird")
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
                               design_model=args.design_model,
                               command=args.argv, name=args.name or out.stem)
            except IdentificationFailed as exc:
                raise IdentificationFailed(f"{exc} (the flights are stored in {store.path}; fly the missing trials "
                                           f"again with a new `aerobat identify`)") from None
    fit = run.fit
    assert fit is not None
    save_figure(plot_identification(fit), figure)
    if args.json:
        print(json_text({
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


def _geometry(args: argparse.Namespace, prior: Any) -> Any:
    from aerobat.quadrotor.identification.logfit import Geometry

    v = prior.vehicle
    half = v.arm_length_m / math.sqrt(2.0)
    return Geometry(mass_kg=args.mass_kg if args.mass_kg is not None else v.mass_kg,
                    motor_x_m=args.motor_x_m if args.motor_x_m is not None else half,
                    motor_y_m=args.motor_y_m if args.motor_y_m is not None else half,
                    inertia_zz_ratio=v.inertia_zz_kg_m2 / (v.inertia_xx_kg_m2 + v.inertia_yy_kg_m2))


def _cmd_identify_log(args: argparse.Namespace, out: Path, figure: Path) -> int:
    """``identify --log FILE[:N] …``: fit the vehicle the logs flew, validate on the file's other logs."""
    import tomli_w

    from aerobat.experiments.log_identify import (
        airframe_from_log_fit,
        airframe_notes,
        identification_warnings,
        identify_from_logs,
        parse_log_ref,
        prior_for_log,
        vehicle_from_log_fit,
    )
    from aerobat.plotting import save_figure, write_text
    from aerobat.plotting.flightlog import plot_log_fit
    from aerobat.quadrotor.vehicle import save_vehicle, vehicle_from_name_or_file

    refs = [parse_log_ref(text) for text in args.log]
    if args.airframe is not None:
        refuse_overwrite(Path(text_path(args.airframe, "--airframe")), store_path=None, force=args.force,
                         option="--airframe")
    if args.vehicle is None:  # the prior from the log's firmware, said (issue 44: a 5-inch fitted as a Hummingbird)
        name, why = prior_for_log(refs[0].path)
        chosen = f"{name}, chosen for {why}; --vehicle names yours"
    else:
        name, chosen = args.vehicle, "--vehicle"
    prior = vehicle_from_name_or_file(name)
    geometry = _geometry(args, prior)
    say = console(args.json).print

    def starting() -> None:
        # only once the logs are read and fit to identify, so that a refusal is the only line; and not with --json,
        # whose object says it all: stderr then carries nothing but a failure's one line
        if not args.json:
            say(f"identifying from {', '.join(str(r) for r in refs)}: mass {geometry.mass_kg:g} kg, motors at "
                f"(±{geometry.motor_x_m:g}, ±{geometry.motor_y_m:g}) m, prior {prior.name} ({chosen})")

    window = tuple(args.window_s) if args.window_s else None
    result = identify_from_logs(refs, geometry, before_fit=starting, prior=prior, window_s=window)
    fit = result.fit
    config = vehicle_from_log_fit(fit, prior, name=args.name or out.stem, idle_command=result.idle_command)
    save_vehicle(config, out, header=f"identified by aerobat identify --log from {fit.name} around the prior "
                                     f"{prior.name} (mass and motor positions given or the prior's, not identified)")
    save_figure(plot_log_fit(fit, result.prepared[0]), figure)
    warnings = identification_warnings(fit, prior)
    airframe = None
    battery = result.battery
    vibration = result.vibration
    if args.airframe:
        airframe = airframe_from_log_fit(fit, battery_reference_v=result.battery_reference_v, battery=battery)
        # the pilot flies with the mass the user gave, as a pilot who weighed the quad would
        pilot = {"vehicle_mass_kg": airframe["mass_kg"]}
        write_text(args.airframe, f"# [airframe] of the Betaflight plant from {fit.name} (prior {prior.name})\n"
                                  + "".join(f"# {line}\n" for line in airframe_notes(fit))
                                  + "".join(f"# CHECK: {line}\n" for line in [*result.excitation_notes, *warnings])
                                  + _vibration_comment(vibration)
                                  + tomli_w.dumps({"airframe": airframe, "pilot": pilot}))
    if args.json:
        print(json_text({
            "logs": list(result.fitted), "values": {k: {"value": v, "sigma": s, "unit": u}
                                                    for k, (v, s, u) in fit.values.items()},
            "holdout": [m.__dict__ for m in fit.holdout_metrics], "fit": [m.__dict__ for m in fit.fit_metrics],
            "validation": {name: (v if isinstance(v, str) else [m.__dict__ for m in v])
                           for name, v in result.validations},
            "fit_segments_s": fit.fit_segments_s, "holdout_segments_s": fit.holdout_segments_s,
            "notes": list(fit.notes), "warnings": warnings, "prior": prior.name, "wall_s": fit.wall_s,
            "excitation_deg_s": dict(zip(("roll", "pitch", "yaw"), result.excitation.rms_deg_s, strict=True)),
            "battery": None if battery is None else dataclasses.asdict(battery),
            "vibration": None if vibration is None else dataclasses.asdict(vibration),
            "out": str(out), "figure": str(figure), "airframe": args.airframe}))
        return 0
    _print_log_fit(result)
    say(battery.describe() if battery is not None else "battery: not identified (the logs record no voltage, or too "
                                                        "little flight)", highlight=False)
    if vibration is not None:
        say(vibration.describe(), highlight=False)
    for line in warnings:
        say(f"check: {line}")
    say(f"vehicle written to {out} (figure {figure}" + (f", airframe {args.airframe}" if args.airframe else "") +
        f"); use it with --vehicle {out}")
    return 0


def _print_log_fit(result: Any) -> None:
    from rich.table import Table

    fit = result.fit
    out = console()
    table = Table(title=f"identified from {fit.name}: {sum(b - a for a, b in fit.fit_segments_s):.1f} s fitted, "
                        f"{sum(b - a for a, b in fit.holdout_segments_s):.1f} s held out")
    for name, justify in (("quantity", "left"), ("value", "right"), ("± 1σ", "right"), ("unit", "left")):
        table.add_column(name, justify=justify)  # type: ignore[arg-type]
    for name, (value, sigma, unit) in fit.values.items():
        table.add_row(name, f"{value:.5g}", "fixed" if sigma != sigma else f"{sigma:.2g}", unit)
    out.print(table)
    check = Table(title="prediction (R² / correlation)")
    check.add_column("flight", overflow="fold", min_width=24)  # whole names: log 2 and log 3 differ at the end
    for m in fit.holdout_metrics:
        check.add_column(m.channel, justify="right")
    check.add_row("held-out blocks", *[f"{m.r2:.2f} / {m.correlation:.2f}" for m in fit.holdout_metrics])
    for name, metrics in result.validations:
        if isinstance(metrics, str):
            check.add_row(name, metrics, "", "", "")
        else:
            check.add_row(name, *[f"{m.r2:.2f} / {m.correlation:.2f}" for m in metrics])
    out.print(check)
    out.print(f"{fit.evaluations} model evaluations in {fit.wall_s:.1f} s")
    for note in fit.notes:
        out.print(f"note: {note}", highlight=False)


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
                                        "file", formatter_class=HelpFormatter)
    p.add_argument("--output", dest="out", default=None, metavar="FILE.toml",
                   help="the identified vehicle file to write (required)")
    old_spelling(p, "--out", "out")
    p.add_argument("--vehicle", default=None,
                   help="prior: the vehicle you believe you have (preset name or vehicle TOML file); the trials are "
                        "built on it and the plant is built around it (default: hummingbird when flying; with --log "
                        "the preset of the log's firmware, said: fpv5 for Betaflight, crazyflie21 for a Crazyflie)")
    p.add_argument("--figure", default=None, metavar="FILE.png",
                   help="measured against fitted responses (default: --output with .png)")
    p.add_argument("--name", default=None, help="the identified vehicle's name (default: --output's stem)")
    p.add_argument("--force", action="store_true", help="replace --output if it exists")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    fly = p.add_argument_group("flying the identification sequence (the default)")
    add_plant_options(fly, feedback=False)  # identification always flies the open loop
    fly.add_argument("--no-flips", action="store_true", help="leave out the two slow flips (720°/s)")
    fly.add_argument("--max-angle-deg", type=finite_float(3.0, 68.0, "deg"), default=math.degrees(0.5),
                     help="largest attitude a rate doublet may reach (default: 28.6, that is 0.5 rad)")
    fly.add_argument("--max-attempts", type=bounded_int(1, 10), default=2,
                     help="flights per trial when its trigger is lost, the plant stops answering or it is aborted")
    fly.add_argument("--max-flights", type=bounded_int(1, 100), default=12, help="flights in all")
    logs = p.add_argument_group("from real flight logs instead (--log)")
    logs.add_argument("--log", metavar="FILE[:N]", action="append", default=None,
                      help="identify from real flight logs instead of flying: a blackbox, ULog or Crazyflie file, or "
                           "log N of it; repeat to fit several together, the file's other logs validate "
                           "(default: fly the sequence)")
    logs.add_argument("--mass-kg", type=finite_float(0.005, 50.0, "kg"), default=None, metavar="KG",
                      help="with --log: take-off mass (default: the prior's)")
    logs.add_argument("--motor-x-m", type=finite_float(0.005, 2.0, "m"), default=None, metavar="M",
                      help="with --log: motor distance from the centre along x (default: the prior's arm / √2)")
    logs.add_argument("--motor-y-m", type=finite_float(0.005, 2.0, "m"), default=None, metavar="M",
                      help="with --log: motor distance from the centre along y (default: the prior's arm / √2)")
    logs.add_argument("--airframe", metavar="FILE.toml", default=None,
                      help="with --log: also write the Betaflight plant's [airframe] section (default: not written)")
    logs.add_argument("--window-s", nargs=2, type=finite_float(0.0, 1e6, "s"), metavar=("START", "END"),
                      default=None,
                      help="with --log: fit only this window of each log named [s], e.g. its first half, and "
                           "validate on the rest of it too (default: whole logs)")
    fit = p.add_argument_group("the fit")
    fit.add_argument("--max-position-rms-mm", type=finite_float(0.01, 10000.0, "mm"), default=20.0,
                     help="refuse a fit whose position residual is larger (RMS)")
    fit.add_argument("--max-angle-rms-deg", type=finite_float(0.001, 170.0, "deg"), default=3.0,
                     help="refuse a fit whose attitude residual is larger (RMS)")
    fit.add_argument("--from-session", metavar="SESSION", type=session_ref,
                     help="fit a stored identification session again instead of flying: an id or 'last' (default: fly)")
    add_db_option(p)
    p.set_defaults(func=_cmd_identify)


def _vibration_comment(vibration: Any) -> str:
    """The identified vibration as [airframe] lines to copy in, commented out: not flown unless the user does."""
    if vibration is None:
        return ""
    import tomli_w

    lines = tomli_w.dumps(vibration.airframe_fields()).splitlines()
    return ("# vibration, identified from the log's unfiltered gyro; not flown unless these lines are moved under\n"
            "# [airframe] (the thrust coefficient also sets the rotors' reaction torque):\n"
            + "".join(f"#   {line}\n" for line in lines if line.strip()))
