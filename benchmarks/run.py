"""aerobat benchmarks: ``make bench`` runs this and rewrites docs/performance.md.

Benchmarks, not tests: they measure and report, they never fail on a number.
Each figure is the median of several repeats after JIT warm-up unless noted.
"""

from __future__ import annotations

import argparse
import os
import platform
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

from aerobat import hummingbird, load_program, simulate  # noqa: E402
from aerobat.core.design import design  # noqa: E402
from aerobat.core.learning import learn  # noqa: E402
from aerobat.plants import Arena  # noqa: E402
from aerobat.quadrotor.dynamics import N_STATE, controller_vector, hover_state, plant_vector  # noqa: E402
from aerobat.quadrotor.maneuvers import MultiFlip  # noqa: E402
from aerobat.quadrotor.simulate import _batch_continuous, _run_continuous, _steps  # noqa: E402

CONFIG = hummingbird()
OTHER_MARKER = "<!-- other benchmarks: kept by make bench -->"
TRIPLE = load_program(ROOT / "examples" / "triple_flip_1800.toml")


def median_time(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def bench_single() -> dict:
    compiled = TRIPLE.compile()
    steps = _steps(compiled.breakpoints_s, 5e-4)
    kernel_args = (compiled.breakpoints_s, compiled.coefficients, len(compiled.breakpoints_s) - 1,
                   plant_vector(CONFIG.vehicle), controller_vector(CONFIG.controller), 5e-4,
                   np.empty(0), np.empty((0, N_STATE)), np.empty((0, 4)))
    x0 = hover_state(CONFIG.vehicle)
    numba.set_num_threads(1)

    def kernel():
        for _ in range(20):
            _run_continuous(x0.copy(), *kernel_args)

    t_kernel = median_time(kernel, 7) / 20

    def api():
        for _ in range(20):
            simulate(compiled, CONFIG, record=False)

    t_api = median_time(api, 7) / 20
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    return {"steps": steps, "kernel_steps_s": steps / t_kernel, "api_steps_s": steps / t_api,
            "api_ms": t_api * 1e3}


def bench_batch(n: int = 1000) -> dict:
    compiled = TRIPLE.compile()
    k = len(compiled.breakpoints_s) - 1
    bp = np.tile(compiled.breakpoints_s, (n, 1))
    coeffs = np.tile(compiled.coefficients, (n, 1, 1, 1))
    nseg = np.full(n, k, dtype=np.int64)
    plants = np.tile(plant_vector(CONFIG.vehicle), (n, 1))
    plants[:, 0] *= np.linspace(0.95, 1.05, n)  # vary the mass: 1000 different vehicles
    ctrl = np.tile(controller_vector(CONFIG.controller), (n, 1))
    x0 = np.tile(hover_state(CONFIG.vehicle), (n, 1))
    out = np.empty_like(x0)
    steps = _steps(compiled.breakpoints_s, 5e-4) * n
    results = {}
    for threads in (1, numba.config.NUMBA_NUM_THREADS):
        numba.set_num_threads(threads)
        t = median_time(lambda: _batch_continuous(x0, bp, coeffs, nseg, plants, ctrl, 5e-4, out), 5)
        results[threads] = steps / t
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    return results


def bench_cli() -> dict:
    exe = str(Path(sys.executable).with_name("aerobat"))
    cmd = [exe, "simulate", str(ROOT / "examples" / "single_flip.toml"), "--json"]
    subprocess.run(cmd, check=True, capture_output=True)  # warm the cache
    warm = []
    for _ in range(5):
        start = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        warm.append(time.perf_counter() - start)
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        start = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True, env=env)
        cold = time.perf_counter() - start
    return {"warm_s": statistics.median(warm), "first_jit_s": cold}


def bench_design() -> dict:
    out = {}
    for dims in (2, 3):
        m = MultiFlip(vehicle=CONFIG.vehicle, flips=3, dims=dims)
        from aerobat.quadrotor.simulate import NominalModel

        model = NominalModel(CONFIG)
        out[dims] = median_time(lambda m=m, model=model: design(m, model), 5)
    return out


def bench_arena() -> dict:
    arena = Arena(CONFIG, seed=1)
    arena.fly(TRIPLE)
    times = []
    for _ in range(20):
        start = time.perf_counter()
        arena.fly(TRIPLE)
        times.append(time.perf_counter() - start)
    m = MultiFlip(vehicle=CONFIG.vehicle, flips=3, dims=3)
    from aerobat.quadrotor.simulate import NominalModel

    d = design(m, NominalModel(CONFIG))
    start = time.perf_counter()
    learn(m, d, Arena(CONFIG, seed=1), iterations=60)
    return {"trial_ms": statistics.median(times) * 1e3, "learn60_s": time.perf_counter() - start}


def bench_betaflight_section() -> list[str]:
    """Lockstep and timing of the Betaflight plant (``benchmarks/bench_betaflight.py``), as markdown lines."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from aerobat.plants.betaflight.errors import FirmwareUnavailable

    lines = ["## Betaflight firmware in the loop (`benchmarks/bench_betaflight.py`)", ""]
    try:
        import bench_betaflight

        rows, _ = bench_betaflight.run()
    except FirmwareUnavailable as error:
        return [*lines, f"Not measured: the SITL is unavailable here ({str(error).splitlines()[0]}).", ""]
    return [*lines, "| what | target | measured |", "|---|---|---|", *[f"| {a} | {b} | {c} |" for a, b, c in rows],
            "", "A trial is one whole Fig. 8 iteration from power-on: calibration, arming, take-off from the floor",
            "2.5 m below the start, settling, the flip, the return, landing and disarming.", ""]


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--write", metavar="FILE", help="write the markdown report here")
    args = parser.parse_args()
    print("benchmarking (about a minute)…", flush=True)
    single = bench_single()
    batch = bench_batch()
    cli = bench_cli()
    des = bench_design()
    arena = bench_arena()
    betaflight = bench_betaflight_section()
    threads = numba.config.NUMBA_NUM_THREADS
    rows = [
        ("RK4 steps/s, one vehicle, one thread (kernel, program sampling included)", "≥ 3,000,000",
         f"{single['kernel_steps_s']:,.0f}"),
        ("RK4 steps/s, one vehicle through `simulate()` (Python overhead included)", "—",
         f"{single['api_steps_s']:,.0f} ({single['api_ms']:.2f} ms per 1.35 s flip)"),
        ("vehicle-steps/s, batch of 1000, 1 thread", "—", f"{batch[1]:,.0f}"),
        (f"vehicle-steps/s, batch of 1000, {threads} threads", "≥ 8,000,000", f"{batch[threads]:,.0f}"),
        ("`aerobat simulate` wall time, warm JIT cache", "≤ 2 s", f"{cli['warm_s']:.2f} s"),
        ("`aerobat simulate` wall time, first-ever JIT (empty cache)", "≤ 20 s", f"{cli['first_jit_s']:.1f} s"),
        ("design of the 2D triple flip (p⁰, J, C)", "≤ 0.1 s", f"{des[2] * 1e3:.0f} ms"),
        ("design of the 3D triple flip (p⁰, J, C)", "≤ 0.25 s", f"{des[3] * 1e3:.0f} ms"),
        ("one complete arena trial (settle, upload, trigger, flip, measure, return)", "≤ 50 ms",
         f"{arena['trial_ms']:.1f} ms"),
        ("60 learning iterations of the 3D triple flip on the arena", "≤ 10 s", f"{arena['learn60_s']:.1f} s"),
    ]
    lines = [
        "# Performance",
        "",
        "Measured by `make bench` (`benchmarks/run.py`), which rewrites this file. Medians of repeated runs",
        "after JIT warm-up unless noted. Tests never assert wall-clock times; these numbers are the record.",
        "",
        f"Machine: {machine()}.",
        f"Measured: {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}.",
        "",
        "| what | target | measured |",
        "|---|---|---|",
        *[f"| {a} | {b} | {c} |" for a, b, c in rows],
        "",
        "Workload: the 1.35 s triple flip of `examples/triple_flip_1800.toml`, continuous mode, 0.5 ms",
        f"RK4 steps ({single['steps']} steps per flight); the batch varies the mass over ±5 % across 1000 vehicles.",
        "References from `../shared/design.md`: RotorPy 3.0 ~1,800 steps/s, crazyflow 0.4 ~73,000 steps/s",
        "(one world) and ~0.7 M drone-steps/s (1000 worlds).",
        "",
        *betaflight,
    ]
    report = "\n".join(lines)
    print(report)
    if args.write:
        # keep the hand-measured sections that follow the marker (other benchmark scripts)
        target = Path(args.write)
        kept = ""
        if target.exists() and OTHER_MARKER in target.read_text():
            kept = target.read_text()[target.read_text().index(OTHER_MARKER):]
        target.write_text(report + ("\n" + kept if kept else ""))
        print(f"written to {args.write}")


if __name__ == "__main__":
    main()
