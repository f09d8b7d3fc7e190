"""The frame's vibration in real logs (issue 42): the numbers docs/plants.md quotes.

Run (needs ../shared/data; about 10 s):

    .venv/bin/python scripts/results_vibration.py
    .venv/bin/python scripts/results_vibration.py --json
    .venv/bin/python scripts/results_vibration.py --fly    # and the ROMA chain's first attempts (~3 min)
    .venv/bin/python scripts/results_vibration.py --figure docs/figures/logs/roma_vibration.png
    .venv/bin/python scripts/results_vibration.py --replay  # flights 2 and 3 replayed, gyro before the filters (~1 min)
    .venv/bin/python scripts/results_vibration.py --replay --replay-figure docs/figures/logs/roma_replay_vibration.png

The ROMA F5's three flights record the gyro before the firmware's filters (Betaflight's debug_mode
GYRO_SCALED), sampled at the log's 250 Hz. For each flight alone, with flight 1's identified thrust curve:
the thrust coefficient whose folded rotor lines carry the most gyro power
(:func:`aerobat.quadrotor.identification.vibration.fit_vibration`), the rotors' frequency at the median
command, the share of steady windows whose strongest line lies on a folded rotor line (at that k and at the
prior's), and the lines' rms per axis. Then, per throttle band, the strongest line above 30 Hz that the log
shows (median over the band's steady windows) beside where the fold puts the rotors' line at the fitted and
at the prior's k.

With ``--replay``: flights 2 and 3 replayed through the SITL on the airframe ``identify`` writes from flight 1,
with its vibration lines and without them; per axis the rms above 30 Hz of the log's gyro before the filters and
of the gyro the SITL's firmware read, and the strongest line there (``aerobat log replay``'s vibration line;
``--replay-figure``: flight 2's spectra figure, with the lines).

With ``--fly``: the first attempt of the ROMA F5 chain (``scripts/results_roma.py``: the 3D triple flip at
600 °/s designed on the firmware model, flown open loop on the identified airframe with the log's tune),
seeds 0–3, with the airframe as ``identify`` writes it, with only the identified thrust coefficient, with only
the vibration lines (at the default k), and with both (what ``results_roma.py --vibration`` flies).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
LOG = ROOT.parent / "shared" / "data" / "flight-logs" / "betaflight" / "diatone-roma-f5.bbl"
GEOMETRY = {"mass_kg": 0.55, "motor_x_m": 0.08, "motor_y_m": 0.08}


def run() -> dict[str, Any]:
    """Every number: per-flight fits with flight 1's thrust curve, then the folded lines per throttle band."""
    from aerobat import preset
    from aerobat.experiments.log_identify import identify_from_logs, parse_log_ref
    from aerobat.experiments.log_replay import FLYING_MOTOR
    from aerobat.logs import read_log
    from aerobat.quadrotor.flightlog import Channel
    from aerobat.quadrotor.identification.logfit import Geometry, thrust_curve
    from aerobat.quadrotor.identification.vibration import LOW_HZ, WINDOW, fit_vibration, folded_hz
    from aerobat.quadrotor.xframe import Airframe

    ref = parse_log_ref(f"{LOG}:1")
    identified = identify_from_logs([ref], Geometry(**GEOMETRY), prior=preset("fpv5"))
    fit = identified.fit
    f_max = fit.values["thrust_max_n"][0]
    ratio, shape = min(max(fit.model.r, 0.0), 0.9), min(max(fit.model.k, 0.0), 1.0)

    def thrust(u: Any) -> np.ndarray:
        return f_max * thrust_curve(np.asarray(u, dtype=float), ratio, shape)

    k_prior = Airframe().thrust_coefficient_n_s2
    flights = []
    bands: dict[float, list[float]] = {}
    windows: list[tuple[float, np.ndarray]] = []  # (mean command, spectrum over its median) of every steady window
    k_first = None
    for index in (1, 2, 3):
        log = read_log(LOG, index)
        motors = log.signals[Channel.MOTOR_COMMAND]
        gyro = log.signals[Channel.GYRO_UNFILTERED].at(motors.time_s)
        v = fit_vibration([(motors.time_s, gyro, motors.values)], thrust, k_prior, flying_command=FLYING_MOTOR)
        if v is None:
            raise SystemExit(f"{LOG.name}:{index}: no steady window")
        k_first = k_first or v.thrust_coefficient_n_s2
        flights.append({"flight": index, "thrust_coefficient_n_s2": v.thrust_coefficient_n_s2,
                        "ratio_to_prior": v.thrust_coefficient_n_s2 / k_prior, "rotor_hz": v.rotor_hz,
                        "windows": v.windows, "matched_share": v.matched_share,
                        "matched_share_prior": v.matched_share_prior, "contrast": v.contrast,
                        "runner_up": v.runner_up, "line_rms_deg_s": [math.degrees(x) for x in v.line_rms_rad_s]})
        # the strongest line above LOW_HZ of each steady window, by its mean command's band
        rate = 1.0 / float(np.median(np.diff(motors.time_s)))
        freqs = np.fft.rfftfreq(WINDOW, 1.0 / rate)
        taper = np.hanning(WINDOW)
        for s in range(0, len(motors.time_s) - WINDOW + 1, WINDOW // 2):
            u = motors.values[s:s + WINDOW]
            if u.mean() <= FLYING_MOTOR or u.std(axis=0).max() >= 0.03:
                continue
            g = gyro[s:s + WINDOW]
            power = (np.abs(np.fft.rfft((g - g.mean(axis=0)) * taper[:, None], axis=0)) ** 2).sum(axis=1)
            scored = freqs >= LOW_HZ
            windows.append((float(u.mean()), power / np.median(power[scored])))
            band = math.floor(u.mean() / 0.05) * 0.05
            bands.setdefault(round(band, 2), []).append(float(freqs[scored][np.argmax(power[scored])]))
    table = []
    for band in sorted(bands):
        centre = band + 0.025
        t = float(thrust(centre))
        table.append({"command": [band, round(band + 0.05, 2)], "windows": len(bands[band]),
                      "log_line_hz": float(np.median(bands[band])),
                      "folded_at_fit_hz": float(folded_hz(math.sqrt(t / k_first) / (2 * math.pi), 250.0)),
                      "rotor_at_fit_hz": math.sqrt(t / k_first) / (2 * math.pi),
                      "folded_at_prior_hz": float(folded_hz(math.sqrt(t / k_prior) / (2 * math.pi), 250.0))})
    commands = np.linspace(0.15, 0.5, 71)
    curve = np.array([float(thrust(c)) for c in commands])
    return {"prior_thrust_coefficient_n_s2": k_prior, "flights": flights, "bands": table,
            "figure": {"freqs_hz": freqs.tolist(), "windows": [(c, p.tolist()) for c, p in windows],
                       "commands": commands.tolist(),
                       "folded_fit_hz": folded_hz(np.sqrt(curve / k_first) / (2 * math.pi), 250.0).tolist(),
                       "folded_prior_hz": folded_hz(np.sqrt(curve / k_prior) / (2 * math.pi), 250.0).tolist()}}


def figure(data: dict[str, Any], path: Path) -> None:
    """The unfiltered gyro's spectrum against motor command (steady windows of the three flights, each over its
    median), with where the fold puts the rotors' line at flight 1's k and at the default k."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from aerobat.plotting import save_figure

    freqs = np.array(data["freqs_hz"])
    edges = np.arange(0.15, 0.5001, 0.025)
    image = np.full((len(edges) - 1, freqs.size), np.nan)
    for i in range(len(edges) - 1):
        rows = [np.array(p) for c, p in data["windows"] if edges[i] <= c < edges[i + 1]]
        if rows:
            image[i] = 10.0 * np.log10(np.mean(rows, axis=0))
    fig, ax = plt.subplots(figsize=(8, 4.5))
    df = freqs[1] - freqs[0]
    freq_edges = np.append(freqs - df / 2.0, freqs[-1] + df / 2.0)
    mesh = ax.pcolormesh(edges, freq_edges, image.T, shading="flat", cmap="magma", vmin=0.0, vmax=30.0)
    fig.colorbar(mesh, ax=ax, label="power over the window's median [dB]")
    ax.plot(data["commands"], data["folded_fit_hz"], color="cyan", lw=1.6, label="rotor line, folded: flight 1's k")
    ax.plot(data["commands"], data["folded_prior_hz"], color="white", lw=1.2, ls="--",
            label="rotor line, folded: the default k")
    ax.axhline(30.0, color="grey", lw=0.8, ls=":")
    ax.set_xlim(edges[0], edges[-1])
    ax.set_ylim(0.0, 125.0)
    ax.set_xlabel("mean motor command of the window")
    ax.set_ylabel("frequency in the 250 Hz log [Hz]")
    ax.set_title("ROMA F5, flights 1-3: the unfiltered gyro (roll + pitch + yaw) against motor command")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def fly(seeds: tuple[int, ...] = (0, 1, 2, 3)) -> dict[str, list[Any]]:
    """The chain's first attempt [m] per seed for each share of the identified vibration (a status if lost)."""
    import tempfile
    import tomllib

    import tomli_w

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import results_roma as chain

    from aerobat.store import Store

    out: dict[str, list[Any]] = {}
    with tempfile.TemporaryDirectory(prefix="aerobat-vibration-") as tmp:
        work = Path(tmp)
        vehicle, airframe = work / "roma.toml", work / "roma_bf.toml"
        chain.run_aerobat(["identify", "--log", f"{LOG}:1", *chain.IDENTIFY, "--output", str(vehicle), "--airframe",
                        str(airframe)])
        text = airframe.read_text()
        found = tomllib.loads("\n".join(line[4:] for line in text.splitlines() if line.startswith("#   ")))
        lines = {k: found[k] for k in ("vibration_rms_rad_s", "vibration_thrust_n")}
        shares = {"as identify writes it": {}, "the thrust coefficient only": {
            "thrust_coefficient_n_s2": found["thrust_coefficient_n_s2"]}, "the lines only": lines, "both": found}
        for n, (name, extra) in enumerate(shares.items()):
            table = tomllib.loads(text)
            table["airframe"].update(extra)
            flown = work / f"airframe-{n}.toml"
            flown.write_text(tomli_w.dumps(table))
            firsts: list[Any] = []
            for seed in seeds:
                db = work / f"{n}-{seed}.sqlite"
                chain.run_aerobat(["learn", *chain.FLIP, "--vehicle", str(vehicle), "--plant", "betaflight",
                                "--betaflight", str(flown), "--tune", str(LOG), "--feedback", "none", "--trials", "1",
                                "--seed", str(seed), "--db", str(db), "--out", str(work / f"out-{n}-{seed}")],
                               may_fail=True)
                with Store(db, create=False) as store:
                    sid = store.list_sessions()[-1].id
                    records = store.iterations(sid)
                    mask = np.array(store.maneuver(store.session(sid).maneuver_id).position_mask, dtype=bool)
                first = records[0] if records else None
                firsts.append(float(np.linalg.norm(first.error[mask])) if first is not None and first.status == "ok"
                              else (first.status if first is not None else "not flown"))
            out[name] = firsts
    return out


def _airframes(work: Path) -> tuple[Path, Path]:
    """The airframe ``identify`` writes from flight 1 as written, and with its commented vibration lines in it."""
    import tomllib

    import tomli_w

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import results_roma as chain

    vehicle, airframe = work / "roma.toml", work / "roma_bf.toml"
    chain.run_aerobat(["identify", "--log", f"{LOG}:1", *chain.IDENTIFY, "--output", str(vehicle), "--airframe",
                       str(airframe)])
    text = airframe.read_text()
    table = tomllib.loads(text)
    commented = "\n".join(line[4:] for line in text.splitlines() if line.startswith("#   "))
    table["airframe"].update(tomllib.loads(commented))
    shaking = work / "roma_bf_vibration.toml"
    shaking.write_text(tomli_w.dumps(table))
    return airframe, shaking


def replay(figure_path: Path | None = None) -> list[dict[str, Any]]:
    """Flights 2 and 3 replayed on flight 1's airframe, without and with its vibration lines (whole flights)."""
    import tempfile

    from aerobat.experiments.log_replay import AXES, replay_log
    from aerobat.plants.fpv.params import load_betaflight

    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="aerobat-vibration-") as tmp:
        quiet_file, shaking_file = _airframes(Path(tmp))
        quiet, shaking = load_betaflight(quiet_file), load_betaflight(shaking_file)
        for flight in (2, 3):
            without = replay_log(LOG, index=flight, params=quiet)
            with_lines = replay_log(LOG, index=flight, params=shaking)
            if figure_path is not None and flight == 2:
                from aerobat.plotting import save_figure
                from aerobat.plotting.log_replay import plot_replay_spectra

                save_figure(plot_replay_spectra(with_lines), figure_path)
            for k, axis in enumerate(AXES):
                a, b = without.vibration[k], with_lines.vibration[k]
                rows.append({"flight": flight, "axis": axis, "log_rms_deg_s": a.rms_log_deg_s,
                             "sim_rms_without_deg_s": a.rms_sim_deg_s, "sim_rms_with_deg_s": b.rms_sim_deg_s,
                             "log_line_hz": a.peak_log_hz, "sim_line_with_hz": b.peak_sim_hz,
                             "window_s": list(with_lines.window_s)})
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--figure", metavar="PNG", type=Path,
                        help="draw the unfiltered gyro's spectrum against motor command with the folded rotor lines")
    parser.add_argument("--replay", action="store_true",
                        help="also replay flights 2 and 3 and compare the gyro before the filters (~1 min)")
    parser.add_argument("--replay-figure", metavar="PNG", type=Path,
                        help="with --replay: flight 2's spectra figure, with the vibration lines")
    parser.add_argument("--fly", action="store_true",
                        help="also fly the ROMA chain's first attempts with each share of the vibration (~3 min)")
    args = parser.parse_args(argv)
    if not LOG.exists():
        print(f"{LOG}: not found (the shared data folder is missing)", file=sys.stderr)
        return 2
    result = run()
    if args.figure:
        figure(result["figure"], args.figure)
    result.pop("figure")
    if args.replay:
        result["replay"] = replay(args.replay_figure)
    if args.fly:
        result["first_attempt_m"] = fly()
    if args.json:
        print(json.dumps(result, indent=1))
        return 0
    print(f"prior thrust coefficient {result['prior_thrust_coefficient_n_s2']:.3g} N/(rad/s)^2")
    print("| flight | k [N/(rad/s)²] | × prior | rotors at the median command | steady windows | strongest line on a "
          "folded rotor line: fitted k | prior's k | contrast | runner-up | lines' rms roll, pitch, yaw [°/s] |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for f in result["flights"]:
        rms = ", ".join(f"{x:.1f}" for x in f["line_rms_deg_s"])
        print(f"| {f['flight']} | {f['thrust_coefficient_n_s2']:.3g} | {f['ratio_to_prior']:.2f} | "
              f"{f['rotor_hz']:.0f} Hz | {f['windows']} | {f['matched_share']:.0%} | {f['matched_share_prior']:.0%} | "
              f"{f['contrast']:.1f} | {f['runner_up']:.2f} | {rms} |")
    print()
    print("| motor command | steady windows | the log's strongest line above 30 Hz | rotor line at flight 1's k: "
          "true, folded | folded at the prior's k |")
    print("|---|---|---|---|---|")
    for b in result["bands"]:
        print(f"| {b['command'][0]:.2f}–{b['command'][1]:.2f} | {b['windows']} | {b['log_line_hz']:.0f} Hz | "
              f"{b['rotor_at_fit_hz']:.0f} Hz, {b['folded_at_fit_hz']:.0f} Hz | {b['folded_at_prior_hz']:.0f} Hz |")
    if args.replay:
        print()
        print("| flight | axis | log: rms above 30 Hz | SITL without the lines | SITL with them | "
              "log's strongest line | SITL's, with the lines |")
        print("|---|---|---|---|---|---|---|")
        for r in result["replay"]:
            print(f"| {r['flight']} | {r['axis']} | {r['log_rms_deg_s']:.1f} °/s | "
                  f"{r['sim_rms_without_deg_s']:.1f} °/s | {r['sim_rms_with_deg_s']:.1f} °/s | "
                  f"{r['log_line_hz']:.0f} Hz | {r['sim_line_with_hz']:.0f} Hz |")
    if args.fly:
        print()
        print("| the ROMA chain's airframe | first attempt, seeds 0-3 [m] |")
        print("|---|---|")
        for name, firsts in result["first_attempt_m"].items():
            shown = ", ".join(f"{v:.3f}" if isinstance(v, float) else str(v) for v in firsts)
            print(f"| {name} | {shown} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
