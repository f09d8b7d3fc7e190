"""aerobat benchmarks: ``make bench`` runs this and rewrites docs/performance.md.

Benchmarks, not tests: they measure and report, they never fail on a number.

The machine these run on is usually shared, so the headline figures are *ratios*
measured in one process, interleaved round by round, against a reference that
suffers the same load: aerobat's simulation kernel against the bare RK4 of the
same model in ``benchmarks/reference.py`` (the machine's limit), and two threads
against one. Single-thread kernels are timed on the thread's CPU clock, so time
the scheduler gives to other processes does not count. Absolute times (the
design, the first ``learn``) are wall-clock medians and say how loaded the machine
was (the load average is printed with them).

``python benchmarks/run.py --json`` prints one JSON object instead of the report.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import platform
import re
import select
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from reference import constants, reference_run  # noqa: E402

from aerobat import hummingbird, load_program  # noqa: E402
from aerobat.core.design import design  # noqa: E402
from aerobat.core.learning import learn  # noqa: E402
from aerobat.plants import Arena  # noqa: E402
from aerobat.quadrotor.dynamics import N_STATE, controller_vector, hover_state, plant_vector  # noqa: E402
from aerobat.quadrotor.maneuvers import MultiFlip  # noqa: E402
from aerobat.quadrotor.playback import run_continuous  # noqa: E402
from aerobat.quadrotor.program import RampDown  # noqa: E402
from aerobat.quadrotor.simulate import NominalModel, _run_batch, _steps, batch_threads, set_batch_threads  # noqa: E402

CONFIG = hummingbird()
OTHER_MARKER = "<!-- other benchmarks: kept by make bench -->"
MAX_STEP_S = 5e-4
# p⁰ of the 3D triple flip (tests/core/test_design.py pins it): the kernel workload
P0_3D = np.array([21.147414905322183, 0.2489405172107463, 0.40965469406191607, 21.281144061832844,
                  0.2944397583640787, 8.21327673052149e-05, 0.005610005735469527, -0.0021228918136138486,
                  -0.009274212359579277])
TRIPLE_3D = MultiFlip(vehicle=CONFIG.vehicle, flips=3, dims=3)
# the design's own program plus a ramp-down of the rate commands: every kind of segment the
# kernel meets (constant, linear and quadratic commands, both ramps)
WORKLOAD = dataclasses.replace(TRIPLE_3D.program(P0_3D), ramp_down=RampDown(collective_s=0.1, rates_s=0.15))
FIXED_CMD = np.array([12.0, 3.0, -1.0, 0.5])  # the reference's one constant command
EMPTY = (np.empty(0), np.empty((0, N_STATE)), np.empty((0, 4)))  # nothing recorded


def stolen_s() -> float | None:
    """CPU time the hypervisor gave to other virtual machines so far (the ``steal`` of /proc/stat) [s]."""
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def load() -> str:
    try:
        return "load average " + " ".join(f"{v:.1f}" for v in os.getloadavg())
    except OSError:
        return "load average unknown"


def interleaved(fns: dict, rounds: int, clock=time.perf_counter) -> dict:
    """Time every function once per round, in turn, for ``rounds`` rounds; {name: [seconds per round]}."""
    for fn in fns.values():
        fn()
    times: dict = {name: [] for name in fns}
    for _ in range(rounds):
        for name, fn in fns.items():
            start = clock()
            fn()
            times[name].append(clock() - start)
    return times


def ratio(fast: list, slow: list) -> float:
    """Speed of ``slow``'s workload relative to ``fast``'s, from the least-disturbed rounds (the minima)."""
    return min(fast) / min(slow)


# ------------------------------------------------------------------ kernels


def bench_kernel(rounds: int = 31) -> dict:
    """aerobat's continuous-mode kernel (program sampling and ramps included) vs the reference, one thread."""
    compiled = WORKLOAD.compile()
    bp, coeffs = compiled.breakpoints_s, compiled.coefficients
    steps = _steps(bp, MAX_STEP_S)
    plant, ctrl = plant_vector(CONFIG.vehicle), controller_vector(CONFIG.controller)
    x0 = hover_state(CONFIG.vehicle)
    c = constants(CONFIG.vehicle, CONFIG.controller)
    repeats = 20

    one = (x0[None, :], bp[None, :], coeffs[None], np.array([len(bp) - 1]), plant[None, :], ctrl[None, :],
           np.zeros((1, 3)), MAX_STEP_S, np.empty((1, N_STATE)), np.zeros(1, dtype=np.int64), *EMPTY)

    def kernel():  # one vehicle, one program, nothing recorded: what simulate(record=False) runs
        for _ in range(repeats):
            run_continuous(*one)

    def reference():
        for _ in range(repeats):
            reference_run(x0.copy(), FIXED_CMD, c, MAX_STEP_S, steps)

    t = interleaved({"kernel": kernel, "reference": reference}, rounds, clock=time.thread_time)
    per_round = [r / k for k, r in zip(t["kernel"], t["reference"], strict=True)]
    return {"steps": steps, "segments": len(bp) - 1,
            "kernel_steps_s": steps * repeats / min(t["kernel"]),
            "reference_steps_s": steps * repeats / min(t["reference"]),
            "kernel_vs_reference": ratio(t["reference"], t["kernel"]),
            "kernel_vs_reference_median_round": statistics.median(per_round)}


def _batch_inputs(n: int):
    compiled = WORKLOAD.compile()
    k = len(compiled.breakpoints_s) - 1
    bp = np.tile(compiled.breakpoints_s, (n, 1))
    coeffs = np.tile(compiled.coefficients, (n, 1, 1, 1))
    nseg = np.full(n, k, dtype=np.int64)
    plants = np.tile(plant_vector(CONFIG.vehicle), (n, 1))
    plants[:, 0] *= np.linspace(0.95, 1.05, n)  # vary the mass: n different vehicles
    ctrl = np.tile(controller_vector(CONFIG.controller), (n, 1))
    x0 = np.tile(hover_state(CONFIG.vehicle), (n, 1))
    delays = np.zeros((n, 3))  # no rate-loop latency
    return x0, bp, coeffs, nseg, plants, ctrl, delays, _steps(compiled.breakpoints_s, MAX_STEP_S) * n


def bench_batch(n: int = 1000, rounds: int = 9) -> dict:
    """The batch kernel: one thread against the reference, and two threads against one."""
    x0, bp, coeffs, nseg, plants, ctrl, delays, steps = _batch_inputs(n)
    out = np.empty_like(x0)
    c = constants(CONFIG.vehicle, CONFIG.controller)
    threads = batch_threads()

    def batch():
        _run_batch(x0, bp, coeffs, nseg, plants, ctrl, delays, MAX_STEP_S, out)

    def reference():  # the same number of vehicle-steps through the reference
        for b in range(n):
            reference_run(x0[b].copy(), FIXED_CMD, c, MAX_STEP_S, steps // n)

    set_batch_threads(1)
    try:
        t1 = interleaved({"batch": batch, "reference": reference}, rounds, clock=time.thread_time)
    finally:
        set_batch_threads(None)

    def one_thread():
        set_batch_threads(1)
        try:
            batch()
        finally:
            set_batch_threads(None)

    # wall clock (the worker threads run on other cores), and the process's CPU time alongside: on a
    # loaded machine the wall clock also counts time the scheduler gave to other jobs, the CPU time does not
    wall: dict = {"1": [], "n": []}
    cpu: dict = {"1": [], "n": []}
    one_thread()
    batch()
    for _ in range(rounds):
        for name, fn in (("1", one_thread), ("n", batch)):
            w, c0 = time.perf_counter(), time.process_time()
            fn()
            cpu[name].append(time.process_time() - c0)
            wall[name].append(time.perf_counter() - w)
    tp = wall
    # with the work split evenly, each thread's share of the CPU time is what the wall clock would be
    # on idle cores; the extra CPU time of the threaded run (start-up, waiting, contention) counts against it
    cpu_speedup = min(cpu["1"]) / (min(cpu["n"]) / threads)
    return {"vehicles": n, "threads": threads,
            "batch_speedup_threads_cpu": cpu_speedup,
            "batch_1_thread_steps_s": steps / min(t1["batch"]),
            "reference_steps_s": steps / min(t1["reference"]),
            "batch_vs_reference": ratio(t1["reference"], t1["batch"]),
            "batch_wall_1_thread_steps_s": steps / min(tp["1"]),
            "batch_wall_n_threads_steps_s": steps / min(tp["n"]),
            "batch_speedup_threads": min(tp["1"]) / min(tp["n"]),
            "batch_speedup_threads_median": statistics.median(tp["1"]) / statistics.median(tp["n"])}


# ------------------------------------------------------------------- design


def bench_design(rounds: int = 15) -> dict:
    out = {"load": load()}
    for dims in (2, 3):
        m = MultiFlip(vehicle=CONFIG.vehicle, flips=3, dims=dims)
        model = NominalModel(CONFIG)
        t = interleaved({"design": lambda m=m, model=model: design(m, model)}, rounds)["design"]
        d = design(m, model)
        out[dims] = {"median_s": statistics.median(t), "min_s": min(t), "evaluations": d.evaluations,
                     "status": d.status.value}
        if dims == 3:
            out["p0_3d_max_abs_diff"] = float(np.max(np.abs(d.p_nominal - P0_3D)))
    return out


def bench_firmware_design(rounds: int = 5) -> dict:
    """The 3D triple flip at 1800 °/s designed on the Betaflight plant's firmware model (both stages), and the
    model's speed: gyro periods (8 kHz) flown per second on one thread."""
    from aerobat.experiments.designing import nominal_design
    from aerobat.plants import PlantChoice
    from aerobat.plants.fpv.design_model import firmware_design_model
    from aerobat.plants.fpv.params import BetaflightParams
    from aerobat.quadrotor.simulate import set_batch_threads
    from aerobat.quadrotor.vehicle import fpv5

    config = fpv5()
    flip = MultiFlip(vehicle=config.vehicle, flips=3, max_rate_rad_s=math.radians(1800), dims=3)
    plant = PlantChoice("betaflight", feedback="none")
    nominal = nominal_design(flip, config, plant=plant)  # compiled and cached
    t = interleaved({"design": lambda: nominal_design(flip, config, plant=plant)}, rounds)["design"]
    model = firmware_design_model(config, BetaflightParams())
    program = flip.program(nominal.design.p_nominal)
    set_batch_threads(1)
    try:
        one = interleaved({"fly": lambda: model.final_states([program])}, 9)["fly"]
    finally:
        set_batch_threads(None)
    steps = program.duration_s * model.firmware.gyro_rate_hz
    return {"load": load(), "median_s": statistics.median(t), "min_s": min(t), "status": nominal.design.status.value,
            "evaluations": nominal.design.evaluations + (nominal.paper.evaluations if nominal.paper else 0),
            "flight_ms": statistics.median(one) * 1e3, "steps_per_s": steps / statistics.median(one)}


# ---------------------------------------------------------------- processes

ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")
FIRST_TRIAL = re.compile(r"^\s+1\s+(ok|\w+)\s")


def _time_to_line(argv: list[str], pattern: re.Pattern, env: dict, cwd: str, timeout_s: float = 300.0) -> dict:
    """Run ``argv`` on a pseudo-terminal (as a user would); wall time to the first line matching ``pattern``."""
    import pty

    master, slave = pty.openpty()
    start = time.perf_counter()
    proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=slave, stderr=slave, env=env, cwd=cwd)
    os.close(slave)
    first = None
    buffer = b""
    lines = []
    try:
        while True:
            ready, _, _ = select.select([master], [], [], timeout_s)
            if not ready:
                break
            try:
                chunk = os.read(master, 65536)
            except OSError:  # the child closed the terminal
                break
            if not chunk:
                break
            buffer += chunk
            *complete, buffer = buffer.split(b"\n")
            for raw in complete:
                line = ANSI.sub("", raw.decode(errors="replace")).rstrip("\r")
                lines.append(line)
                if first is None and pattern.search(line):
                    first = time.perf_counter() - start
    finally:
        proc.wait()
        os.close(master)
    total = time.perf_counter() - start
    return {"first_s": first, "total_s": total, "status": proc.returncode, "lines": lines}


def _cli_env(**extra: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"), COLUMNS="120", **extra)
    return env


def bench_first_learn(cold: bool = True) -> dict:
    """Wall time from starting ``aerobat learn … --trials 1`` to its first trial line.

    ``warm``: with the compiled code that ``make setup`` leaves in numba's cache (as a user's
    first command after setup); ``cold``: with an empty cache (what setup saves).
    """
    argv = [sys.executable, "-m", "aerobat.cli", "learn", "flip", "--flips", "3", "--dims", "3", "--plant", "arena",
            "--trials", "1", "--out", "out", "--db", "aerobat.sqlite"]
    result = {}
    runs = {"warm": {}}
    if cold:
        runs["cold"] = {}
    for name in runs:
        with tempfile.TemporaryDirectory() as work:
            env = _cli_env()
            if name == "cold":
                env["NUMBA_CACHE_DIR"] = str(Path(work) / "numba-cache")
            r = _time_to_line(argv, FIRST_TRIAL, env, work)
        if r["first_s"] is None:
            raise RuntimeError(f"no trial line from {' '.join(argv)}:\n" + "\n".join(r["lines"][-20:]))
        result[name] = {"first_trial_s": r["first_s"], "total_s": r["total_s"]}
    result["load"] = load()
    return result


def bench_cli() -> dict:
    cmd = [sys.executable, "-m", "aerobat.cli", "simulate", str(ROOT / "examples" / "single_flip.toml"), "--json"]
    env = _cli_env()
    subprocess.run(cmd, check=True, capture_output=True, env=env)  # warm the cache
    warm = []
    for _ in range(5):
        start = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True, env=env)
        warm.append(time.perf_counter() - start)
    return {"warm_s": statistics.median(warm)}


def bench_arena() -> dict:
    triple = load_program(ROOT / "examples" / "triple_flip_1800.toml")
    arena = Arena(CONFIG, seed=1)
    arena.fly(triple)
    times = []
    for _ in range(20):
        start = time.perf_counter()
        arena.fly(triple)
        times.append(time.perf_counter() - start)
    d = design(TRIPLE_3D, NominalModel(CONFIG))
    start = time.perf_counter()
    learn(TRIPLE_3D, d, Arena(CONFIG, seed=1), iterations=60)
    return {"trial_ms": statistics.median(times) * 1e3, "learn60_s": time.perf_counter() - start}


def bench_betaflight_section() -> list[str]:
    """Lockstep and timing of the Betaflight plant (``benchmarks/bench_betaflight.py``), as markdown lines."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from aerobat.firmware.betaflight.errors import FirmwareUnavailable

    lines = ["## Betaflight firmware in the loop (`benchmarks/bench_betaflight.py`)", ""]
    try:
        import bench_betaflight

        rows, _ = bench_betaflight.run()
    except FirmwareUnavailable as error:
        return [*lines, f"Not measured: the SITL is unavailable here ({str(error).splitlines()[0]}).", ""]
    return [*lines, "| what | target | measured |", "|---|---|---|", *[f"| {a} | {b} | {c} |" for a, b, c in rows],
            "", "A trial is one whole Fig. 8 iteration from power-on: calibration, arming, take-off from the floor",
            "2.5 m below the start, settling, the flip, the return, landing and disarming.", ""]


def bench_exchange_load_section(rounds: int = 5) -> list[str]:
    """The exchange at load 0, 1 and 2 (``benchmarks/bench_exchange_load.py``), as markdown lines."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from aerobat.firmware.betaflight.errors import FirmwareUnavailable

    try:
        import bench_exchange_load

        results = bench_exchange_load.run(rounds)
    except FirmwareUnavailable as error:
        return ["## Betaflight on a shared machine", "",
                f"Not measured: the SITL is unavailable here ({str(error).splitlines()[0]}).", ""]
    return [*bench_exchange_load.section(results, rounds), ""]


def bench_logs_section() -> list[str]:
    """Reading and identifying from real flight logs (``benchmarks/bench_logs.py``), as markdown lines."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import bench_logs

    rows = bench_logs.run()
    return ["## Real flight logs (`benchmarks/bench_logs.py`)", "", "| what | target | measured |", "|---|---|---|",
            *[f"| {a} | {b} | {c} |" for a, b, c in rows], ""]


def bench_store_section() -> list[str]:
    """The store and the browser at 100,000 sessions (``benchmarks/browse_load.py``), as markdown lines."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import browse_load

    return browse_load.section(browse_load.run())


def machine() -> str:
    cpu = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, numba {numba.__version__}, "
            f"numpy {np.__version__}, {platform.system()} {platform.release()}")


# ------------------------------------------------------------------ report


def measure(quick: bool = False) -> dict:
    stolen_before = stolen_s()
    kernel = bench_kernel(rounds=11 if quick else 31)
    batch = bench_batch(n=200 if quick else 1000, rounds=5 if quick else 15)
    des = bench_design(rounds=5 if quick else 15)
    firmware = bench_firmware_design(rounds=2 if quick else 5)
    first = bench_first_learn(cold=not quick)
    cli = bench_cli()
    arena = bench_arena()
    stolen_after = stolen_s()
    return {
        "kernel_vs_reference": kernel["kernel_vs_reference"],
        "batch_vs_reference": batch["batch_vs_reference"],
        f"batch_speedup_{batch['threads']}_threads": batch["batch_speedup_threads"],
        "design_3d_s": des[3]["median_s"],
        "design_2d_s": des[2]["median_s"],
        "first_learn_start_s": first["warm"]["first_trial_s"],
        "first_learn_start_empty_cache_s": first.get("cold", {}).get("first_trial_s"),
        "design_firmware_3d_s": firmware["median_s"],
        "kernel": kernel, "batch": batch, "design": {str(k): v for k, v in des.items()}, "first_learn": first,
        "firmware_design": firmware,
        "cli": cli, "arena": arena, "machine": machine(), "cores": os.cpu_count(),
        "measured": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "stolen_s": None if stolen_before is None or stolen_after is None else stolen_after - stolen_before,
    }


def report(r: dict, betaflight: list[str] | None = None) -> str:
    """The markdown of docs/performance.md; ``betaflight``: :func:`bench_betaflight_section`'s lines."""
    k, b, d, f = r["kernel"], r["batch"], r["design"], r["first_learn"]
    n = b["threads"]
    rows = [
        ("aerobat's kernel ÷ the reference, one thread (program sampling and ramps included)", "≥ 0.8",
         f"**{k['kernel_vs_reference']:.2f}** (median round {k['kernel_vs_reference_median_round']:.2f})"),
        (f"batch of {b['vehicles']} vehicles, one thread ÷ the reference", "≥ 0.8",
         f"**{b['batch_vs_reference']:.2f}**"),
        (f"batch of {b['vehicles']} vehicles, {n} threads ÷ 1 thread", "≥ 1.85",
         f"**{b['batch_speedup_threads']:.2f}** (medians: {b['batch_speedup_threads_median']:.2f})"),
        ("design of the 3D triple flip (p⁰, J, C), warm; its p⁰ against the one pinned in tests/core/test_design.py",
         "≤ 50 ms on a quiet machine (issue 46); 1e-9",
         f"**{d['3']['median_s'] * 1e3:.0f} ms** median, {d['3']['min_s'] * 1e3:.0f} ms best "
         f"({d['3']['evaluations']} simulations); p⁰ within {d['p0_3d_max_abs_diff']:.1e}"),
        ("design of the 2D triple flip (p⁰, J, C), warm", "—",
         f"{d['2']['median_s'] * 1e3:.0f} ms median, {d['2']['min_s'] * 1e3:.0f} ms best "
         f"({d['2']['evaluations']} simulations)"),
        ("design of the 3D triple flip at 1800 °/s on the Betaflight firmware model (fpv5, aerobat's settings): "
         "the paper's model, then the firmware model from its p⁰", "≤ 10 s",
         f"**{r['firmware_design']['median_s']:.2f} s** median, {r['firmware_design']['min_s']:.2f} s best "
         f"({r['firmware_design']['evaluations']} simulations, {r['firmware_design']['status']})"),
        ("the firmware model flying that p⁰ (0.94 s at 8 kHz), one thread", "—",
         f"{r['firmware_design']['flight_ms']:.1f} ms ({r['firmware_design']['steps_per_s'] / 1e6:.2f} M gyro "
         f"periods/s)"),
        ("first `aerobat learn flip --flips 3 --dims 3 --plant arena --trials 1` after `make setup`: "
         "start to its first trial line", "≤ 3 s", f"**{f['warm']['first_trial_s']:.2f} s**"),
    ]
    if "cold" in f:
        rows.append(("the same with an empty numba cache (what setup's warm-up saves)", "—",
                     f"{f['cold']['first_trial_s']:.1f} s"))
    rows += [
        ("`aerobat simulate single_flip.toml --json`, a whole process", "≤ 2 s", f"{r['cli']['warm_s']:.2f} s"),
        ("one complete arena trial (settle, upload, trigger, flip, measure, return)", "≤ 50 ms",
         f"{r['arena']['trial_ms']:.1f} ms"),
        ("60 learning iterations of the 3D triple flip on the arena", "≤ 10 s", f"{r['arena']['learn60_s']:.1f} s"),
    ]
    absolute = [
        ("reference: bare RK4 of the same model, one thread", f"{k['reference_steps_s'] / 1e6:.1f} M steps/s"),
        ("aerobat's kernel, one thread", f"{k['kernel_steps_s'] / 1e6:.1f} M steps/s"),
        ("aerobat's batch, 1 thread (wall clock)", f"{b['batch_wall_1_thread_steps_s'] / 1e6:.1f} M vehicle-steps/s"),
        (f"aerobat's batch, {n} threads (wall clock)",
         f"{b['batch_wall_n_threads_steps_s'] / 1e6:.1f} M vehicle-steps/s"),
    ]
    lines = [
        "# Performance",
        "",
        "Measured by `make bench` (`benchmarks/run.py`), which rewrites this file; `python benchmarks/run.py --json`",
        "prints the same figures as one JSON object. Tests never assert wall-clock times; these numbers are the",
        "record.",
        "",
        f"Machine: {r['machine']}. The machine is shared with other jobs, so the first three rows are ratios",
        "measured in one process, interleaved round by round, against work that suffers the same load: the bare",
        "RK4 of the same model in `benchmarks/reference.py` (fixed inputs, no program, nothing recorded, constants",
        "precomputed, the machine's limit) and one thread against several. Single-thread rows use the thread's",
        "CPU clock; the thread-scaling row uses wall clock (best of the interleaved rounds).",
        f"Measured: {r['measured']}; wall-clock rows under {d['load']} ({r['cores']} cores)"
        + ("." if r.get("stolen_s") is None else
           f"; the hypervisor gave {r['stolen_s']:.1f} s of CPU time to other machines during the run."),
        "",
        "| what | target | measured |",
        "|---|---|---|",
        *[f"| {a} | {b_} | {c} |" for a, b_, c in rows],
        "",
        "Absolute speeds of the same runs (they move with the load; the ratios above do not):",
        "",
        "| what | measured |",
        "|---|---|",
        *[f"| {a} | {c} |" for a, c in absolute],
        "",
        "Kernel workload: the 3D triple flip at its p⁰ with ramp-downs on the collective (0.1 s) and on the",
        f"rate commands (0.15 s): {k['segments']} segments of constant, linear and quadratic commands, continuous",
        f"mode, 0.5 ms RK4 steps ({k['steps']} per flight); the batch varies the mass over ±5 % across the vehicles.",
        "",
        *(betaflight or []),
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--write", metavar="FILE", help="write the markdown report here")
    parser.add_argument("--json", action="store_true", help="print one JSON object with every figure")
    parser.add_argument("--quick", action="store_true", help="fewer rounds, no empty-cache run (a smoke test)")
    args = parser.parse_args()
    if not args.json:
        print("benchmarking (a few minutes)…", flush=True)
    results = measure(quick=args.quick)
    if args.json:
        print(json.dumps(results, default=float))
        return
    # the firmware and log benches: the report only, not --json
    text = report(results, bench_betaflight_section() + bench_exchange_load_section() + bench_logs_section()
                  + bench_store_section())
    print(text)
    if args.write:
        # keep the hand-measured sections that follow the marker (other benchmark scripts)
        target = Path(args.write)
        kept = ""
        if target.exists() and OTHER_MARKER in target.read_text():
            kept = target.read_text()[target.read_text().index(OTHER_MARKER):]
        target.write_text(text + ("\n" + kept if kept else ""))
        print(f"written to {args.write}")


if __name__ == "__main__":
    main()
