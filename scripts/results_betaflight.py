"""Regenerate the Betaflight numbers and figures of docs/results.md and docs/plants.md.

Run (the firmware is built on first use):

    .venv/bin/python scripts/results_betaflight.py rate     # step responses, the nominal P-loop fit (~30 s)
    .venv/bin/python scripts/results_betaflight.py learn    # three maneuvers, 30 trials each (~4 min)
    .venv/bin/python scripts/results_betaflight.py gyro     # 8 kHz and 4 kHz side by side (~1 min)
    .venv/bin/python scripts/results_betaflight.py all

Everything is written to docs/figures/betaflight/ (JSON and PNG); learning sessions go to the
store given by --db (default out/betaflight.sqlite), every trial included.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from aerobat.core.design import design
from aerobat.plants.betaflight.plant import BetaflightPlant
from aerobat.plants.fpv.params import BetaflightParams
from aerobat.plants.fpv.pilot import throttle_for_collective
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.program import Program, Switch
from aerobat.quadrotor.simulate import NominalModel, simulate
from aerobat.quadrotor.vehicle import VehicleConfig, fpv5

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "figures" / "betaflight"
CONFIG = fpv5()
AXES = {"roll": (0, 10, 1.0, "rate_gain_p_per_s", "rate_p"), "pitch": (1, 11, 1.0, "rate_gain_q_per_s", "rate_q"),
        "yaw": (2, 12, -1.0, "rate_gain_r_per_s", "rate_r")}
MANEUVERS = {
    "triple": dict(flips=3, max_rate_rad_s=math.radians(1800), dims=3, axis="roll"),
    "single": dict(flips=1, max_rate_rad_s=math.radians(800), dims=2, axis="roll"),
    "pitch_double": dict(flips=2, max_rate_rad_s=math.radians(1800), dims=3, axis="pitch"),
}


# ------------------------------------------------------------------------- rate


def measure_step(axis: str, rate_deg_s: float, seed: int = 1, params: BetaflightParams | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Body rate (true, aerobat FLU) after an ACRO stick step from hover; t = 0 when the step reaches the receiver."""
    stick_index, state_index, sign, _, _ = AXES[axis]
    plant = BetaflightPlant(CONFIG, params, seed=seed, feedback="none")
    with plant.open_flight() as flight:
        plant.pilot.power_on_and_arm(flight)
        plant.pilot.settle(flight)
        plant.pilot.hover(flight, 0.5)
        sticks = np.zeros(4)
        sticks[3] = throttle_for_collective(CONFIG.vehicle.gravity_m_s2, plant.pilot.limits)
        sticks[stick_index] = sign * math.radians(rate_deg_s) / plant.pilot.sticks.rate_max_rad_s
        arrival = flight.time_s + flight.latency_steps * flight.step_s
        times, rates = [], []
        for _ in range(flight.frames_for(0.3)):
            flight.frame(plant.pilot.channels(sticks, arm=True, angle=False), lossless=True)
            times.append(flight.time_s - arrival)
            rates.append(flight.x[state_index])
        sticks[stick_index] = 0.0
        for _ in range(flight.frames_for(0.1)):
            flight.frame(plant.pilot.channels(sticks, arm=True, angle=False), lossless=True)
        plant.pilot.fly_to(flight, plant.start_m, 1.0, check=False)
    return np.array(times), np.degrees(np.array(rates))


def nominal_step(config: VehicleConfig, axis: str, rate_deg_s: float,
                 gains: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The design model's response to the same step with rate gains (P_p, P_q, P_r)."""
    _, state_index, _, _, channel = AXES[axis]
    controller = dataclasses.replace(config.controller, rate_gain_p_per_s=gains[0], rate_gain_q_per_s=gains[1],
                                     rate_gain_r_per_s=gains[2])
    model = VehicleConfig(vehicle=config.vehicle, controller=controller, name=config.name)
    program = Program(switches=(Switch(time_s=0.0, channel=channel, value=math.radians(rate_deg_s)),),
                      duration_s=0.3, hover_collective_m_s2=config.vehicle.gravity_m_s2)
    trajectory = simulate(program, model, record=True)
    return trajectory.times_s, np.degrees(trajectory.states[:, state_index])


def step_metrics(t: np.ndarray, rate: np.ndarray, command: float) -> dict[str, float]:
    def first(level: float) -> float:
        above = np.nonzero(rate >= level * command)[0]
        return float(np.interp(level * command, rate[above[0] - 1: above[0] + 1], t[above[0] - 1: above[0] + 1])) \
            if above.size and above[0] > 0 else math.nan
    return {"t50_ms": 1e3 * first(0.5), "t90_ms": 1e3 * first(0.9),
            "overshoot_pct": float(100.0 * (rate.max() / command - 1.0)), "final_deg_s": float(rate[t > 0.2].mean())}


def fit_gains(steps: dict[str, tuple[np.ndarray, np.ndarray, float]]) -> tuple[float, float, float]:
    """Rate gains (P, P, P_r) whose nominal step responses are closest to Betaflight's.

    Least squares over 0–0.25 s after each step; roll and pitch share one gain (after the model's
    moment inversion the P loop is the same on both), yaw has its own. The axes couple through the
    model's thrust limits (a large step saturates its motors), so the two gains are fitted in turn
    until they stop changing.
    """
    def cost(axes: tuple[str, ...], gains: tuple[float, float, float]) -> float:
        total = 0.0
        for axis in axes:
            t, rate, command = steps[axis]
            window = (t >= 0.0) & (t <= 0.25)
            nt, nr = nominal_step(CONFIG, axis, command, gains)
            total += float(np.sum((np.interp(t[window], nt, nr) - rate[window]) ** 2))
        return total

    def best(fn: Any) -> float:
        grid = np.geomspace(2.0, 300.0, 60)  # the cost has local minima: a grid, then a local refinement
        k = int(np.argmin([fn(g) for g in grid]))
        low, high = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        return float(minimize_scalar(fn, bounds=(low, high), method="bounded", options={"xatol": 0.05}).x)

    rp, yaw = CONFIG.controller.rate_gain_p_per_s, CONFIG.controller.rate_gain_r_per_s
    for _ in range(6):
        new_rp = best(lambda g, yaw=yaw: cost(("roll", "pitch"), (g, g, yaw)))
        new_yaw = best(lambda g, rp=new_rp: cost(("yaw",), (rp, rp, g)))
        done = abs(new_rp - rp) < 0.1 and abs(new_yaw - yaw) < 0.1
        rp, yaw = new_rp, new_yaw
        if done:
            break
    return rp, rp, yaw


def cmd_rate() -> dict[str, Any]:
    steps = {axis: (*measure_step(axis, command), command)
             for axis, command in (("roll", 1000.0), ("pitch", 1000.0), ("yaw", 400.0))}
    fitted = fit_gains(steps)
    current = (CONFIG.controller.rate_gain_p_per_s, CONFIG.controller.rate_gain_q_per_s,
               CONFIG.controller.rate_gain_r_per_s)
    results: dict[str, Any] = {"fitted_gains_per_s": fitted, "vehicle_file_gains_per_s": current}
    for axis, (t, rate, command) in steps.items():
        nt, nr = nominal_step(CONFIG, axis, command, fitted)
        ct, cr = nominal_step(CONFIG, axis, command, current)
        window = (t >= 0.0) & (t <= 0.25)
        rms = float(np.sqrt(np.mean((np.interp(t[window], nt, nr) - rate[window]) ** 2)))
        results[axis] = {"command_deg_s": command, "betaflight": step_metrics(t, rate, command),
                         "fitted": step_metrics(nt, nr, command), "fitted_rms_deg_s": rms,
                         "vehicle_file": step_metrics(ct, cr, command), "t_s": t.tolist(), "rate_deg_s": rate.tolist()}
        print(f"{axis}: Betaflight {results[axis]['betaflight']}; fitted {results[axis]['fitted']} "
              f"(rms {rms:.0f} deg/s); fpv5.toml {results[axis]['vehicle_file']}")
    print(f"fitted gains {np.round(fitted, 1).tolist()} 1/s; fpv5.toml {current}")
    _plot_steps(results)
    return results


def _plot_steps(results: dict[str, Any]) -> None:
    from aerobat.plotting import save_figure
    from aerobat.plotting.files import new_figure

    fig = new_figure(figsize=(12, 3.4))
    for ax, axis in zip(fig.subplots(1, 3), ("roll", "pitch", "yaw"), strict=True):
        r = results[axis]
        ax.plot(np.array(r["t_s"]) * 1e3, r["rate_deg_s"], "k.-", ms=3, label="Betaflight (true rate)")
        for gains, style, what in ((results["fitted_gains_per_s"], "C0-", "fitted"),
                                   (results["vehicle_file_gains_per_s"], "C1--", "fpv5.toml")):
            nt, nr = nominal_step(CONFIG, axis, r["command_deg_s"], tuple(gains))
            ax.plot(nt * 1e3, nr, style, label=f"nominal P loop, {what} {np.round(gains, 1).tolist()} 1/s")
        ax.axhline(r["command_deg_s"], color="0.7", lw=0.8)
        ax.set_xlim(-10, 300)
        ax.set_title(f"{axis} step {r['command_deg_s']:g} °/s", fontsize=9)
        ax.set_xlabel("time since the step reached the receiver [ms]")
        ax.legend(fontsize=6)
    fig.axes[0].set_ylabel("body rate [°/s]")
    save_figure(fig, OUT / "rate_steps.png")


# ------------------------------------------------------------------------ learn


def learn_one(name: str, seed: int, iterations_target: int, db: Path) -> dict[str, Any]:
    from aerobat.core.rules import RuleChoice
    from aerobat.experiments.sessions import start_session
    from aerobat.plants import PlantChoice
    from aerobat.store import Store

    maneuver = MultiFlip(vehicle=CONFIG.vehicle, **MANEUVERS[name])
    nominal = design(maneuver, NominalModel(CONFIG))
    started = time.perf_counter()
    iterations: list[Any] = []
    with Store(db) as store:
        run = start_session(store, maneuver, model=CONFIG, plant=PlantChoice("betaflight", seed=seed, feedback="none"),
                            rule=RuleChoice(), iterations=iterations_target, design_result=nominal,
                            command=("scripts/results_betaflight.py", "learn", name, str(seed)))
        outcome = run.run(on_iteration=iterations.append)
        session_id = run.id
    wall = time.perf_counter() - started
    measured = [it for it in iterations if it.status.value == "ok"]
    errors = np.array([it.error for it in measured])
    pos_idx = [i for i, e in enumerate(maneuver.errors) if e.kind.value == "position"]
    ang_idx = [i for i, e in enumerate(maneuver.errors) if e.kind.value == "angle"]
    pos = np.linalg.norm(errors[:, pos_idx], axis=1)
    last = slice(len(pos) - 10, len(pos))
    angles = np.degrees(np.abs(errors[last][:, ang_idx]))
    out = {"maneuver": maneuver.name, "seed": seed, "session": session_id, "status": outcome.status.value,
           "trials": len(iterations), "measured": len(measured),
           "statuses": [it.status.value for it in iterations],
           "duration_s": nominal.duration_s, "p_nominal": nominal.p_nominal.tolist(),
           "learned": (iterations[-1].params + iterations[-1].step).tolist(), "position_errors_m": pos.tolist(),
           "first_m": float(pos[0]), "last10_mean_m": float(pos[last].mean()),
           "last10_ratio": float(pos[last].mean() / pos[0]),
           "last10_angle_mean_abs_deg": {maneuver.errors[i].name: float(a) for i, a in zip(ang_idx, angles.mean(0),
                                                                                               strict=True)},
           "last10_angle_max_abs_deg": float(angles.max()), "wall_s": wall}
    print(f"{name} seed {seed}: first {out['first_m']:.3f} m, last-10 mean {out['last10_mean_m']:.3f} m "
          f"({100 * out['last10_ratio']:.0f} %), angles last 10 ≤ {out['last10_angle_max_abs_deg']:.2f}°, "
          f"{out['trials']} trials, {wall:.0f} s (session {session_id})")
    return out


def cmd_learn(db: Path, seeds: list[int]) -> dict[str, Any]:
    results = {f"{name}-seed-{seed}": learn_one(name, seed, 30, db) for name in MANEUVERS for seed in seeds}
    _plot_learning(results)
    return results


def _plot_learning(results: dict[str, Any]) -> None:
    from aerobat.plotting import save_figure
    from aerobat.plotting.files import new_figure

    fig = new_figure(figsize=(7, 3.6))
    ax = fig.subplots()
    for key, r in results.items():
        ax.semilogy(np.arange(1, len(r["position_errors_m"]) + 1), r["position_errors_m"], ".-", label=key)
    ax.axhline(0.15, color="0.6", lw=0.8, ls="--")
    ax.set_xlabel("measured trial")
    ax.set_ylabel("position error [m]")
    ax.set_title("learning through Betaflight 4.6 (SITL, lockstep)", fontsize=9)
    ax.legend(fontsize=7)
    save_figure(fig, OUT / "learning.png")


# ------------------------------------------------------------------------- gyro


def cmd_gyro() -> dict[str, Any]:
    """The nominal triple flip's first attempt and a roll step at 8 kHz and at 4 kHz, same seed."""
    maneuver = MultiFlip(vehicle=CONFIG.vehicle, **MANEUVERS["triple"])
    nominal = design(maneuver, NominalModel(CONFIG))
    out: dict[str, Any] = {}
    for rate in (8000, 4000):
        params = BetaflightParams().replace(firmware__gyro_rate_hz=rate)
        trials = []
        for seed in (1, 2, 3):
            plant = BetaflightPlant(CONFIG, params, seed=seed, feedback="none")
            trial = plant.fly(maneuver.program(nominal.p_nominal))
            peak = float(np.degrees(np.abs(plant.last_truth[1][:, 10]).max()))
            trials.append({"error": maneuver.error(trial.final_state).tolist(), "peak_roll_rate_deg_s": peak,
                           "info": {k: trial.info[k] for k in ("real_time_factor", "wall_s", "simulated_s", "hover")}})
        t, r = measure_step("roll", 1000.0, params=params)
        out[str(rate)] = {"trials": trials, "step": step_metrics(t, r, 1000.0)}
        e = np.array([tr["error"] for tr in trials])
        print(f"{rate} Hz: first-attempt errors {np.round(e[:, [0, 2, 5]], 3).tolist()} m, flip angle "
              f"{np.round(np.degrees(e[:, 4]), 2).tolist()}°, peak roll rate "
              f"{max(tr['peak_roll_rate_deg_s'] for tr in trials):.0f}°/s, real time ×"
              f"{np.mean([tr['info']['real_time_factor'] for tr in trials]):.1f}, step {out[str(rate)]['step']}")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("what", choices=("rate", "learn", "gyro", "all"))
    parser.add_argument("--db", type=Path, default=ROOT / "out" / "betaflight.sqlite")
    parser.add_argument("--seeds", default="1", help="comma list of plant seeds for learn")
    args = parser.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    args.db.parent.mkdir(parents=True, exist_ok=True)
    seeds = [int(s) for s in args.seeds.split(",")]
    todo = ("rate", "learn", "gyro") if args.what == "all" else (args.what,)
    for what in todo:
        result = cmd_rate() if what == "rate" else cmd_learn(args.db, seeds) if what == "learn" else cmd_gyro()
        suffix = "" if what != "learn" or seeds == [1] else "_" + "_".join(map(str, seeds))
        (OUT / f"{what}{suffix}.json").write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
