"""The firmware design model's numbers (issue 41): docs/plants.md and docs/method.md quote them.

Run (needs the Betaflight SITL, built by ``make setup``; ../shared/data for the ROMA F5):

    .venv/bin/python scripts/results_firmware_model.py agreement   # model vs SITL, noiseless (~30 s)
    .venv/bin/python scripts/results_firmware_model.py learn       # default world, seeds 1-5, both models (~8 min)
    .venv/bin/python scripts/results_firmware_model.py maneuvers   # pitch double flip, translation: first attempts
    .venv/bin/python scripts/results_firmware_model.py decompose   # the first attempt, world effect by effect
    .venv/bin/python scripts/results_firmware_model.py figure      # the paper model, the firmware model, a trial
    .venv/bin/python scripts/results_firmware_model.py smoothness  # where the firmware is not smooth (~1 min)
    .venv/bin/python scripts/results_firmware_model.py translation # why the translation does not converge
    .venv/bin/python scripts/results_firmware_model.py all

Each writes ``docs/figures/firmware_model/<name>.json`` (and the figure its PNG) and prints a table.
The ROMA F5 chain is ``scripts/results_roma.py --design-model firmware``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "figures" / "firmware_model"
ROMA_LOG = ROOT.parent / "shared" / "data" / "flight-logs" / "betaflight" / "diatone-roma-f5.bbl"
ROMA_IDENTIFY = ["--vehicle", "fpv5", "--mass-kg", "0.55", "--motor-x-m", "0.08", "--motor-y-m", "0.08"]


def _write(name: str, data: dict[str, Any]) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / f"{name}.json").write_text(json.dumps(data, indent=1) + "\n")


def _triple(config: Any, rate_deg_s: float = 1800.0) -> Any:
    from aerobat.quadrotor.maneuvers import MultiFlip

    return MultiFlip(vehicle=config.vehicle, flips=3, max_rate_rad_s=math.radians(rate_deg_s), dims=3)


def roma_setup(work: Path) -> tuple[Any, Any]:
    """The ROMA F5 as scripts/results_roma.py builds it: (vehicle, Betaflight params with its tune)."""
    import contextlib
    import io

    from aerobat.cli.app import main
    from aerobat.firmware.betaflight.tune import load_tune
    from aerobat.plants.fpv.params import load_betaflight
    from aerobat.quadrotor.vehicle import vehicle_from_name_or_file

    vehicle, airframe = work / "roma.toml", work / "roma_bf.toml"
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(["identify", "--log", f"{ROMA_LOG}:1", *ROMA_IDENTIFY, "--output", str(vehicle),
                     "--airframe", str(airframe)])
    if code != 0:
        raise SystemExit(f"identify --log exited {code}")
    params = dataclasses.replace(load_betaflight(airframe), tune=load_tune(ROMA_LOG))
    return vehicle_from_name_or_file(str(vehicle)), params


# -------------------------------------------------------------------- smoothness


def _largest_step(values: np.ndarray) -> float:
    """The largest step between neighbouring samples beyond its neighbours' mean (smooth: ~0; a jump: its size)."""
    steps = np.diff(values)
    return float(np.max(np.abs(steps[1:-1] - 0.5 * (steps[:-2] + steps[2:]))))


def sweep(model: Any, maneuver: Any, p: np.ndarray, index: int, half_width: float, points: int) -> dict[str, Any]:
    """Parameter ``index`` swept by ±``half_width`` around ``p``: the final position's largest step [m]."""
    params = np.tile(p, (points, 1))
    params[:, index] += np.linspace(-half_width, half_width, points)
    finals = model.final_states([maneuver.program(q) for q in params])
    return {"largest_step_m": max(_largest_step(finals[:, axis]) for axis in range(3)),
            "spacing": 2 * half_width / (points - 1), "points": points}


def jacobian_consistency(model: Any, maneuver: Any, p: np.ndarray) -> float:
    """‖J(h) − J(4h)‖/‖J(h)‖ in scaled coordinates, h = 1e-3 scale (central differences; smooth: ≪ 1)."""
    scales = np.array([spec.scale for spec in maneuver.parameters])
    errors = np.array([spec.scale for spec in maneuver.errors])

    def jac(step: float) -> np.ndarray:
        rows = []
        for k in range(p.size):
            plus, minus = p.copy(), p.copy()
            plus[k] += step * scales[k]
            minus[k] -= step * scales[k]
            finals = model.final_states([maneuver.program(plus), maneuver.program(minus)])
            rows.append((maneuver.error(finals[0]) - maneuver.error(finals[1])) / errors / (2 * step))
        return np.array(rows).T

    small, large = jac(1e-3), jac(4e-3)
    return float(np.linalg.norm(small - large) / np.linalg.norm(small))


def saturation(config: Any, maneuver: Any, p: np.ndarray) -> dict[str, Any]:
    """How much of the triple flip's p⁰ the motors spend at idle or full output, in the design model."""
    from aerobat.plants.fpv.design_model import firmware_design_model
    from aerobat.plants.fpv.params import BetaflightParams
    from aerobat.quadrotor.firmware.layout import K_MIN_COMMAND, K_MOTOR_HIGH, K_MOTOR_LOW

    model = firmware_design_model(config, BetaflightParams())
    flown = model.trajectory(maneuver.program(p))
    k = model.k  # the packet is (output − min_command − ½ µs of truncation's mean) / 1000 at design fidelity
    low = (k[K_MOTOR_LOW] - k[K_MIN_COMMAND] - 0.5) / 1000.0
    high = (k[K_MOTOR_HIGH] - k[K_MIN_COMMAND] - 0.5) / 1000.0
    at_idle = np.any(flown.motors <= low + 1e-9, axis=1)
    at_full = np.any(flown.motors >= high - 1e-9, axis=1)
    return {"packet_idle": low, "packet_full": high, "steps": int(flown.motors.shape[0]),
            "fraction_at_idle": float(np.mean(at_idle)), "fraction_at_full": float(np.mean(at_full)),
            "fraction_at_a_limit": float(np.mean(at_idle | at_full))}


def cmd_smoothness() -> dict[str, Any]:
    """Sweeps and Jacobians of both fidelities (and the paper's model) around the triple flip's firmware p⁰,
    and a design on each fidelity."""
    from aerobat.core.design import design
    from aerobat.plants.fpv.design_model import firmware_design_model
    from aerobat.plants.fpv.params import BetaflightParams
    from aerobat.quadrotor.simulate import NominalModel
    from aerobat.quadrotor.vehicle import fpv5

    config = fpv5()
    maneuver = _triple(config)
    paper = design(maneuver, NominalModel(config))
    models = {fidelity: firmware_design_model(config, BetaflightParams(), fidelity=fidelity)
              for fidelity in ("design", "exact")}
    data: dict[str, Any] = {"maneuver": maneuver.name}
    designs = {}
    for fidelity, model in models.items():
        started = time.perf_counter()
        designs[fidelity] = result = design(maneuver, model, p_guess=paper.p_nominal)
        data[f"design_on_{fidelity}"] = {"status": result.status.value, "residual": float(result.residual_norm),
                                         "simulations": int(result.evaluations),
                                         "wall_s": round(time.perf_counter() - started, 2)}
    p = designs["design"].p_nominal
    for name, model in (*models.items(), ("paper", NominalModel(config))):
        data[name] = {
            # p1, the accelerate stage's length: ±2 radio frames at 0.1 ms, ±1 ms at 10 µs (< a gyro period)
            "switch_time": sweep(model, maneuver, p, 1, 0.008, 161),
            "switch_time_fine": sweep(model, maneuver, p, 1, 0.001, 201),
            "collective": sweep(model, maneuver, p, 3, 0.05, 101),  # p3 ± 0.05 m/s²
            "jacobian_h_vs_4h": jacobian_consistency(model, maneuver, p)}
    data["saturation"] = saturation(config, maneuver, p)
    _write("smoothness", data)
    print(f"{maneuver.name}, around the design model's p0; largest step of the final position between neighbours")
    print("model     p1 ±8 ms /0.1 ms   p1 ±1 ms /10 us   p3 ±0.05 m/s2   |J(h)-J(4h)|/|J(h)|")
    for name in ("design", "exact", "paper"):
        row = data[name]
        steps = [row[key]["largest_step_m"] * 1000 for key in ("switch_time", "switch_time_fine", "collective")]
        print(f"{name:8s} {steps[0]:10.2f} mm {steps[1]:13.3f} mm {steps[2]:12.3f} mm {row['jacobian_h_vs_4h']:14.4f}")
    for fidelity in ("design", "exact"):
        print(f"designed on the {fidelity} fidelity: {data[f'design_on_{fidelity}']}")
    print(f"motors at idle or full {data['saturation']['fraction_at_a_limit']:.1%} of the flip's gyro periods")
    return data


# -------------------------------------------------------------------- agreement


def agreement_case(name: str, config: Any, params: Any, maneuver: Any) -> dict[str, Any]:
    """The firmware model (both fidelities) against the SITL flying the same program in a noiseless world."""
    from aerobat.experiments.designing import nominal_design
    from aerobat.plants import PlantChoice
    from aerobat.plants.betaflight.model_check import noiseless, sitl_flight
    from aerobat.plants.betaflight.plant import BetaflightPlant
    from aerobat.plants.fpv.design_model import firmware_design_model

    nominal = nominal_design(maneuver, config, plant=PlantChoice("betaflight", params), design_model="firmware")
    program = maneuver.program(nominal.design.p_nominal)
    model = firmware_design_model(config, params)
    started = time.perf_counter()
    sitl = sitl_flight(BetaflightPlant(config, noiseless(params, model), seed=0, feedback="none"), program)
    sitl_s = time.perf_counter() - started
    model.final_states([program])  # compiled already; timed below
    started = time.perf_counter()
    for _ in range(20):
        model.final_states([program])
    row: dict[str, Any] = {"case": name, "maneuver": maneuver.name, "steps": int(len(sitl.times_s)),
                           "sitl_flight_s": round(sitl_s, 3),
                           "model_flight_s": round((time.perf_counter() - started) / 20, 5),
                           "design_simulations": int(nominal.design.evaluations)}
    for fidelity in ("exact", "design"):
        flown = firmware_design_model(config, params, fidelity=fidelity).trajectory(program)
        n = min(len(sitl.times_s), len(flown.times_s))
        row[fidelity] = {
            "final_position_m": float(np.linalg.norm(sitl.states[n - 1, :3] - flown.states[n - 1, :3])),
            "final_rotation_deg": math.degrees(float(np.linalg.norm(sitl.states[n - 1, 17:20]
                                                                     - flown.states[n - 1, 17:20]))),
            "largest_motor_difference": float(np.max(np.abs(sitl.motors[:n] - flown.motors[:n]))),
            "largest_setpoint_difference_deg_s": float(np.max(np.abs(sitl.setpoint_deg_s[:n]
                                                                     - flown.setpoint_deg_s[:n]))),
        }
    return row


def cmd_agreement(work: Path) -> dict[str, Any]:
    from aerobat.plants.fpv.params import BetaflightParams
    from aerobat.quadrotor.vehicle import fpv5

    rows = [agreement_case("aerobat's tune, fpv5", fpv5(), BetaflightParams(), _triple(fpv5()))]
    if ROMA_LOG.is_file():
        config, params = roma_setup(work)
        rows.append(agreement_case("ROMA F5's tune and identified airframe", config, params, _triple(config, 600.0)))
    data = {"rows": rows}
    _write("agreement", data)
    print("case                                         fidelity  position [cm]  rotation [deg]  motors  set point")
    for row in rows:
        for fidelity in ("exact", "design"):
            r = row[fidelity]
            print(f"{row['case']:44s} {fidelity:8s}  {100 * r['final_position_m']:12.2f}  "
                  f"{r['final_rotation_deg']:14.3f}  {r['largest_motor_difference']:6.3f}  "
                  f"{r['largest_setpoint_difference_deg_s']:9.2f}")
        print(f"  one program: the SITL (power on, arm, take off, settle, hover, fly) {row['sitl_flight_s']:.2f} s, "
              f"the model {row['model_flight_s'] * 1000:.1f} ms; the design took {row['design_simulations']} "
              "simulations")
    return data


# ------------------------------------------------------------------------ learn


def learn_sessions(config: Any, maneuver: Any, plant: Any, design_model: str, seeds: list[int], trials: int,
                   db: Path) -> list[dict[str, Any]]:
    """One session per seed, open loop; every number read back from the store."""
    from aerobat.experiments.designing import nominal_design
    from aerobat.experiments.sessions import position_error_m, start_session
    from aerobat.store import Store

    nominal = nominal_design(maneuver, config, plant=plant, design_model=design_model)
    rows = []
    with Store(db) as store:
        for seed in seeds:
            started = time.perf_counter()
            run = start_session(store, maneuver, model=config, plant=dataclasses.replace(plant, seed=seed),
                                design_result=nominal, iterations=trials)
            outcome = run.run()
            records = store.iterations(outcome.session_id)
            errors = [position_error_m(maneuver, r.error) for r in records if r.status == "ok"]
            below = next((k + 1 for k, e in enumerate(errors) if e < 0.15), None)
            rows.append({"seed": seed, "session": outcome.session_id, "trials": len(records),
                         "measured": len(errors), "lost": len(records) - len(errors),
                         "first_m": errors[0] if errors else math.nan,
                         "last10_mean_m": float(np.mean(errors[-10:])) if errors else math.nan,
                         "trials_to_0.15_m": below, "wall_s": round(time.perf_counter() - started, 1)})
    return rows


def _summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    below = [r["trials_to_0.15_m"] for r in rows if r["trials_to_0.15_m"] is not None]
    return {"first_median_m": float(np.median([r["first_m"] for r in rows])),
            "first_range_m": [float(min(r["first_m"] for r in rows)), float(max(r["first_m"] for r in rows))],
            "last10_median_m": float(np.median([r["last10_mean_m"] for r in rows])),
            "trials_to_0.15_m_median": float(np.median(below)) if below else None,
            "lost": int(sum(r["lost"] for r in rows))}


def cmd_learn(work: Path, seeds: list[int], trials: int) -> dict[str, Any]:
    from aerobat.plants import PlantChoice
    from aerobat.quadrotor.vehicle import fpv5

    config = fpv5()
    maneuver = _triple(config)
    plant = PlantChoice("betaflight", feedback="none")
    data: dict[str, Any] = {"maneuver": maneuver.name, "seeds": seeds, "trials": trials}
    for model in ("paper", "firmware"):
        rows = learn_sessions(config, maneuver, plant, model, seeds, trials, work / f"learn-{model}.sqlite")
        data[model] = {"sessions": rows, **_summary(rows)}
    _write("learn", data)
    print(f"{maneuver.name}, default Betaflight world, open loop, {trials} trials, seeds {seeds}")
    print("model     first median [m] (range)   last-10 median [m]  trials to 0.15 m  lost")
    for model in ("paper", "firmware"):
        s = data[model]
        print(f"{model:8s}  {s['first_median_m']:7.3f} ({s['first_range_m'][0]:.3f}-{s['first_range_m'][1]:.3f})"
              f"      {s['last10_median_m']:10.3f}         {s['trials_to_0.15_m_median']}        {s['lost']}")
    return data


# -------------------------------------------------------------------- maneuvers


def first_attempts(config: Any, maneuver: Any, plant: Any, seeds: list[int]) -> dict[str, Any]:
    """The nominal design of each model flown once per seed: the first attempt's position error."""
    from aerobat.core.maneuver import position_indices
    from aerobat.experiments.designing import nominal_design

    out: dict[str, Any] = {}
    idx = position_indices(maneuver.errors)
    for model in ("paper", "firmware"):
        nominal = nominal_design(maneuver, config, plant=plant, design_model=model)
        program = maneuver.program(nominal.design.p_nominal)
        misses = []
        for seed in seeds:
            trial = dataclasses.replace(plant, seed=seed).build(config).fly(program)
            misses.append(float(np.linalg.norm(maneuver.error(trial.final_state)[idx])) if trial.ok else math.nan)
        predicted = nominal.design.residual
        out[model] = {"design": nominal.design.status.value, "design_s": round(nominal.compute_s, 2),
                      "design_residual": float(nominal.design.residual_norm), "design_message": nominal.design.message,
                      "design_residual_errors": dict(zip([e.name for e in maneuver.errors], map(float, predicted),
                                                         strict=True)),
                      "first_m": misses, "median_m": float(np.nanmedian(misses))}
    out["ratio"] = out["paper"]["median_m"] / out["firmware"]["median_m"]
    return out


def cmd_maneuvers(seeds: list[int]) -> dict[str, Any]:
    from aerobat.plants import PlantChoice
    from aerobat.quadrotor.maneuvers import MultiFlip, translation_maneuver
    from aerobat.quadrotor.vehicle import fpv5

    config = fpv5()
    plant = PlantChoice("betaflight", feedback="none")
    cases = {"pitch double flip at 1400 deg/s": MultiFlip(vehicle=config.vehicle, flips=2, axis="pitch",
                                                          max_rate_rad_s=math.radians(1400), dims=3),
             "translation to (5, 5) m": translation_maneuver(config, (5.0, 5.0))}
    data = {name: first_attempts(config, maneuver, plant, seeds) for name, maneuver in cases.items()}
    _write("maneuvers", {"seeds": seeds, **data})
    print(f"first attempts through Betaflight (default world, open loop, seeds {seeds})")
    print("maneuver                          paper median [m]  firmware median [m]  ratio")
    for name, r in data.items():
        print(f"{name:32s}  {r['paper']['median_m']:16.3f}  {r['firmware']['median_m']:19.3f}  {r['ratio']:5.1f}")
    return data


def cmd_translation() -> dict[str, Any]:
    """Why the translation to (5, 5) m does not converge on the firmware model: its final y against each switch
    duration, near the paper model's p⁰, in steps of 0.1, 1 and 2 ms."""
    from aerobat.experiments.designing import nominal_design
    from aerobat.plants import PlantChoice
    from aerobat.plants.fpv.design_model import firmware_design_model
    from aerobat.plants.fpv.params import BetaflightParams
    from aerobat.quadrotor.maneuvers import translation_maneuver
    from aerobat.quadrotor.vehicle import fpv5

    config = fpv5()
    maneuver = translation_maneuver(config, (5.0, 5.0))
    p0 = nominal_design(maneuver, config, plant=PlantChoice("betaflight", feedback="none"),
                        design_model="paper").design.p_nominal
    model = firmware_design_model(config, BetaflightParams())
    steps = (-2e-3, -1e-3, -1e-4, 0.0, 1e-4, 1e-3, 2e-3)

    def y_error(p: np.ndarray) -> float:
        return float(maneuver.error(model.final_states([maneuver.program(p)])[0])[0])

    rows = []
    for k in range(len(p0)):
        ys = []
        for h in steps:
            p = p0.copy()
            p[k] += h
            ys.append(y_error(p))
        slopes = [(ys[i + 1] - ys[i]) / (steps[i + 1] - steps[i]) for i in range(len(steps) - 1)]
        rows.append({"parameter": f"p{k}", "y_m": ys, "slopes_m_per_s": slopes})
    _write("translation", {"steps_s": list(steps), "p0": p0.tolist(), "rows": rows})
    print("translation to (5, 5) m on the firmware model: y error [m] with p_k of the paper's p0 moved by "
          + ", ".join(f"{1e3 * h:+g} ms" for h in steps))
    for r in rows:
        lo, hi = min(r["slopes_m_per_s"]), max(r["slopes_m_per_s"])
        print(f"  {r['parameter']}: " + " ".join(f"{y:+.3f}" for y in r["y_m"])
              + f"   slopes between neighbours {lo:+.0f} … {hi:+.0f} m/s")
    return {"rows": rows}


# -------------------------------------------------------------------- decompose


def decompose(config: Any, params: Any, maneuver: Any, seed: int) -> list[dict[str, Any]]:
    """The firmware design's first attempt in the noiseless world, then with each of the world's effects."""
    from aerobat.core.maneuver import position_indices
    from aerobat.experiments.designing import nominal_design
    from aerobat.plants import PlantChoice
    from aerobat.plants.betaflight.model_check import noiseless
    from aerobat.plants.betaflight.plant import BetaflightPlant
    from aerobat.plants.fpv.design_model import firmware_design_model

    nominal = nominal_design(maneuver, config, plant=PlantChoice("betaflight", params), design_model="firmware")
    program = maneuver.program(nominal.design.p_nominal)
    clean = noiseless(params, firmware_design_model(config, params))
    frame = params.airframe
    variants = {
        "the model's world (noiseless)": clean,
        "+ gyro scale errors": clean.replace(sensors=dataclasses.replace(
            clean.sensors, gyro_scale_error=params.sensors.gyro_scale_error)),
        "+ centre-of-mass offset": clean.replace(airframe=dataclasses.replace(
            clean.airframe, com_offset_m=frame.com_offset_m)),
        "+ uneven motors": clean.replace(airframe=dataclasses.replace(clean.airframe, thrust_gains=frame.thrust_gains)),
        "+ sensor noise and bias": clean.replace(sensors=dataclasses.replace(params.sensors,
                                                                            gyro_scale_error=(0.0, 0.0, 0.0))),
        "+ wind, gusts, jitter": clean.replace(disturbances=params.disturbances),
        "+ radio losses": clean.replace(radio=params.radio),
        "+ motion-capture noise": clean.replace(motion_capture=params.motion_capture),
        "the full world": params,
    }
    idx = position_indices(maneuver.errors)
    names = [e.name for e in maneuver.errors]
    motors = firmware_design_model(config, params).trajectory(program).motors  # the design model's own flight
    rows = [{"world": "the design model (p⁰ on the model)", "status": "model",
             "full_motor_steps": float(np.mean(motors.max(axis=1) >= 0.999)),
             "p_nominal": [float(v) for v in nominal.design.p_nominal]}]
    for name, world in variants.items():
        trial = BetaflightPlant(config, world, seed=seed, feedback="none").fly(program)
        e = maneuver.error(trial.final_state)
        rows.append({"world": name, "status": trial.status.value, "position_m": float(np.linalg.norm(e[idx])),
                     "flip_angle_deg": (math.degrees(float(e[names.index("flip_angle")])) if "flip_angle" in names
                                        else math.nan),
                     "errors": dict(zip(names, (float(v) for v in e), strict=True))})
    return rows


def cmd_decompose(work: Path) -> dict[str, Any]:
    from aerobat.plants.fpv.params import BetaflightParams
    from aerobat.quadrotor.vehicle import fpv5

    data = {"default": decompose(fpv5(), BetaflightParams(), _triple(fpv5()), seed=1)}
    if ROMA_LOG.is_file():
        config, params = roma_setup(work)
        data["roma"] = decompose(config, params, _triple(config, 600.0), seed=0)
        # the same without the pack's sag under load (issue 42): the chain as it was before identification wrote it
        data["roma_no_battery"] = decompose(config, params.replace(airframe__battery_rest_v=None,
                                                                   airframe__battery_sag_v=0.0),
                                            _triple(config, 600.0), seed=0)
    _write("decompose", data)
    for case, rows in data.items():
        print(f"{case}: the firmware design's first attempt, one world effect at a time")
        model, *flown = rows
        print(f"  p⁰ {np.round(model['p_nominal'], 3)}: on the model a motor at full output in "
              f"{100 * model['full_motor_steps']:.1f} % of the gyro periods")
        for r in flown:
            print(f"  {r['world']:32s} {r['status']:8s} position {r['position_m']:6.3f} m  "
                  f"flip angle {r['flip_angle_deg']:+6.1f} deg")
    return data


# ----------------------------------------------------------------------- figure


def cmd_figure() -> dict[str, Any]:
    """The same program flown by the paper's model, the firmware model and the Betaflight plant (seed 1)."""
    from aerobat.experiments.designing import nominal_design
    from aerobat.plants import PlantChoice
    from aerobat.plants.fpv.design_model import firmware_design_model
    from aerobat.plants.fpv.params import BetaflightParams
    from aerobat.plotting.files import save_figure
    from aerobat.plotting.firmware import plot_model_comparison
    from aerobat.quadrotor.simulate import simulate
    from aerobat.quadrotor.vehicle import fpv5

    config = fpv5()
    maneuver = _triple(config)
    plant = PlantChoice("betaflight", seed=1, feedback="none")
    nominal = nominal_design(maneuver, config, plant=plant, design_model="firmware")
    program = maneuver.program(nominal.design.p_nominal)
    paper = simulate(program, config)
    firmware = firmware_design_model(config, BetaflightParams()).trajectory(program)
    flying = plant.build(config)
    trial = flying.fly(program)
    truth_t, truth_x = flying.last_truth  # type: ignore[attr-defined]
    fig = plot_model_comparison(
        [("paper's model", paper.times_s, paper.states), ("firmware model", firmware.times_s, firmware.states),
         ("Betaflight SITL trial (seed 1)", truth_t, truth_x)],
        title=f"{maneuver.name}: p⁰ of the firmware model")
    OUT.mkdir(parents=True, exist_ok=True)
    save_figure(fig, OUT / "overlay.png", dpi=130)
    e = maneuver.error(trial.final_state)
    data = {"trial_status": trial.status.value, "trial_errors": [float(v) for v in e]}
    _write("figure", data)
    print(f"figure written to {OUT / 'overlay.png'}")
    return data


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("what", choices=("agreement", "learn", "maneuvers", "decompose", "figure", "smoothness",
                                         "translation", "all"))
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5], help="plant seeds")
    parser.add_argument("--trials", type=int, default=30, help="trials per learning session")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="aerobat-firmware-model-") as folder:
        work = Path(folder)
        if args.what in ("agreement", "all"):
            cmd_agreement(work)
        if args.what in ("decompose", "all"):
            cmd_decompose(work)
        if args.what in ("maneuvers", "all"):
            cmd_maneuvers(args.seeds[:3])
        if args.what in ("figure", "all"):
            cmd_figure()
        if args.what in ("smoothness", "all"):
            cmd_smoothness()
        if args.what in ("translation", "all"):
            cmd_translation()
        if args.what in ("learn", "all"):
            cmd_learn(work, args.seeds, args.trials)
    return 0


if __name__ == "__main__":
    sys.exit(main())
