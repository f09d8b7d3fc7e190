"""Experiment-store benchmarks (issue 6); prints a markdown table.

* the cost of storing one iteration (trajectory and plant state included), per plant and
  ``synchronous`` setting;
* ``aerobat sessions`` on a synthetic store of 1,000 sessions and 100,000 iterations,
  in-process (the command's own work) and as a fresh process (what a user waits for);
* migrating that store from schema version 1.

Benchmarks measure and report; they never fail on a number.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import platform
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from aerobat import hummingbird  # noqa: E402
from aerobat.cli import main  # noqa: E402
from aerobat.config import dataclass_to_table  # noqa: E402
from aerobat.core.design import design  # noqa: E402
from aerobat.core.learning import Iteration, IterationStatus  # noqa: E402
from aerobat.plants import Arena, NominalPlant  # noqa: E402
from aerobat.quadrotor.maneuvers import MultiFlip  # noqa: E402
from aerobat.quadrotor.simulate import NominalModel  # noqa: E402
from aerobat.store import Store  # noqa: E402
from aerobat.store.migrations import APPLICATION_ID, SCHEMA_V1  # noqa: E402

CONFIG = hummingbird()
VEHICLE = {"name": CONFIG.name, "vehicle": dataclass_to_table(CONFIG.vehicle),
           "controller": dataclass_to_table(CONFIG.controller)}
RULE = {"name": "paper", "schedule": {"kind": "paper", "minimum": 0.1}}


def percentile(values: list[float], q: float) -> float:
    return float(np.percentile(np.array(values), q))


def bench_append(tmp: Path, label: str, maneuver, plant, synchronous: str, n: int) -> dict:
    """Time ``append_iteration`` (encode, plant state, insert, summary, commit) on real trials."""
    nominal = design(maneuver, NominalModel(CONFIG))
    trials = [t for t in (plant.fly(maneuver.program(nominal.p_nominal)) for _ in range(8)) if t.ok][:5]
    state = plant.get_state() if hasattr(plant, "get_state") else None
    path = tmp / f"append-{label.replace(' ', '-')}-{synchronous}.sqlite"
    times, state_times, cpu_times = [], [], []
    with Store(path, synchronous=synchronous) as store:
        sid = store.create_session(vehicle=VEHICLE, plant_kind=plant.name, plant_config={}, maneuver=maneuver,
                                   design=nominal, seed=0, rule=RULE, target_iterations=n,
                                   start_params=nominal.p_nominal)
        params = nominal.p_nominal
        for k in range(1, n + 1):
            trial = trials[k % len(trials)]
            start = time.perf_counter()
            cpu_start = time.thread_time()
            plant_state = plant.get_state() if state is not None else None
            middle = time.perf_counter()
            store.append_iteration(sid, Iteration(k, k, IterationStatus.OK, params, maneuver.error(trial.final_state),
                                                  0.1, 1.0, np.zeros_like(params), trial.message, trial),
                                   plant_state=plant_state)
            end = time.perf_counter()
            cpu_times.append(time.thread_time() - cpu_start)
            times.append(end - start)
            state_times.append(middle - start)
    size = path.stat().st_size + sum(Path(f"{path}{s}").stat().st_size for s in ("-wal",)
                                     if Path(f"{path}{s}").exists())
    return {"label": label, "synchronous": synchronous, "rows": trials[0].times_s.size,
            "median_ms": 1e3 * statistics.median(times), "p95_ms": 1e3 * percentile(times, 95),
            "mean_ms": 1e3 * statistics.fmean(times), "cpu_ms": 1e3 * statistics.fmean(cpu_times),
            "state_ms": 1e3 * statistics.median(state_times),
            "kb_per_iteration": size / n / 1024}


def synthetic_store(path: Path, sessions: int, per_session: int, *, version: int = 2) -> None:
    """A store of ``sessions`` × ``per_session`` iterations written directly with executemany."""
    flip = MultiFlip(vehicle=CONFIG.vehicle, flips=3, dims=3)
    d_rng = np.random.default_rng(0)
    f8 = lambda a: np.asarray(a, dtype="<f8").tobytes()  # noqa: E731
    if version == 2:
        Store(path).close()
        conn = sqlite3.connect(path, isolation_level=None)
    else:
        conn = sqlite3.connect(path, isolation_level=None)
        conn.execute("PRAGMA journal_mode = WAL")
        for statement in SCHEMA_V1.split(";"):
            if statement.strip():
                conn.execute(statement)
        conn.execute(f"PRAGMA application_id = {APPLICATION_ID}")
        conn.execute("PRAGMA user_version = 1")
        conn.execute("INSERT INTO meta VALUES ('application', 'aerobat')")
    conn.execute("PRAGMA synchronous = OFF")
    conn.execute("BEGIN")
    conn.execute("INSERT INTO vehicles VALUES (1, 'hummingbird', ?, 'v')", (json.dumps(VEHICLE),))
    conn.execute("INSERT INTO plants VALUES (1, 'arena', 1, '{}', 'p')")
    conn.execute("INSERT INTO maneuvers VALUES (1, 'flip', ?, ?, ?, ?, ?, ?, ?, 'm')", (
        flip.name, json.dumps(flip.spec()), json.dumps([p.name for p in flip.parameters]),
        json.dumps([p.unit for p in flip.parameters]), json.dumps([e.name for e in flip.errors]),
        json.dumps([e.unit for e in flip.errors]), json.dumps([e.scale for e in flip.errors])))
    z9, z81 = f8(np.zeros(9)), f8(np.eye(9))
    conn.execute("INSERT INTO designs VALUES (1, 1, 1, 9, 9, ?, ?, ?, 0.0, ?, ?, 'tsvd', ?, 1.0, 9, 1, "
                 "'converged', 'ok', 1.6, 1.0, 100, 'now', 'd')", (z9, z9, z9, z81, z81, z9))
    plant_state = json.dumps(Arena(CONFIG, seed=0).get_state(), separators=(",", ":"))
    now = "2025-01-01T00:00:00.000+00:00"
    rows = []
    for s in range(1, sessions + 1):
        base = (s, 1, 1, 1, s, json.dumps(RULE), per_session, z9, "completed", "done", now, now, "h", 1,
                "h:1:1", "[]", "0.1.0")
        if version == 2:
            rows.append((*base, per_session, per_session, per_session, per_session, f8(d_rng.normal(size=9)),
                         float(d_rng.random()), z9))
        else:
            rows.append(base)
    columns = ("id, maneuver_id, design_id, plant_id, seed, rule, target_iterations, start_params, state, "
               "message, started_at, updated_at, host, pid, owner, command, aerobat_version")
    if version == 2:
        columns += (", n_records, n_measured, last_index, last_correction, last_error, last_position_error_m, "
                    "current_params")
    conn.executemany(f"INSERT INTO sessions ({columns}) VALUES ({', '.join('?' * len(rows[0]))})", rows)
    params = f8(d_rng.normal(size=9))
    error = f8(d_rng.normal(size=9) * 0.01)
    final = f8(d_rng.normal(size=20))
    it_columns = ("session_id, idx, correction, status, params, next_params, error, gamma, scale, message, "
                  "final_state, start_state, recorded_at" + (", plant_state" if version == 2 else ""))
    marks = ", ".join("?" * (14 if version == 2 else 13))
    for s in range(1, sessions + 1):
        batch = [(s, k, k, "ok", params, params, error, 0.1, 1.0, "maneuver flown", final, final, now,
                  *((plant_state,) if version == 2 else ())) for k in range(1, per_session + 1)]
        conn.executemany(f"INSERT INTO iterations ({it_columns}) VALUES ({marks})", batch)
    conn.execute("COMMIT")
    conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    conn.close()


def time_in_process(argv: list[str], repeats: int = 5) -> float:
    times = []
    for _ in range(repeats):
        sink = io.StringIO()
        start = time.perf_counter()
        with contextlib.redirect_stdout(sink):
            code = main(argv)
        times.append(time.perf_counter() - start)
        assert code == 0
    return statistics.median(times)


def time_process(argv: list[str], repeats: int = 3) -> float:
    exe = ROOT / ".venv" / "bin" / "aerobat"
    prefix = [str(exe)] if exe.exists() else [sys.executable, "-m", "aerobat.cli"]
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run([*prefix, *argv], check=True, stdout=subprocess.DEVNULL)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def time_import() -> float:
    times = []
    for _ in range(3):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import aerobat.cli"], check=True)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main_bench() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=300, help="appends per configuration")
    parser.add_argument("--sessions", type=int, default=1000)
    parser.add_argument("--per-session", type=int, default=100)
    options = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        flip2 = MultiFlip(vehicle=CONFIG.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
        flip3 = MultiFlip(vehicle=CONFIG.vehicle, flips=3, dims=3)
        appends = [
            bench_append(tmp, "arena, 2D single flip", flip2, Arena(CONFIG, seed=0), "normal", options.iterations),
            bench_append(tmp, "arena, 3D triple flip", flip3, Arena(CONFIG, seed=0), "normal", options.iterations),
            bench_append(tmp, "nominal, 3D triple flip", flip3, NominalPlant(CONFIG), "normal", options.iterations),
            bench_append(tmp, "arena, 3D triple flip", flip3, Arena(CONFIG, seed=0), "full",
                         min(options.iterations, 100)),
        ]
        big = tmp / "big.sqlite"
        start = time.perf_counter()
        synthetic_store(big, options.sessions, options.per_session)
        generate_s = time.perf_counter() - start
        size_mb = big.stat().st_size / 1e6
        with Store(big) as store:
            start = time.perf_counter()
            listed = store.list_sessions()
            query_s = time.perf_counter() - start
            assert len(listed) == options.sessions
        sessions_in = time_in_process(["sessions", "--db", str(big)])
        show_in = time_in_process(["show", "500", "--db", str(big)], repeats=3)
        export_in = time_in_process(["export", "500", "--db", str(big)], repeats=3)
        sessions_proc = time_process(["sessions", "--db", str(big)])
        import_s = time_import()
        old = tmp / "v1.sqlite"
        synthetic_store(old, options.sessions, options.per_session, version=1)
        start = time.perf_counter()
        with Store(old) as store:
            migrated = store.migrated_from
        migrate_s = time.perf_counter() - start
        assert migrated == [1, 2]  # version 1 → 2 → 3
    print(f"Machine: {platform.machine()}, {os.cpu_count()} CPUs, {platform.system()} {platform.release()}, "
          f"Python {platform.python_version()}, SQLite {sqlite3.sqlite_version}\n")
    print("| storing one iteration | trajectory rows | synchronous | median [ms] | p95 [ms] | mean [ms] | "
          "mean CPU [ms] | of which get_state [ms] | stored [KiB/iteration] |")
    print("|---|---:|---|---:|---:|---:|---:|---:|---:|")
    for a in appends:
        print(f"| {a['label']} | {a['rows']} | {a['synchronous']} | {a['median_ms']:.2f} | {a['p95_ms']:.2f} | "
              f"{a['mean_ms']:.2f} | {a['cpu_ms']:.2f} | {a['state_ms']:.3f} | {a['kb_per_iteration']:.1f} |")
    n_it = options.sessions * options.per_session
    print(f"\n| store of {options.sessions:,} sessions, {n_it:,} iterations ({size_mb:.0f} MB, generated in "
          f"{generate_s:.1f} s) | time [s] | target [s] |")
    print("|---|---:|---:|")
    print(f"| `Store.list_sessions()` (the query) | {query_s:.4f} | |")
    print(f"| `aerobat sessions`, in-process (parse, open, query, print {options.sessions} rows) | "
          f"{sessions_in:.3f} | 0.5 |")
    print(f"| `aerobat sessions`, fresh process (interpreter, imports included) | {sessions_proc:.3f} | 0.5 |")
    print(f"| of which `python -c 'import aerobat.cli'` alone | {import_s:.3f} | |")
    print(f"| `aerobat show` of one {options.per_session}-iteration session, in-process | {show_in:.3f} | |")
    print(f"| `aerobat export` (csv) of one session, in-process | {export_in:.3f} | |")
    print(f"| migrating the same store from schema version 1 | {migrate_s:.3f} | |")


if __name__ == "__main__":
    main_bench()
