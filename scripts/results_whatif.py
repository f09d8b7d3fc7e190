"""What-if replays of the ROMA F5's flights (issue 42): the numbers docs/plants.md quotes.

    .venv/bin/python scripts/results_whatif.py            # single changes, another quad's tune
    .venv/bin/python scripts/results_whatif.py props      # the props' direction against the log's motors
    .venv/bin/python scripts/results_whatif.py twin       # flights 1-3 on the default and the identified airframe
    .venv/bin/python scripts/results_whatif.py gecko      # the Gecko: fitted on its first half, replayed on the rest
    .venv/bin/python scripts/results_whatif.py spectra    # gyro spectra, log against SITL (docs/figures/logs)
    .venv/bin/python scripts/results_whatif.py delay      # how much of the fit's 12 ms delay flight 1 decides

Flight 1, 40–62 s (three roll steps), flown with the log's own tune and with single roll changes; then
flight 3, 20–40 s, with the TII Racing KakuteH7's 4.3.1 diff. Each row: the step response estimated from
set point to gyro (50 % time, rise 10 → 90 %, overshoot), the medians over the set-point steps found, the
tracking error, and the motors' saturation and noise; "log" is the real flight read the same way.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
ROMA = SHARED / "flight-logs" / "betaflight" / "diatone-roma-f5.bbl"
KAKUTE = SHARED / "betaflight-configs" / "tii-racing-kakuteh7-4.3.1-diff.txt"
AXIS = {"roll": 0, "pitch": 1, "yaw": 2}


def _ms(v: float) -> str:
    return "—" if math.isnan(v) else f"{1e3 * v:.1f}"


def _pct(v: float) -> str:
    return "—" if math.isnan(v) else f"{100 * v:.1f}"


def rows(result, axis: str, label: str, include_log: bool) -> list[str]:
    k = AXIS[axis]
    out = []
    for reading in result.readings[(0 if include_log else 1):]:
        a = reading.axes[k]
        name = label if reading.name == "SITL, what-if" else reading.name
        out.append(f"| {name} | {_ms(a.delay_s)} | {_ms(a.rise_s)} | {_pct(a.overshoot)} | {a.steps}: "
                   f"{_ms(a.step_rise_s)} ms, {_pct(a.step_overshoot)} % | {a.tracking_rms_deg_s:.1f} | "
                   f"{100 * reading.saturated_fraction:.1f} | {100 * reading.motor_noise_rms:.2f} |")
    return out


def props() -> None:
    """Flights 2 and 3, whole, flown with props in and props out: the motors' yaw mix against the log's."""
    import numpy as np

    from aerobat.experiments.log_replay import replay_log
    from aerobat.quadrotor.log_analysis import band_pass

    mix = np.array([1.0, -1.0, -1.0, 1.0])  # M1 + M4 − M2 − M3 in Betaflight's motor order: props in, yaw left
    print("| flight | props | yaw mix correlation: raw | 1–20 Hz | gyro rms roll · pitch · yaw [°/s] |")
    print("|---|---|---|---|---|")
    for index in (2, 3):
        for out in (False, True):
            r = replay_log(ROMA, index=index, props_out=out)
            dt = float(np.median(np.diff(r.time_s)))
            sim, log = r.motors_sim @ mix, r.motors_log @ mix
            raw = float(np.corrcoef(sim, log)[0, 1])
            band = float(np.corrcoef(band_pass(sim, dt), band_pass(log, dt))[0, 1])  # 1–20 Hz
            rms = " · ".join(f"{g.rms:.1f}" for g in r.gyro)
            print(f"| {index} | {'out' if out else 'in'} | {raw:+.3f} | {band:+.3f} | {rms} |")


def twin() -> None:
    """Flights 1–3, whole, on the default 5-inch and on the airframe identified from flight 1 (as `identify
    --log …:1 --airframe` writes it: props out from the mixer, a poorly excited axis from the prior's ratio, the
    battery's reference voltage), thrust following the logged battery, and once at constant thrust."""
    import contextlib
    import io
    import tempfile

    import numpy as np

    from aerobat.cli import main as cli
    from aerobat.experiments.log_replay import replay_log
    from aerobat.plants.fpv.params import load_betaflight

    with tempfile.TemporaryDirectory(prefix="aerobat-twin-") as work:
        airframe = Path(work) / "roma_bf.toml"
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            code = cli(["identify", "--log", f"{ROMA}:1", "--vehicle", "fpv5", "--mass-kg", "0.55", "--motor-x-m",
                        "0.08", "--motor-y-m", "0.08", "--output", str(Path(work) / "roma.toml"), "--airframe",
                        str(airframe)])
        if code != 0:
            raise SystemExit(f"identify failed ({code})")
        identified = load_betaflight(airframe)
        print("| flight | airframe | gyro rms (corr.) roll · pitch · yaw [°/s] | tracking error corr. raw / 1–20 Hz, "
              "roll · pitch · yaw | motors corr. | P-term corr. roll · pitch · yaw |")
        print("|---|---|---|---|---|---|")
        for index in (1, 2, 3):
            for name, params, battery in (("default 5-inch", None, True),
                                          ("identified from flight 1", identified, True),
                                          ("identified, thrust constant (--no-battery)", identified, False)):
                r = replay_log(ROMA, index=index, params=params, battery=battery)
                gyro = " · ".join(f"{g.rms:.1f} ({g.correlation:.3f})" for g in r.gyro)
                track = " · ".join(f"{e.correlation:.2f} / {e.band_correlation:.2f}" for e in r.tracking)
                motors = np.array([m.correlation for m in r.motors])
                p_term = " · ".join(f"{m.correlation:.2f}" if m is not None else "—" for m in r.pid[0])
                print(f"| {index} | {name} | {gyro} | {track} | {motors.min():.2f}–{motors.max():.2f} | {p_term} |")


GECKO = SHARED / "flight-logs" / "betaflight" / "aikonf7-gecko.bbl"


def _identify_airframe(work: Path, log: str, extra: list[str]) -> Path:
    import contextlib
    import io

    from aerobat.cli import main as cli

    airframe = work / "airframe.toml"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        code = cli(["identify", "--log", log, "--vehicle", "fpv5", *extra, "--output", str(work / "vehicle.toml"),
                    "--airframe", str(airframe)])
    if code != 0:
        raise SystemExit(f"identify failed ({code})")
    return airframe


def _replay_rows(path: Path, index: int, window: tuple[float, float] | None, rows: list[tuple[str, Any]]) -> None:
    import numpy as np

    from aerobat.experiments.log_replay import replay_log

    mix = np.array([1.0, -1.0, -1.0, 1.0])
    for name, params in rows:
        r = replay_log(path, index=index, window_s=window, params=params)
        gyro = " · ".join(f"{g.rms:.1f} ({g.correlation:.3f})" for g in r.gyro)
        track = " · ".join(f"{e.correlation:.2f} / {e.band_correlation:.2f}" for e in r.tracking)
        steps = r.step_summary()
        rise = " · ".join(f"{1e3 * s['rise_log_s']:.0f} / {1e3 * s['rise_sim_s']:.0f} ms, "
                          f"{100 * s['overshoot_log']:.0f} / {100 * s['overshoot_sim']:.0f} %"
                          if s["steps"] else "—" for s in steps.values())
        yaw = float(np.corrcoef(r.motors_sim @ mix, r.motors_log @ mix)[0, 1])
        print(f"| {name} | {gyro} | {track} | {rise} | {yaw:+.2f} |")


def gecko() -> None:
    """The Gecko (one 134 s log, mass and frame unknown: the 5-inch preset's): identified on 0–67 s, replayed on
    67–134 s with the default 5-inch and with what identification wrote."""
    import tempfile

    from aerobat.plants.fpv.params import load_betaflight

    with tempfile.TemporaryDirectory(prefix="aerobat-gecko-") as work:
        airframe = load_betaflight(_identify_airframe(Path(work), str(GECKO), ["--window-s", "0", "67"]))
        print("| airframe | gyro rms (corr.) roll · pitch · yaw [°/s] | tracking error corr. raw / 1–20 Hz | "
              "steps: rise, overshoot log / SITL (medians) | yaw mix corr. |")
        print("|---|---|---|---|---|")
        _replay_rows(GECKO, 1, (67.0, 133.8), [("default 5-inch", None), ("identified on 0–67 s", airframe)])


def spectra() -> None:
    """Flight 3, 20–60 s: the logged and the simulated gyro's spectra (the figure) and their rms above 20 Hz."""
    import numpy as np

    from aerobat.experiments.log_replay import replay_log
    from aerobat.plotting import save_figure
    from aerobat.plotting.log_replay import plot_replay_spectra
    from aerobat.quadrotor.log_analysis import band_pass

    r = replay_log(ROMA, index=3, window_s=(20.0, 60.0))
    out = Path(__file__).resolve().parents[1] / "docs" / "figures" / "logs" / "roma3_replay_spectra.png"
    save_figure(plot_replay_spectra(r), out)
    dt = float(np.median(np.diff(r.time_s)))
    nyquist = 0.5 / dt
    print(f"gyro rms above 20 Hz (to {nyquist:.0f} Hz), flight 3, 20–60 s [°/s]: log / SITL")
    for k, axis in enumerate(("roll", "pitch", "yaw")):
        log, sim = (float(np.sqrt(np.mean(band_pass(x[:, k], dt, (20.0, nyquist)) ** 2)))
                    for x in (r.gyro_log, r.gyro_sim))
        print(f"  {axis:5s} {log:.2f} / {sim:.3f}")
    print(f"figure written to {out}")


DELAYS_MS = (0.0, 1.5, 4.0, 6.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0, 16.0, 20.0)
COST_BOUND = 1.05
"""A delay whose best fit costs at most 5 % more than the free fit's is not excluded by the log."""


def delay() -> None:
    """The fit of ROMA flight 1 with its command-to-thrust delay held at each of :data:`DELAYS_MS`."""
    import numpy as np

    from aerobat.experiments.log_identify import identify_from_logs
    from aerobat.quadrotor.identification.logfit import Geometry, delay_profile

    geometry = Geometry(mass_kg=0.55, motor_x_m=0.08, motor_y_m=0.08, inertia_zz_ratio=0.935)
    result = identify_from_logs([f"{ROMA}:1"], geometry)
    fit = result.fit
    points = delay_profile(result.prepared, fit.layout, geometry, fit, [d / 1e3 for d in DELAYS_MS])
    print(f"### ROMA F5 flight 1: the fit with its delay held (free fit: delay {1e3 * fit.model.delay_s:.1f} ms, "
          f"motor time constant {1e3 * fit.model.tau_s:.1f} ms)\n")
    print("| delay [ms] | motor time constant [ms] | delay + time constant [ms] | fit cost ÷ free fit's | "
          "held-out R² roll, pitch, yaw, specific force |\n|---|---|---|---|---|")
    for pt in points:
        print(f"| {1e3 * pt.delay_s:.1f} | {1e3 * pt.tau_s:.1f} | {1e3 * (pt.delay_s + pt.tau_s):.1f} | "
              f"{pt.cost:.3f} | " + ", ".join(f"{m.r2:.2f}" for m in pt.holdout) + " |")
    delays = np.array([pt.delay_s for pt in points])
    costs = np.array([pt.cost for pt in points])
    inside = delays[costs <= COST_BOUND]
    print(f"\nDelays whose fit costs ≤ {COST_BOUND:.2f}× the free fit's: {1e3 * inside.min():.1f}–"
          f"{1e3 * inside.max():.1f} ms (on this grid); with the log's gyro filters only (1.5 ms) it costs "
          f"{costs[list(DELAYS_MS).index(1.5)]:.2f}×, with no delay {costs[0]:.2f}×.")


def main() -> None:
    import sys

    if sys.argv[1:] == ["delay"]:
        delay()
        return

    if sys.argv[1:] == ["spectra"]:
        spectra()
        return

    if sys.argv[1:] == ["gecko"]:
        gecko()
        return

    if sys.argv[1:] == ["props"]:
        props()
        return
    if sys.argv[1:] == ["twin"]:
        twin()
        return
    from aerobat.experiments.log_whatif import what_if
    from aerobat.firmware.betaflight.tune import load_tune

    if not ROMA.is_file():
        raise SystemExit(f"{ROMA} is absent: the real logs are needed")
    head = ["| flown | 50 % [ms] | rise [ms] | overshoot [%] | steps found: rise, overshoot (medians) | "
            "tracking rms [°/s] | motor ≥ 99 % [% of time] | motor noise > 20 Hz [% rms] |",
            "|---|---|---|---|---|---|---|---|"]
    own = {n: v for _, n, v, _ in load_tune(ROMA, log_index=1).active_settings()}
    p, i = int(own["p_roll"]), int(own["i_roll"])
    print(f"### ROMA F5 flight 1, 40–62 s, roll (the log's tune: p_roll {p}, i_roll {i}, f_roll {own['f_roll']})\n")
    lines = list(head)
    for k, change in enumerate((f"p_roll={2 * p}", f"p_roll={p // 2}", f"i_roll={2 * i}")):
        result = what_if(f"{ROMA}:1", changes=[change], window_s=(40.0, 62.0))
        lines += rows(result, "roll", f"SITL, {change}", include_log=(k == 0))
        if k:
            lines.pop(-2)  # the twin once
    print("\n".join(lines) + "\n")
    if KAKUTE.is_file():
        result = what_if(f"{ROMA}:3", tune=load_tune(KAKUTE), window_s=(20.0, 40.0))
        print(f"### ROMA F5 flight 3, 20–40 s, with {KAKUTE.name}: {len(result.differences)} settings differ\n")
        print(", ".join(f"{d.name} {d.flown} → {d.what_if}" for d in result.differences) + "\n")
        for axis in ("roll", "pitch"):
            print(f"{axis}:\n")
            print("\n".join(head + rows(result, axis, "SITL, the KakuteH7's tune", include_log=True)) + "\n")


if __name__ == "__main__":
    main()
