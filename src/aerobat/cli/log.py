"""``aerobat log info|plot|export FILE``: what a real flight log holds, as figures and as CSV."""

from __future__ import annotations

import argparse
import csv
import io
from collections.abc import Callable
from pathlib import Path
from typing import Any

from aerobat.cli.common import (
    HelpFormatter,
    bounded_int,
    console,
    finite_float,
    output_dir,
    refuse_overwrite,
)
from aerobat.cli.json_output import json_text
from aerobat.errors import ConfigError

__all__ = ["log_summary", "register"]


def _named(args: argparse.Namespace) -> None:
    """``FILE:N`` as ``FILE`` and ``--index N`` (the one way every command names a log in a file)."""
    from aerobat.logs import parse_log_ref

    ref = parse_log_ref(args.file).with_index(args.index)
    args.file, args.index = str(ref.path), ref.index


def _logs(args: argparse.Namespace) -> list[Any]:
    from aerobat.logs import read_logs

    _named(args)
    logs = read_logs(args.file)
    if getattr(args, "index", None) is not None:
        if args.index > len(logs):
            raise ConfigError(f"{args.file}: log {args.index} does not exist; the file holds {len(logs)} "
                              f"log{'s' if len(logs) != 1 else ''}")
        return [logs[args.index - 1]]
    return logs


_TUNE_KEYS = ("rollPID", "pitchPID", "yawPID", "rates_type", "rc_rates", "rates", "rc_expo", "feedforward_weight",
              "looptime", "pid_process_denom", "gyro_lowpass_hz", "dterm_lowpass_hz", "dshot_idle_value",
              "motorOutput", "MC_ROLLRATE_P", "MC_PITCHRATE_P", "MC_YAWRATE_P", "MPC_THR_HOVER", "MAV_TYPE",
              "SYS_AUTOSTART", "event")


def log_summary(log: Any) -> dict[str, Any]:
    """One log as a JSON-ready table: durations, rates, fields, firmware and a tune summary."""
    meta = log.metadata
    return {
        "file": str(log.path), "index": log.index, "logs_in_file": log.logs_in_file,
        "source": log.source.firmware, "format": log.source.value,
        "duration_s": round(log.duration_s, 3),
        "firmware": meta.firmware, "firmware_version": meta.firmware_version, "board": meta.board,
        "craft_name": meta.craft_name, "vehicle_type": meta.vehicle_type, "start_time": meta.start_time,
        "signals": {ch.value: {"samples": s.samples, "rate_hz": round(s.rate_hz, 1), "unit": s.unit,
                               "columns": list(s.columns), "from": list(s.source_fields)}
                    for ch, s in log.signals.items()},
        "motor_layout": log.motor_layout.mixer if log.motor_layout else None,
        "tune": {k: meta.parameters[k] for k in _TUNE_KEYS if k in meta.parameters},
        "parameters": len(meta.parameters),
        "notes": list(log.notes),
    }


def _cmd_info(args: argparse.Namespace) -> int:
    summaries = [log_summary(log) for log in _logs(args)]
    if args.json:
        print(json_text({"file": str(args.file), "logs": summaries}))
        return 0
    say = console().print
    say(f"{args.file}: {len(summaries)} log{'s' if len(summaries) != 1 else ''}")
    for s in summaries:
        who = " ".join(x for x in (s["firmware"], s["firmware_version"], s["board"], repr(s["craft_name"])
                                   if s["craft_name"] else "") if x)
        say(f"  log {s['index']}: {s['duration_s']:.1f} s, {s['source']} ({who}), {s['vehicle_type']}, "
            f"motors: {s['motor_layout'] or 'no layout'}")
        for name, sig in s["signals"].items():
            say(f"      {name:16s} {sig['samples']:7d} samples at {sig['rate_hz']:7.1f} Hz  [{sig['unit']}]  "
                f"{', '.join(sig['from'])}")
        if s["tune"]:
            say("      tune: " + "; ".join(f"{k} {v}" for k, v in s["tune"].items()))
        say(f"      {s['parameters']} header fields / parameters kept")
        for note in s["notes"]:
            say(f"      note: {note}")
    return 0


def _cmd_plot(args: argparse.Namespace) -> int:
    from aerobat.plotting import save_figure
    from aerobat.plotting.flightlog import (
        plot_log_pid,
        plot_log_spectra,
        plot_log_spectrogram,
        plot_log_step_response,
        plot_log_traces,
    )

    logs = _logs(args)
    out = Path(args.out) if args.out else Path("out") / f"log-{Path(args.file).name}"
    out = output_dir(out)
    window = tuple(args.window_s) if args.window_s else None
    say = console(args.json).print
    written = []
    for log in logs:
        stem = f"log{log.index}"
        figures = (("traces", plot_log_traces, "needs a gyro"), ("pid", plot_log_pid, "the log has no PID terms"),
                   ("spectra", plot_log_spectra, ""),
                   ("spectrogram", plot_log_spectrogram,
                    "needs a gyro and a throttle over at least one 128-sample segment"),
                   ("step_response", plot_log_step_response, "needs a rate set point and a gyro"))
        for suffix, draw, missing in figures:
            path = out / f"{stem}_{suffix}.png"
            refuse_overwrite(path, store_path=None, force=args.force, option="--out")
            figure = draw(log, window_s=window)
            if figure is None:
                say(f"log {log.index}: no {suffix.replace('_', ' ')} figure: {missing}")
                continue
            save_figure(figure, path)  # one figure at a time: each is let go once written
            written.append(str(path))
            say(f"wrote {path}")
    if args.json:
        print(json_text({"figures": written}))
    return 0


def _what_if(args: argparse.Namespace, params: Any, source: str, out: Path, window: Any, progress: Any) -> int:
    """``log replay FILE --tune OTHER --set NAME=VALUE``: the logged sticks with the log's tune and the other."""
    import sys

    from aerobat.experiments.log_replay import AXES
    from aerobat.experiments.log_whatif import what_if
    from aerobat.plotting import save_figure
    from aerobat.plotting.log_replay import plot_what_if

    say = console(args.json).print
    tune = None
    if args.tune is not None:
        from aerobat.cli.tune_options import read_tune

        tune = read_tune(args.tune, option="--tune FILE:N")[0].tune  # checked as the firmware would be
    result = what_if(args.file, tune=tune, changes=tuple(args.set or ()), window_s=window, params=params,
                     airframe_source=source, step_min_deg_s=args.step_min_deg_s, seed=args.seed, progress=progress)
    if sys.stderr.isatty():
        print(file=sys.stderr)
    lo, hi = result.flown.window_s
    figure = out / f"{result.flown.log.replace('#', '-log')}_{lo:g}-{hi:g}s_whatif.png"
    refuse_overwrite(figure, store_path=None, force=args.force, option="--out")
    save_figure(plot_what_if(result), figure)
    if args.json:
        print(json_text({**result.summary(), "figure": str(figure)}))
        return 0
    say(f"{result.flown.log} {lo:g}–{hi:g} s: the logged sticks through Betaflight 4.6 SITL with the log's own tune "
        f"and with {result.what_if_source}; airframe: {source}", highlight=False)
    if result.differences:
        say("  settings that differ, as the firmware runs them (the log's → the what-if): " + "; ".join(
            f"{d.name} {d.flown} → {d.what_if}" for d in result.differences), highlight=False)
    else:
        say("  no setting differs: the what-if flies the log's own tune", highlight=False)
    names = " / ".join(r.name for r in result.readings)
    say(f"  per axis, {names}:", highlight=False)

    def ms(v: float) -> str:
        return f"{1e3 * v:.0f}" if v == v else "—"

    def pct(v: float) -> str:
        return f"{100 * v:.0f}" if v == v else "—"

    for k, axis in enumerate(AXES):
        a = [r.axes[k] for r in result.readings]
        say(f"  {axis:5s} step response: 50 % at {' / '.join(ms(x.delay_s) for x in a)} ms, rise "
            f"{' / '.join(ms(x.rise_s) for x in a)} ms, overshoot {' / '.join(pct(x.overshoot) for x in a)} %; "
            f"{a[0].steps} set-point steps: rise {' / '.join(ms(x.step_rise_s) for x in a)} ms; tracking error rms "
            f"{' / '.join(f'{x.tracking_rms_deg_s:.1f}' for x in a)} deg/s", highlight=False)
    say(f"  motors: at >= 99 % {' / '.join(f'{100 * r.saturated_fraction:.1f}' for r in result.readings)} % of the "
        f"time; noise above 20 Hz {' / '.join(f'{100 * r.motor_noise_rms:.2f}' for r in result.readings)} % rms",
        highlight=False)
    say("  the sticks are the logged ones: a pilot would have flown the other tune differently", highlight=False)
    say(f"wrote {figure}", highlight=False)
    return 0


#: Rows of CSV made at a time: the export streams, never holding the log's text (or a copy of its table) whole.
CSV_BLOCK_ROWS = 20_000


def _long_csv(log: Any, write: Callable[[str], Any]) -> None:
    """Every series of ``log`` on its own time base: one row per sample, long format."""
    write("signal,unit,time_s,v0,v1,v2,v3,columns\n")
    for ch, s in log.signals.items():
        cols = "|".join(s.columns)
        for start in range(0, s.samples, CSV_BLOCK_ROWS):
            buffer = io.StringIO()
            writer = csv.writer(buffer, lineterminator="\n")
            for t, row in zip(s.time_s[start: start + CSV_BLOCK_ROWS], s.values[start: start + CSV_BLOCK_ROWS],
                              strict=True):
                writer.writerow([ch.value, s.unit, f"{t:.6f}", *[f"{v:.7g}" for v in row], cols])
            write(buffer.getvalue())


def _wide_csv(log: Any, write: Callable[[str], Any]) -> None:
    """The series that share the log's main time base side by side, one row per sample."""
    import numpy as np

    groups: dict[bytes, list[Any]] = {}
    for s in log.signals.values():
        groups.setdefault(s.time_s.tobytes(), []).append(s)
    main = max(groups.values(), key=lambda g: (g[0].samples, len(g)))
    write(",".join(["time_s"] + [f"{s.channel.value}.{c}[{s.unit}]" for s in main for c in s.columns]) + "\n")
    for start in range(0, main[0].samples, CSV_BLOCK_ROWS):
        rows = slice(start, start + CSV_BLOCK_ROWS)
        buffer = io.StringIO()
        np.savetxt(buffer, np.column_stack([main[0].time_s[rows]] + [s.values[rows] for s in main]), delimiter=",",
                   fmt="%.7g")
        write(buffer.getvalue())


def _cmd_export(args: argparse.Namespace) -> int:
    import sys

    from aerobat.fileio import atomic_output

    logs = _logs(args)
    if args.output is not None and len(logs) > 1:
        raise ConfigError(f"--output {args.output}: the file holds {len(logs)} logs; name one as FILE:N, or give "
                          "--out DIR for one CSV file per log")
    render = _long_csv if args.long else _wide_csv
    written: list[Path] = []
    if args.output is None and args.out is None:
        for log in logs:
            render(log, sys.stdout.write)
        return 0
    for log in logs:
        name = f"{Path(args.file).stem}-log{log.index}.csv"
        path = Path(args.output) if args.output else output_dir(Path(args.out)) / name
        option = "--output" if args.output else "--out"
        refuse_overwrite(path, store_path=None, force=args.force, option=option)
        with atomic_output(path, option=option) as handle:  # replaces the file once the whole CSV is written
            def write(text: str, handle: Any = handle) -> None:
                handle.write(text.encode("utf-8"))

            render(log, write)
        written.append(path)
        console(args.json).print(f"wrote {path}", highlight=False)
    if args.json:
        print(json_text({"files": [str(p) for p in written]}))
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    import math
    import sys

    from aerobat.experiments.log_replay import AXES, VIBRATION_LOW_HZ, replay_log
    from aerobat.plotting import save_figure
    from aerobat.plotting.log_replay import plot_replay, plot_replay_spectra, plot_replay_steps

    params, source = None, "the default 5-inch (settings.toml's airframe)"
    if args.airframe is not None:
        from aerobat.plants import PLANTS, replaying_plants

        spec = PLANTS.get(args.plant or replaying_plants()[0], source="--plant")
        if spec.load_settings is None:
            raise ConfigError(f"--airframe: the {spec.name} plant takes no settings file")
        params, source = spec.load_settings(args.airframe), f"{args.airframe}"
    out = output_dir(Path(args.out) if args.out else Path("out") / f"replay-{Path(args.file).name.split(':')[0]}")
    window = tuple(args.window_s) if args.window_s else None
    say = console(args.json).print

    terminal = sys.stderr.isatty()
    reported = [-math.inf]

    def progress(done: float, total: float) -> None:
        if terminal:  # one line that counts up
            print(f"\r  replayed {done:6.1f} / {total:.1f} s", end="", file=sys.stderr, flush=True)
        elif done >= total or done - reported[0] >= 0.25 * total:  # a log, CI: a few plain lines
            reported[0] = done
            print(f"  replayed {done:6.1f} / {total:.1f} s", file=sys.stderr, flush=True)

    if args.tune is not None or args.set:
        return _what_if(args, params, source, out, window, progress)
    result = replay_log(args.file, window_s=window, params=params, airframe_source=source,
                        step_min_deg_s=args.step_min_deg_s, seed=args.seed, progress=progress,
                        battery=not args.no_battery, plant=args.plant)
    if terminal:
        print(file=sys.stderr)
    stem = result.log.replace("#", "-log")
    figure = out / f"{stem}_{result.window_s[0]:g}-{result.window_s[1]:g}s.png"
    steps_figure = figure.with_name(f"{figure.stem}_steps.png")
    spectra_figure = figure.with_name(f"{figure.stem}_spectra.png")
    for path in (figure, steps_figure, spectra_figure):
        refuse_overwrite(path, store_path=None, force=args.force, option="--out")
    save_figure(plot_replay(result), figure)
    save_figure(plot_replay_steps(result), steps_figure)
    save_figure(plot_replay_spectra(result), spectra_figure)
    summary = result.summary()
    summary["figure"] = str(figure)
    summary["steps_figure"] = str(steps_figure)
    summary["spectra_figure"] = str(spectra_figure)
    if result.tune_report is not None:
        summary["tune"] = result.tune_report.text()
    if args.json:
        print(json_text(summary))
        return 0
    lo, hi = result.window_s
    say(f"{result.log} {lo:g}–{hi:g} s replayed through Betaflight 4.6 SITL with the log's own tune, in ACRO, in "
        f"the air; airframe: {source} ({result.wall_s:.1f} s wall, {result.lockstep_steps} lockstep steps)",
        highlight=False)
    say(f"  props {result.props}: the SITL's mixer and the physics' spins follow it", highlight=False)
    say(f"  battery: {result.battery}", highlight=False)
    if result.excluded_s:
        say(f"  {result.excluded_s:.1f} s left out: within 0.5 s of a logged gyro at its 2000 deg/s limit (a crash)",
            highlight=False)
    say("  per axis [deg/s]: rms of (simulated - logged), correlation, rms of the logged series", highlight=False)
    for k, axis in enumerate(AXES):
        sp, curve, g, e = result.setpoint[k], result.setpoint_curve[k], result.gyro[k], result.tracking[k]
        say(f"  {axis:5s} set point: firmware {sp.rms:5.2f} r {sp.correlation:6.4f}, tune's curve {curve.rms:5.2f} "
            f"r {curve.correlation:6.4f} of {sp.logged_rms:5.1f} | gyro {g.rms:5.1f} r {g.correlation:5.3f} of "
            f"{g.logged_rms:5.1f} | tracking error {e.rms:5.1f} r {e.correlation:6.3f} "
            f"(1-20 Hz {e.band_correlation:6.3f}) of {e.logged_rms:5.1f}",
            highlight=False)
    say("  motors: " + "; ".join(f"M{j + 1} rms {m.rms:.3f} r {m.correlation:.3f}"
                                 for j, m in enumerate(result.motors)),
        highlight=False)
    for axis, s in summary["steps"].items():
        if s["steps"]:
            say(f"  {axis:5s} {int(s['steps'])} set-point steps: rise time {1e3 * s['rise_log_s']:.0f} ms logged, "
                f"{1e3 * s['rise_sim_s']:.0f} ms simulated; overshoot {100 * s['overshoot_log']:.0f} % logged, "
                f"{100 * s['overshoot_sim']:.0f} % simulated (medians)", highlight=False)
        else:
            say(f"  {axis:5s} no set-point step of {args.step_min_deg_s:g} deg/s in the window", highlight=False)
    say("  PID terms (firmware units; rms of the difference, correlation, logged rms): " + "; ".join(
        f"{term} " + ", ".join(f"{axis} {m.rms:.1f} r {m.correlation:.2f} of {m.logged_rms:.1f}"
                               for axis, m in zip(AXES, row, strict=True) if m is not None)
        for term, row in zip("PIDF", result.pid, strict=True)), highlight=False)
    if result.vibration:
        say(f"  vibration before the filters ({VIBRATION_LOW_HZ:g} Hz to the log's Nyquist frequency; the log's "
            "unfiltered gyro against the gyro the SITL's firmware read): " + "; ".join(
                f"{axis} rms {m.rms_log_deg_s:.1f} / {m.rms_sim_deg_s:.1f} deg/s, strongest line "
                f"{m.peak_log_hz:.0f} / {m.peak_sim_hz:.0f} Hz" for axis, m in zip(AXES, result.vibration, strict=True))
            + " (log / SITL)", highlight=False)
    else:
        say("  vibration: not compared (the log records no gyro before the firmware's filters: debug_mode "
            "GYRO_SCALED)", highlight=False)
    say(f"wrote {figure}, {steps_figure} and {spectra_figure}", highlight=False)
    return 0


def register(sub: Any) -> None:
    p = sub.add_parser("log", help="read real flight logs: Betaflight blackbox, PX4 ULog, Crazyflie uSD",
                       formatter_class=HelpFormatter)
    cmds = p.add_subparsers(dest="log_command", metavar="COMMAND")

    def common(q: argparse.ArgumentParser) -> None:
        q.add_argument("file", metavar="FILE[:N]",
                       help="a .bbl/.bfl/.txt blackbox log, a .ulg ULog or a Crazyflie log; FILE:N only its log N, "
                            "from 1 (required)")
        q.add_argument("--index", type=bounded_int(1, 10_000), default=None, metavar="N",
                       help="only log N of the file, from 1, as FILE:N (default: every log)")

    q = cmds.add_parser("info", help="what a log file holds: logs, durations, rates, fields, firmware, tune",
                        formatter_class=HelpFormatter)
    common(q)
    q.add_argument("--json", action="store_true", help="print one JSON object")
    q.set_defaults(func=_cmd_info)
    q = cmds.add_parser("plot", help="set point against gyro per axis, motors, throttle and their spectra",
                        formatter_class=HelpFormatter)
    common(q)
    q.add_argument("--out", metavar="DIR", default=None, help="folder for the figures (default: out/log-FILE)")
    q.add_argument("--window-s", nargs=2, type=finite_float(0.0, 1e6, "s"), metavar=("START", "END"), default=None,
                   help="only this time window of the traces [s] (default: the whole log)")
    q.add_argument("--force", action="store_true", help="replace figures that exist")
    q.add_argument("--json", action="store_true", help="print the figures written as one JSON object")
    q.set_defaults(func=_cmd_plot)
    q = cmds.add_parser("export", help="the log's series in SI units as CSV", formatter_class=HelpFormatter)
    common(q)
    q.add_argument("--format", choices=("csv",), default="csv", help="output format")
    q.add_argument("--output", metavar="FILE", default=None, help="write one log's CSV here (default: stdout)")
    q.add_argument("--out", metavar="DIR", default=None,
                   help="write one CSV file per log into this folder (default: none, stdout)")
    q.add_argument("--long", action="store_true",
                   help="one row per sample of every series on its own time base (default: the main time base, "
                        "side by side)")
    q.add_argument("--force", action="store_true", help="replace files that exist")
    q.add_argument("--json", action="store_true", help="print the files written as one JSON object")
    q.set_defaults(func=_cmd_export)
    q = cmds.add_parser("replay", help="fly a Betaflight log's sticks through the SITL with the log's tune and "
                                       "compare per axis", formatter_class=HelpFormatter)
    q.add_argument("file", metavar="FILE[:N]", help="a Betaflight blackbox log, :N its log N (default 1) (required)")
    q.add_argument("--plant", default=None,  # checked by the replay: parsing a log command imports no plant
                   help=argparse.SUPPRESS)  # betaflight, the one built-in plant that replays logs; old lines say it
    q.add_argument("--airframe", metavar="FILE.toml", default=None,
                   help="a Betaflight plant file, e.g. the [airframe] that identify --log --airframe writes "
                        "(default: the packaged 5-inch)")
    q.add_argument("--window-s", nargs=2, type=finite_float(0.0, 1e6, "s"), metavar=("START", "END"), default=None,
                   help="only this window of the log [s], as log plot's (default: the whole log)")
    q.add_argument("--step-min-deg-s", type=finite_float(10.0, 2000.0, "deg/s"), default=100.0,
                   help="smallest set-point step the step-response metrics use")
    q.add_argument("--seed", type=bounded_int(0, 2**31 - 1), default=0, help="seeds the sensor noise")
    q.add_argument("--no-battery", action="store_true",
                   help="keep thrust constant (default: thrust follows the logged battery voltage, × (V/V_ref)²)")
    q.add_argument("--tune", metavar="FILE[:N]", default=None,
                   help="what-if: fly the logged sticks with this tune too (a CLI diff or dump, or another "
                        "log's header, :N its log N) and show both beside the log (default: the log's own only)")
    q.add_argument("--set", metavar="NAME=VALUE", action="append", default=None,
                   help="what-if: change one setting, in the firmware's own terms (repeatable; on top of --tune, "
                        "else of the log's own tune), e.g. --set p_roll=94 (default: none)")
    q.add_argument("--out", metavar="DIR", default=None, help="folder for the figure (default: out/replay-FILE)")
    q.add_argument("--force", action="store_true", help="replace a figure that exists")
    q.add_argument("--json", action="store_true", help="print one JSON object")
    q.set_defaults(func=_cmd_replay)
