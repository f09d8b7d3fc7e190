"""The numbers of docs/logs.md: every shared flight log read, and vehicles identified from them.

    .venv/bin/python scripts/results_logs.py            # prints the markdown tables
    .venv/bin/python scripts/results_logs.py --figures docs/figures/logs   # and draws the docs' figures

Reads ../shared/data/flight-logs (real logs recorded by others); nothing is written.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from aerobat.errors import ConfigError
from aerobat.experiments.log_identify import identify_from_logs
from aerobat.logs import Channel, read_logs
from aerobat.quadrotor.identification.logfit import Geometry, LogFitOptions

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "flight-logs"
CF = [DATA / "crazyflie" / n for n in ("log10", "log15", "log16")]
ROMA = DATA / "betaflight" / "diatone-roma-f5.bbl"
GECKO = DATA / "betaflight" / "aikonf7-gecko.bbl"
PX4 = DATA / "px4" / "auav-x21-quad.ulg"

# published Crazyflie 2.x values (docs/logs.md cites each)
PUBLISHED = {
    "inertia_xx_kg_m2": (1.6572e-5, "Förster 2015 (CF 2.0), in crazyflie-firmware controller_lee.c"),
    "inertia_yy_kg_m2": (1.6656e-5, "Förster 2015"),
    "kappa_m": (0.005964552, "THRUST2TORQUE, crazyflie-firmware platform_defaults.h (0.0069929 for 2.1+ props)"),
    "motor_time_constant_s": (0.0625, "Bitcraze tools/system_id/plot_motor_delay.py, λ = 16 1/s "
                                      "(Eschmann et al.: 0.072 s)"),
    "hover_command": (36000 / 65535, "PID_VEL_THRUST_BASE 36000 of 65535, platform_defaults_cf2.h"),
    "thrust_max_n": (0.12, "THRUST_MAX 0.12 N (2.1+ props), platform_defaults_cf2.h; 0.142 N measured at 93.75 %"),
}
CF_GEOMETRY = Geometry(mass_kg=0.027, motor_x_m=0.028, motor_y_m=0.028, inertia_zz_ratio=0.88)
ROMA_GEOMETRY = Geometry(mass_kg=0.55, motor_x_m=0.08, motor_y_m=0.08, inertia_zz_ratio=0.93)


def _row(cells: list[str]) -> str:
    return "| " + " | ".join(cells) + " |"


def info_table() -> list[str]:
    lines = [_row(["file", "log", "duration", "gyro rate", "firmware", "board / craft", "signals"]),
             _row(["---"] * 7)]
    for path in sorted(DATA.rglob("*")):
        if not path.is_file() or path.name == "README.md":
            continue
        for log in read_logs(path):
            gyro = log.signals.get(Channel.GYRO)
            meta = log.metadata
            lines.append(_row([path.name, str(log.index), f"{log.duration_s:.1f} s",
                               f"{gyro.rate_hz:.0f} Hz" if gyro else "—",
                               f"{meta.firmware} {meta.firmware_version[:12]}", f"{meta.board} {meta.craft_name}",
                               ", ".join(c.value for c in log.signals)]))
    return lines


def _metrics(metrics) -> str:
    return " · ".join(f"{m.r2:.2f}/{m.correlation:.2f}" for m in metrics)


def crazyflie_table() -> list[str]:
    result = identify_from_logs(CF, CF_GEOMETRY)
    v = result.fit.values
    lines = [_row(["quantity", "identified (± jackknife 1σ)", "published", "ratio", "source"]), _row(["---"] * 5)]
    for name, (published, source) in PUBLISHED.items():
        value, sigma, unit = v[name]
        lines.append(_row([f"{name} [{unit}]", f"{value:.4g} ± {sigma:.2g}", f"{published:.4g}",
                           f"{value / published:.2f}", source]))
    value, sigma, _ = v["hover_command_measured"]
    lines.append(_row(["hover command measured in the log (no model)", f"{value:.3f} ± {sigma:.3f}",
                       f"{36000 / 65535:.3f}", f"{value / (36000 / 65535):.2f}", "as above"]))
    lines += ["", f"Held-out blocks, R²/correlation (roll · pitch · yaw acceleration · specific force z): "
                  f"{_metrics(result.fit.holdout_metrics)}; fit {result.fit.wall_s:.1f} s."]
    return lines


def roma_table() -> list[str]:
    lines = [_row(["estimator", "I_xx [kg m²]", "I_yy [kg m²]", "τ [ms]", "f_max [N]", "hover", "held out",
                   "log 2", "log 3"]), _row(["---"] * 9)]
    for label, options in (("least squares, 2–20 Hz (default)", LogFitOptions()),
                           ("instrumental variables on the set point", LogFitOptions(instrument_setpoint=True))):
        result = identify_from_logs([f"{ROMA}:1"], ROMA_GEOMETRY, options=options)
        v = {k: x[0] for k, x in result.fit.values.items()}
        others = {name: m for name, m in result.validations}
        lines.append(_row([label, f"{v['inertia_xx_kg_m2']:.2e}", f"{v['inertia_yy_kg_m2']:.2e}",
                           f"{v['motor_time_constant_s'] * 1e3:.1f}", f"{v['thrust_max_n']:.2f}",
                           f"{v['hover_command']:.3f} (log: {v['hover_command_measured']:.3f})",
                           _metrics(result.fit.holdout_metrics),
                           *[_metrics(others[n]) if not isinstance(others[n], str) else others[n]
                             for n in ("diatone-roma-f5.bbl#2", "diatone-roma-f5.bbl#3")]]))
    return lines


def gecko_and_px4() -> list[str]:
    result = identify_from_logs([GECKO], dataclasses.replace(ROMA_GEOMETRY, mass_kg=0.6))
    v = {k: x[0] for k, x in result.fit.values.items()}
    lines = [f"- Gecko (mass 0.6 kg assumed): I_xx {v['inertia_xx_kg_m2']:.2e}, I_yy {v['inertia_yy_kg_m2']:.2e} "
             f"kg m², τ {v['motor_time_constant_s'] * 1e3:.1f} ms, f_max {v['thrust_max_n']:.2f} N, hover "
             f"{v['hover_command']:.3f} (log {v['hover_command_measured']:.3f}); held out "
             f"{_metrics(result.fit.holdout_metrics)}."]
    try:
        identify_from_logs([PX4], Geometry(mass_kg=1.2, motor_x_m=0.16, motor_y_m=0.16))
        lines.append("- PX4: identified (unexpected: see the text)")
    except ConfigError as exc:
        lines.append(f"- PX4: refused: {str(exc).split(': ', 2)[-1]}")
    return lines


def pilot_table() -> list[str]:
    """What `log plot` reads for a pilot: the crash, and the step response per axis, on each Betaflight flight."""
    from aerobat.logs import read_logs
    from aerobat.plotting.flightlog import log_crash
    from aerobat.quadrotor.log_analysis import estimate_step_response

    lines = ["| flight | crash | roll: 50 % / rise / overshoot | pitch | yaw |", "|---|---|---|---|---|"]
    for path in (ROMA, GECKO):
        for log in read_logs(path):
            if log.duration_s < 10.0:
                continue
            crash = log_crash(log)
            flight = log.window(-np.inf, crash.time_s) if crash else log
            g = flight.signals[Channel.GYRO]
            sp = np.degrees(flight.signals[Channel.RATE_SETPOINT].at(g.time_s))
            cells = []
            for k in range(3):
                r = estimate_step_response(g.time_s, sp[:, k], np.degrees(g.values[:, k]))
                cells.append("—" if r is None else f"{1e3 * r.delay_s:.0f} ms / {1e3 * r.rise_s:.0f} ms / "
                             f"{100 * r.overshoot:.0f} % (0 ms: {r.mean[0]:.2f}, 500 ms: {r.mean[-1]:.2f})")
            where = f"{crash.time_s:.2f} s: {crash.reason}" if crash else "none"
            lines.append(f"| {log.name} | {where} | " + " | ".join(cells) + " |")
    return lines


def figures(out: Path) -> None:
    from aerobat.logs import read_log, read_logs
    from aerobat.plotting import save_figure
    from aerobat.plotting.flightlog import plot_log_fit, plot_log_spectrogram, plot_log_step_response, plot_log_traces

    out.mkdir(parents=True, exist_ok=True)
    save_figure(plot_log_traces(read_log(GECKO), window_s=(50.0, 58.0)), out / "gecko_traces.png")
    roma1 = read_logs(ROMA)[0]
    save_figure(plot_log_traces(roma1), out / "roma1_traces.png")
    save_figure(plot_log_spectrogram(roma1), out / "roma1_spectrogram.png")
    save_figure(plot_log_step_response(roma1), out / "roma1_step_response.png")
    result = identify_from_logs([f"{ROMA}:1"], ROMA_GEOMETRY)
    save_figure(plot_log_fit(result.fit, result.prepared[0]), out / "roma_fit.png")
    print(f"figures written to {out}")


def main() -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--figures", metavar="DIR", type=Path, help="also draw the docs' figures into DIR")
    args = parser.parse_args()
    if not DATA.is_dir():
        raise SystemExit(f"{DATA} is absent: the real logs are needed")
    for title, lines in (("Every shared log", info_table()), ("Crazyflie 2.1 from log10, log15, log16",
                                                               crazyflie_table()),
                         ("DIATONE ROMA F5 from its first log", roma_table()), ("Gecko and PX4", gecko_and_px4()),
                         ("What log plot reads for a pilot", pilot_table())):
        print(f"### {title}\n")
        print("\n".join(lines))
        print()
    if args.figures:
        figures(args.figures)


if __name__ == "__main__":
    main()
