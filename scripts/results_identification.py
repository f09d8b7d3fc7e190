"""Regenerate the numbers and figures of the "Identification" section of docs/results.md (about 8 minutes).

Run: .venv/bin/python scripts/results_identification.py [--quick]

1. Identify the default arena's vehicle on seeds 1-5 (prior: Table 1) and compare every parameter with
   what the arena's true vehicle defines.
2. Design the 3D triple flip (1800 deg/s) on Table 1 and on the vehicle identified on arena seed 0; fly
   the first attempt and learn (the paper's rule) on arena seeds 1-20, both designs on the same seeds.
3. The same first attempt on RotorPy (identified on RotorPy seed 0, flown on seeds 1-5).
4. The vehicle library: envelope and a grid of 2D flips per preset.
``--quick`` runs fewer seeds (for a smoke test).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

from aerobat import hummingbird
from aerobat.core.design import design
from aerobat.core.learning import learn
from aerobat.core.maneuver import position_indices
from aerobat.experiments.identify import identify, write_identified_vehicle
from aerobat.experiments.vehicles import flip_feasibility, vehicle_envelope, vehicle_library
from aerobat.plants import Arena, PlantChoice
from aerobat.plants.arena import ArenaParams
from aerobat.plotting import save_figure
from aerobat.plotting.identification import plot_identification
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ROOT / "docs" / "figures"
OUT = ROOT / "out" / "identification"
H = hummingbird()
TOLERANCE_M = 0.12


def arena_truth() -> dict[str, float]:
    """What the default arena's true vehicle (and, marked, its onboard loop and aerodynamics) define."""
    p = ArenaParams()
    tv, ob, aero = p.true_vehicle, p.onboard, p.aerodynamics
    gains = np.array(tv.thrust_gains)
    mean = float(gains.mean())
    g = gains / mean
    v, c = H.vehicle, H.controller
    stiffness = np.array([c.inertia_xx_kg_m2 * c.rate_gain_p_per_s, c.inertia_yy_kg_m2 * c.rate_gain_q_per_s,
                          c.inertia_zz_kg_m2 * c.rate_gain_r_per_s * tv.drag_constant_scale * mean])
    shortfall = np.array(aero.rotational_damping_n_m_s) / stiffness + np.array(ob.gyro_scale_error)
    return {
        "hover_command_m_s2": v.gravity_m_s2 * tv.mass_scale / mean,
        "collective_gain": mean / tv.mass_scale,
        "collective_max": 4 * v.rotor_thrust_max_n * mean / (v.mass_kg * tv.mass_scale),
        "collective_min": 4 * v.rotor_thrust_min_n * mean / (v.mass_kg * tv.mass_scale),
        "motor_rate_up": tv.motor_rate_up_per_s,
        "motor_rate_down": tv.motor_rate_down_per_s,
        "mass_kg": v.mass_kg * tv.mass_scale,
        "inertia_xx_kg_m2": v.inertia_xx_kg_m2 * tv.inertia_scale[0],
        "inertia_yy_kg_m2": v.inertia_yy_kg_m2 * tv.inertia_scale[1],
        "inertia_ratio_yy_xx": tv.inertia_scale[1] / tv.inertia_scale[0],
        "rate_gain_r": c.rate_gain_r_per_s * tv.drag_constant_scale / tv.inertia_scale[2] * mean,
        "moment_arm_p": -tv.com_offset_m[1] + v.arm_length_m * (g[1] - g[3]) / 4,
        "moment_arm_q": tv.com_offset_m[0] - v.arm_length_m * (g[0] - g[2]) / 4,
        "motor_gain_roll": (g[1] - g[3]) / 2,
        "motor_gain_pitch": (g[0] - g[2]) / 2,
        "motor_gain_yaw": (g[0] + g[2] - g[1] - g[3]) / 4,
        "com_x_m": tv.com_offset_m[0],
        "com_y_m": tv.com_offset_m[1],
        # not the true vehicle's: the onboard loop's and the aerodynamics' (equivalent values)
        "rate_latency_p": (ob.gyro_latency_samples + 0.5) / ob.rate_hz,
        "rate_shortfall_p": float(shortfall[0]),
        "rate_shortfall_q": float(shortfall[1]),
        "rate_shortfall_r": float(shortfall[2]),
        "rotor_drag": aero.rotor_drag_s_m,
        "body_drag": aero.body_drag_n_s2_m2,
    }


# what each compared quantity is, its unit (and a display factor), and whether the true vehicle defines it
ROWS = [
    ("hover_command_m_s2", "hover command g/k", "m/s²", 1, True),
    ("collective_gain", "collective gain k = m_c/m", "-", 1, True),
    ("collective_max", "4 f_max/m", "m/s²", 1, True),
    ("collective_min", "4 f_min/m", "m/s²", 1, True),
    ("motor_rate_up", "motor rate up", "1/s", 1, True),
    ("motor_rate_down", "motor rate down", "1/s", 1, True),
    ("mass_kg", "mass (m_c/k)", "kg", 1, True),
    ("inertia_xx_kg_m2", "I_xx (I_c,xx P/K_p)", "g m²", 1e3, True),
    ("inertia_yy_kg_m2", "I_yy (I_c,yy P/K_q)", "g m²", 1e3, True),
    ("inertia_ratio_yy_xx", "I_yy/I_xx", "-", 1, True),
    ("rate_gain_r", "yaw gain K_r (∝ κ/I_zz)", "1/s", 1, True),
    ("moment_arm_p", "roll moment per thrust A_p", "mm", 1e3, True),
    ("moment_arm_q", "pitch moment per thrust A_q", "mm", 1e3, True),
    ("motor_gain_yaw", "yaw-pair motor difference δ_r", "%", 100, True),
    ("motor_gain_roll", "motor 2 vs 4 difference δ_p", "%", 100, True),
    ("motor_gain_pitch", "motor 1 vs 3 difference δ_q", "%", 100, True),
    ("com_x_m", "centre of mass x (A_q + l δ_q/2)", "mm", 1e3, True),
    ("com_y_m", "centre of mass y (−A_p + l δ_p/2)", "mm", 1e3, True),
    ("rate_latency_p", "roll latency (gyro 1 tick + ½ tick hold)", "ms", 1e3, False),
    ("rate_shortfall_p", "roll rate shortfall (damping + gyro scale)", "%", 100, False),
    ("rate_shortfall_q", "pitch rate shortfall", "%", 100, False),
    ("rate_shortfall_r", "yaw rate shortfall", "%", 100, False),
    ("rotor_drag", "rotor drag", "s/m", 1, False),
    ("body_drag", "body drag", "10⁻³ N s²/m²", 1e3, False),
]


def fitted_values(run) -> dict[str, float]:
    fit = run.fit
    values = {row["name"]: row["value"] for row in fit.parameter_rows()}
    values.update({name: value for name, (value, _) in fit.derived().items()})
    arm = fit.config.effects.thrust_moment_arm_m
    values["com_x_m"], values["com_y_m"] = arm[1], -arm[0]
    return values


def section_parameters(seeds: list[int]) -> list[object]:
    print("\n## 1. Identification on the default arena (prior: Table 1)\n")
    truth = arena_truth()
    runs = []
    for seed in seeds:
        run = identify(PlantChoice("arena", seed=seed), H)
        runs.append(run)
        fit = run.fit
        print(f"seed {seed}: {len(run.flights)} flights ({len(fit.trials)} trials used), residual "
              f"{fit.position_rms_m * 1e3:.2f} mm / {math.degrees(fit.angle_rms_rad):.3f}° RMS, fit "
              f"{fit.wall_s:.1f} s, run {run.wall_s:.1f} s; notes: {'; '.join(run.notes) or '-'}")
        if seed == seeds[0]:
            save_figure(plot_identification(fit), FIGURES / "identification_arena.png", dpi=80)
    values = [fitted_values(r) for r in runs]
    print(f"\n| quantity | unit | arena's true value | identified, mean ± std over {len(seeds)} seeds | "
          f"min … max | worst error |")
    print("|---|---|---:|---:|---:|---:|")
    for key, label, unit, factor, defined in ROWS:
        want = truth[key] * factor
        got = np.array([v[key] for v in values]) * factor
        worst = float(np.max(np.abs(got / want - 1.0))) * 100 if want != 0 else math.nan
        mark = "" if defined else " (not the true vehicle's)"
        flag = "**" if defined and worst > 10 else ""
        print(f"| {label}{mark} | {unit} | {want:.4g} | {got.mean():.4g} ± {got.std():.2g} | "
              f"{got.min():.4g} … {got.max():.4g} | {flag}{worst:.1f} %{flag} |")
    return runs


def flip() -> MultiFlip:
    return MultiFlip(vehicle=H.vehicle, flips=3, dims=3)


def first_and_trials(maneuver: MultiFlip, result, seeds: list[int], iterations: int) -> tuple[list[float], list]:
    idx = position_indices(maneuver.errors)
    firsts, ttt = [], []
    for seed in seeds:
        session = learn(maneuver, result, Arena(H, seed=seed, feedback="none"), iterations=iterations, force=True)
        errors = [float(np.linalg.norm(it.error[idx])) for it in session.measured]
        firsts.append(errors[0])
        ttt.append(next((k + 1 for k, e in enumerate(errors) if e < TOLERANCE_M), math.inf))
    return firsts, ttt


def section_arena_flip(seeds: list[int], extra_runs: list[object], iterations: int) -> None:
    print("\n## 2. The 3D triple flip at 1800°/s on the arena: designed on Table 1 and on the identified model\n")
    OUT.mkdir(parents=True, exist_ok=True)
    run0 = identify(PlantChoice("arena", seed=0), H)
    path = OUT / "arena_seed0.toml"
    identified = write_identified_vehicle(run0, path)
    print(f"identified on arena seed 0 ({len(run0.flights)} flights) -> {path.relative_to(ROOT)}")
    rows = []
    for label, config in (("Table 1", H), ("identified (arena seed 0)", identified)):
        m = MultiFlip(vehicle=config.vehicle, flips=3, dims=3)
        started = time.perf_counter()
        result = design(m, NominalModel(config))
        print(f"design on {label}: {result.status.value}, residual {result.residual_norm:.3g}, "
              f"{time.perf_counter() - started:.1f} s; {result.message[:240]}")
        firsts, ttt = first_and_trials(m, result, seeds, iterations)
        rows.append((label, firsts, ttt))
    print(f"\n| design model | first attempt ‖(x,y,z)‖, median [min … max] over seeds {seeds[0]}–{seeds[-1]} | "
          f"median trials to {TOLERANCE_M} m | reached on the first trial |")
    print("|---|---:|---:|---:|")
    for label, firsts, ttt in rows:
        finite = [t for t in ttt if math.isfinite(t)]
        print(f"| {label} | {np.median(firsts):.3f} m [{min(firsts):.3f} … {max(firsts):.3f}] | "
              f"{np.median(ttt):g} ({len(finite)}/{len(ttt)} reached in {iterations}) | "
              f"{sum(1 for t in ttt if t == 1)}/{len(ttt)} |")
    ratio = np.median(rows[1][1]) / np.median(rows[0][1])
    print(f"\nmedian first attempt, identified / Table 1: {ratio:.2f}")
    print("per seed (first attempt Table 1 → identified, trials to 0.12 m):")
    print(", ".join(f"{s}: {a:.2f}→{b:.2f} m ({ta:g}→{tb:g})" for s, a, b, ta, tb in
                    zip(seeds, rows[0][1], rows[1][1], rows[0][2], rows[1][2], strict=True)))
    if extra_runs:
        print("\nfirst attempt on the same seeds, designed on each vehicle of section 1 (median [max]):")
        for run in extra_runs:
            config = run.fit.config
            m = MultiFlip(vehicle=config.vehicle, flips=3, dims=3)
            result = design(m, NominalModel(config))
            idx = position_indices(m.errors)
            program = m.program(result.p_nominal)
            errors = [float(np.linalg.norm(m.error(Arena(H, seed=s, feedback="none").fly(program).final_state)[idx]))
                      for s in seeds]
            print(f"  identified on arena seed {run.plant.seed}: {np.median(errors):.3f} m [{max(errors):.3f}]")


def section_rotorpy(seeds: list[int]) -> None:
    print("\n## 3. RotorPy: the first attempt of the 3D triple flip\n")
    from aerobat.plants.rotorpy import RotorPyPlant

    run = identify(PlantChoice("rotorpy", seed=0), H)
    fit = run.fit
    save_figure(plot_identification(fit), FIGURES / "identification_rotorpy.png", dpi=80)
    print(f"identified on RotorPy seed 0: {len(run.flights)} flights, residual {fit.position_rms_m * 1e3:.2f} mm / "
          f"{math.degrees(fit.angle_rms_rad):.3f}° RMS, run {run.wall_s:.0f} s")
    print("  " + ", ".join(f"{r['name']} {r['value']:.4g}" for r in fit.parameter_rows()))
    results = {}
    for label, config in (("Table 1", H), ("identified (RotorPy seed 0)", fit.config)):
        m = MultiFlip(vehicle=config.vehicle, flips=3, dims=3)
        result = design(m, NominalModel(config))
        idx = position_indices(m.errors)
        errors = []
        for seed in seeds:
            trial = RotorPyPlant(H, seed=seed, feedback="none").fly(m.program(result.p_nominal))
            errors.append(float(np.linalg.norm(m.error(trial.final_state)[idx])))
        results[label] = errors
        print(f"design on {label}: {result.status.value}; first attempt on seeds {seeds}: "
              f"{', '.join(f'{e:.3f}' for e in errors)} m (mean {np.mean(errors):.3f} m)")
    a, b = (np.mean(v) for v in results.values())
    print(f"\nmean first attempt falls from {a:.3f} m to {b:.3f} m ({(1 - b / a) * 100:.0f} % less)")


def section_presets() -> None:
    print("\n## 4. The vehicle library\n")
    print("| preset | T/W | β̲ / β̄ [m/s²] | max roll / pitch acc. [rad/s²] | "
          "2D flips designed (✓) and refused (✗, why) |")
    print("|---|---:|---:|---:|---|")
    for config in vehicle_library():
        env = vehicle_envelope(config)
        cells = []
        for f in flip_feasibility(config, (1, 2, 3), (720.0, 1080.0, 1440.0, 1800.0)):
            head = f"{f.flips}×{f.max_rate_deg_s:g}"
            if f.feasible:
                cells.append(f"{head} ✓")
            else:
                limits = [name for name in ("β̲", "β̄", "zero duration") if name in f.reason]
                cells.append(f"{head} ✗ ({', '.join(limits) or f.reason.split(';')[0][:40]})")
        print(f"| {config.name} | {env['thrust_to_weight']:.2f} | {env['collective_reduced_min_m_s2']:.2f} / "
              f"{env['collective_reduced_max_m_s2']:.2f} | {env['max_roll_acceleration_rad_s2']:.0f} / "
              f"{env['max_pitch_acceleration_rad_s2']:.0f} | {'; '.join(cells)} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer seeds (smoke test)")
    args = parser.parse_args()
    FIGURES.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    ident_seeds = [1, 2] if args.quick else [1, 2, 3, 4, 5]
    learn_seeds = list(range(1, 4)) if args.quick else list(range(1, 21))
    runs = section_parameters(ident_seeds)
    section_arena_flip(learn_seeds, runs, iterations=6 if args.quick else 15)
    section_rotorpy([1, 2] if args.quick else [1, 2, 3, 4, 5])
    section_presets()
    print(f"\n(all of this took {time.perf_counter() - started:.0f} s)")


if __name__ == "__main__":
    main()
