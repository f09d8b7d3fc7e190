"""RotorPy plant benchmarks and results (issue 7): integrator speed and accuracy, trial cost, learning.

Benchmarks, not tests: they measure and report, they never fail on a number.

    .venv/bin/python benchmarks/bench_rotorpy.py speed            # integrators, s per trial
    .venv/bin/python benchmarks/bench_rotorpy.py learn --figures docs/figures
    .venv/bin/python benchmarks/bench_rotorpy.py all --write out/bench_rotorpy.md

``speed`` flies the nominal 3D triple flip (designed on aerobat's Table 1 model) open loop
through ``Multirotor.step`` at 800 Hz with every integrator and compares each trajectory with a
tight DOP853 reference; then it times whole supervised trials. ``learn`` runs the 40-iteration
triple flip and a 2D single flip on the RotorPy plant and draws the figures for
the RotorPy section of docs/results.md. Needs the ``rotorpy`` extra.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from aerobat import hummingbird, simulate  # noqa: E402
from aerobat.core.design import design  # noqa: E402
from aerobat.core.learning import learn  # noqa: E402
from aerobat.plants.rotorpy import RotorPyPlant, RotorPySettings  # noqa: E402
from aerobat.quadrotor.maneuvers import MultiFlip  # noqa: E402
from aerobat.quadrotor.simulate import NominalModel  # noqa: E402

CONFIG = hummingbird()
INTEGRATORS = ("RK45 (RotorPy default)", "RK45", "RK23", "LSODA", "rk4", "rk3")


def machine() -> str:
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    cpu = platform.processor() or platform.machine()
    return (f"{platform.system()} {platform.release()}, Python {platform.python_version()}, {cpu}, "
            f"{os.cpu_count()} logical CPUs, 1-min load average {load[0]:.1f} when this section started")


def triple_flip() -> tuple[MultiFlip, object]:
    maneuver = MultiFlip(vehicle=CONFIG.vehicle, flips=3, dims=3)
    return maneuver, design(maneuver, NominalModel(CONFIG))


def _open_loop(plant: RotorPyPlant, commands: np.ndarray) -> tuple[np.ndarray, float]:
    """(N+1, 13) trajectory (x, v, q xyzw, w) and wall seconds for one open-loop pass."""
    state = plant.hover_state()
    rows = [np.concatenate([state["x"], state["v"], state["q"], state["w"]])]
    start = time.perf_counter()
    for cmd in commands:
        state = plant.vehicle.step(state, {"cmd_thrust": plant.mass_kg * cmd[0], "cmd_w": cmd[1:4]}, plant.tick_s)
        rows.append(np.concatenate([state["x"], state["v"], state["q"], state["w"]]))
    return np.array(rows), time.perf_counter() - start


def _plant_with(integrator: str) -> RotorPyPlant:
    if integrator == "RK45 (RotorPy default)":
        plant = RotorPyPlant(CONFIG, settings=RotorPySettings(integrator="RK45"))
        plant.vehicle.integrator_kwargs = {"method": "RK45"}  # exactly RotorPy's default: no first_step
        return plant
    return RotorPyPlant(CONFIG, settings=RotorPySettings(integrator=integrator))  # type: ignore[arg-type]


def _attitude_difference_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    dot = np.abs(np.sum(a * b, axis=1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1)))
    return np.degrees(2.0 * np.arccos(np.clip(dot, -1.0, 1.0)))


def bench_integrators(repeats: int = 3) -> dict:
    maneuver, result = triple_flip()
    compiled = maneuver.program(result.p_nominal).compile()
    tick = 1.0 / 800.0
    n = math.ceil(compiled.duration_s / tick - 1e-9) + 40  # the flip and 50 ms of hover after it
    commands = compiled.evaluate(np.arange(n) * tick)
    reference_plant = _plant_with("rk3")
    reference_plant.vehicle.integrator_kwargs = {"method": "DOP853", "rtol": 1e-11, "atol": 1e-11}
    reference, _ = _open_loop(reference_plant, commands)
    rows = []
    for name in INTEGRATORS:
        plant = _plant_with(name)
        times = []
        for _ in range(repeats):
            traj, wall = _open_loop(plant, commands)
            times.append(wall)
        wall = statistics.median(times)
        kwargs = plant.vehicle.integrator_kwargs
        rows.append({
            "integrator": name,
            "kwargs": {k: (v.__name__ if isinstance(v, type) else v) for k, v in kwargs.items()},
            "steps_per_s": n / wall,
            "max_position_m": float(np.abs(traj[:, 0:3] - reference[:, 0:3]).max()),
            "max_velocity_m_s": float(np.abs(traj[:, 3:6] - reference[:, 3:6]).max()),
            "max_attitude_deg": float(_attitude_difference_deg(traj[:, 6:10], reference[:, 6:10]).max()),
            "max_rate_rad_s": float(np.abs(traj[:, 10:13] - reference[:, 10:13]).max()),
        })
    nominal = simulate(compiled, CONFIG, mode="sampled").final_state
    miss = reference[-41, 0:3] - nominal[0:3]
    return {"steps": n, "rows": rows, "open_loop_final_miss_m": miss.tolist(), "machine": machine()}


def bench_trials(trials: int = 4) -> dict:
    maneuver, result = triple_flip()
    program = maneuver.program(result.p_nominal)
    plant = RotorPyPlant(CONFIG, seed=0)
    walls, steps, man_steps = [], [], math.ceil(program.duration_s * 800 - 1e-9)
    for _ in range(trials):
        trial = plant.fly(program)
        walls.append(trial.info["wall_s"])
        steps.append(trial.info["steps"])
    return {"trials": trials, "median_s_per_trial": statistics.median(walls), "mean_steps": float(np.mean(steps)),
            "maneuver_steps": man_steps, "steps_per_s": float(np.sum(steps) / np.sum(walls)), "machine": machine()}


def _figures(session, config, out: Path, stem: str) -> None:
    from aerobat.plotting import save_figure
    from aerobat.plotting.learning import plot_learning
    from aerobat.plotting.vehicle import plot_side_views

    m = session.maneuver
    nominal = simulate(m.program(session.design.p_nominal), config)
    measured = [it for it in session.iterations if it.status == "ok" and it.trial is not None]
    panels = [("nominal (aerobat model)", nominal.times_s, nominal.states),
              (f"first attempt on RotorPy (iteration {measured[0].index})", measured[0].trial.times_s,
               measured[0].trial.states),
              (f"learned (iteration {measured[-1].index})", measured[-1].trial.times_s, measured[-1].trial.states)]
    save_figure(plot_side_views(panels, plane="yz", title=f"{m.name} on RotorPy"),
                out / f"rotorpy_{stem}_side_views.png", dpi=130)
    data = session.to_json_dict()
    save_figure(plot_learning(data["iterations"], data["error_names"], data["error_units"], data["parameter_names"],
                              data["parameter_units"], title=f"{m.name} on RotorPy"),
                out / f"rotorpy_{stem}_learning.png")


def _summary(session, position_idx: list[int], angle_idx: list[int], last: int) -> dict:
    errors = np.array([it.error for it in session.measured])
    pos = np.linalg.norm(errors[:, position_idx], axis=1)
    angles = np.degrees(np.abs(errors[:, angle_idx]))
    walls = [it.trial.info["wall_s"] for it in session.measured]
    return {
        "status": session.status,
        "iterations": len(session.measured),
        "first_position_error_m": float(pos[0]),
        "first_angle_errors_deg": angles[0].tolist(),
        "first_error": errors[0].tolist(),
        f"last{last}_mean_position_error_m": float(pos[-last:].mean()),
        f"last{last}_max_angle_error_deg": float(angles[-last:].max()),
        "ratio": float(pos[-last:].mean() / pos[0]),
        "position_error_per_iteration_m": pos.tolist(),
        "p_nominal": session.design.p_nominal.tolist(),
        "p_learned": session.final_params.tolist(),
        "wall_s": session.wall_s,
        "median_s_per_trial": statistics.median(walls),
    }


def bench_learning(figures: Path | None, seed: int = 0) -> dict:
    out: dict = {"machine": machine()}
    maneuver, result = triple_flip()
    session = learn(maneuver, result, RotorPyPlant(CONFIG, seed=seed), iterations=40)
    out["triple_3d_1800"] = _summary(session, [0, 2, 5], [4, 7, 8], 10)
    if figures is not None:
        _figures(session, CONFIG, figures, "triple")
    single = MultiFlip(vehicle=CONFIG.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
    single_design = design(single, NominalModel(CONFIG))
    session = learn(single, single_design, RotorPyPlant(CONFIG, seed=seed), iterations=15)
    out["single_2d_800"] = _summary(session, [0, 2], [4], 5)
    if figures is not None:
        _figures(session, CONFIG, figures, "single")
    return out


def markdown(results: dict) -> str:
    lines = []
    if "integrators" in results:
        r = results["integrators"]
        lines += [f"Open-loop nominal 3D triple flip + 50 ms hover ({r['steps']} steps at 800 Hz) on the adapted "
                  "RotorPy Hummingbird, aero on; largest deviation from DOP853 (rtol = atol = 1e-11) along the "
                  f"whole trajectory. Machine: {r['machine']}.", "",
                  "| integrator | integrator_kwargs | steps/s | position [m] | velocity [m/s] | attitude [°] "
                  "| body rate [rad/s] |", "|---|---|---:|---:|---:|---:|---:|"]
        for row in r["rows"]:
            lines.append(f"| {row['integrator']} | `{row['kwargs']}` | {row['steps_per_s']:.0f} | "
                         f"{row['max_position_m']:.1e} | {row['max_velocity_m_s']:.1e} | "
                         f"{row['max_attitude_deg']:.1e} | {row['max_rate_rad_s']:.1e} |")
        miss = np.linalg.norm(r["open_loop_final_miss_m"])
        lines += ["", f"Open-loop final position minus aerobat's sampled nominal model: {miss:.3f} m.", ""]
    if "trials" in results:
        t = results["trials"]
        lines += [f"Supervised triple-flip trials (settle, flip, measure, return; default settings, rk3): "
                  f"{t['median_s_per_trial']:.2f} s per trial (median of {t['trials']}), {t['mean_steps']:.0f} "
                  f"steps per trial of which {t['maneuver_steps']} are the maneuver, {t['steps_per_s']:.0f} "
                  f"steps/s overall. Machine: {t['machine']}.", ""]
    if "learning" in results:
        for key, s in results["learning"].items():
            if key == "machine":
                lines += [f"Learning machine: {s}.", ""]
                continue
            last = "last10" if "last10_mean_position_error_m" in s else "last5"
            lines += [f"**{key}**: {s['status']}, {s['iterations']} iterations; first position error "
                      f"{s['first_position_error_m']:.3f} m (angles {np.round(s['first_angle_errors_deg'], 2)} °); "
                      f"{last} mean {s[f'{last}_mean_position_error_m']:.3f} m "
                      f"({100 * s['ratio']:.1f} % of the first), {last} max angle error "
                      f"{s[f'{last}_max_angle_error_deg']:.2f}°; {s['wall_s']:.0f} s wall, "
                      f"{s['median_s_per_trial']:.2f} s per trial (median).", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=("speed", "learn", "all"))
    parser.add_argument("--figures", type=Path, default=None, help="directory for rotorpy_*.png figures")
    parser.add_argument("--write", type=Path, default=None, help="write the markdown report here")
    parser.add_argument("--json", type=Path, default=None, help="write the raw results here")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    results: dict = {}
    if args.what in ("speed", "all"):
        results["integrators"] = bench_integrators()
        results["trials"] = bench_trials()
    if args.what in ("learn", "all"):
        if args.figures is not None:
            args.figures.mkdir(parents=True, exist_ok=True)
        results["learning"] = bench_learning(args.figures, seed=args.seed)
    text = markdown(results)
    print(text)
    if args.write:
        args.write.parent.mkdir(parents=True, exist_ok=True)
        args.write.write_text(text + "\n")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
