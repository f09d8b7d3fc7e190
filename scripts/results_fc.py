"""The real-time rehearsal's numbers in docs/real-vehicle.md: learning, timing, and lockstep beside it.

    .venv/bin/python scripts/results_fc.py summary --db aerobat.sqlite --session 1
        # the figures of a session learned with --plant fc (e.g. the command in docs/real-vehicle.md)
    .venv/bin/python scripts/results_fc.py lockstep --seed 1
        # the same maneuver and seed through the Betaflight plant in lockstep, open loop (~2 min)
    .venv/bin/python scripts/results_fc.py lag --trials 2 --busy 2 [--ground-priority off]
        # how the rehearsal's world and ground kept to the wall clock beside two busy loops
    .venv/bin/python scripts/results_fc.py first --seeds 1 2 3 4 5 --repeats 2
        # the first attempt in real time against lockstep, seed by seed (~4 min; --design-model paper|firmware)

Everything comes from what was stored: each trial's ``info`` carries the world's timekeeping (late
chunks, largest lag), the frame timing during the maneuver (lateness after the deadline, spread of
the intervals, acknowledgement round trips of ``MSP_SET_RAW_RC``), and the outcome. The summary is
printed as the markdown table the document shows, and written as JSON beside the store.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from aerobat.core.maneuver import ErrorKind
from aerobat.store import Store


def _position_rows(errors: np.ndarray, mask: list[bool]) -> np.ndarray:
    pos = [i for i, is_position in enumerate(mask) if is_position]
    return np.linalg.norm(errors[:, pos], axis=1)


def _agg(values: np.ndarray, how: Any) -> float:
    """``how(values)``, NaN when there are none (a session recorded before a figure was kept)."""
    return float(how(values)) if values.size else math.nan


def summarize(db: Path, session_id: int) -> dict[str, Any]:
    """The session's learning and timing figures (every trial counted, lost and aborted ones included)."""
    with Store(db) as store:
        session = store.session(session_id)
        records = store.iterations(session_id)
        mask = list(store.maneuver(session.maneuver_id).position_mask)
    measured = [r for r in records if r.status.value == "ok"]
    position = _position_rows(np.array([r.error for r in measured]), mask) if measured else np.empty(0)
    frames = [r.info.get("maneuver_frames", {}) for r in records if r.info.get("maneuver_frames")]
    worlds = [r.info.get("world", {}) for r in records if r.info.get("world")]

    def values(rows: list[dict[str, Any]], key: str) -> np.ndarray:
        return np.array([row[key] for row in rows if row.get(key) is not None and math.isfinite(row[key])],
                        dtype=float)

    latencies = [r.info.get("command_latency_s") for r in records]
    latency_ms = np.array([t * 1e3 for t in latencies if t is not None and math.isfinite(t)])
    late_chunks = sum(w.get("late_chunks", 0) for w in worlds)
    chunks = sum(w.get("chunks", 0) for w in worlds)
    return {
        "session": session_id, "plant": session.plant_kind, "state": session.state.value,
        "trials": len(records), "measured": len(measured),
        "not_measured": {r.index: f"{r.status.value}: {r.message}" for r in records if r.status.value != "ok"},
        "first_m": float(position[0]) if position.size else math.nan,
        "last10_m": float(position[-10:].mean()) if position.size >= 10 else math.nan,
        "last_m": float(position[-1]) if position.size else math.nan,
        "gyro_rate_hz": sorted({w.get("gyro_rate_hz") for w in worlds}),
        "maneuver_frames": int(sum(f.get("frames", 0) for f in frames)),
        "maneuver_late_frames": int(sum(f.get("late_frames", 0) for f in frames)),
        "frame_lateness_median_ms": _agg(values(frames, "lateness_median_ms"), np.median),
        "frame_lateness_max_ms": _agg(values(frames, "lateness_max_ms"), np.max),
        "frame_interval_std_ms": _agg(values(frames, "interval_std_ms"), np.median),
        "ack_round_trip_median_ms": _agg(values(frames, "ack_round_trip_median_ms"), np.median),
        "ack_round_trip_max_ms": _agg(values(frames, "ack_round_trip_max_ms"), np.max),
        "command_latency_median_ms": _agg(latency_ms, np.median),
        "command_latency_max_ms": _agg(latency_ms, np.max),
        "world_late_chunk_fraction": late_chunks / chunks if chunks else math.nan,
        "world_max_lag_ms": float(max((w.get("max_lag_s", 0.0) for w in worlds), default=math.nan) * 1e3),
        "all_disarmed": all(max(w.get("motors", [0.0])) == 0.0 for w in worlds),
    }


def table(s: dict[str, Any]) -> str:
    """The summary as the document's markdown table."""
    rows = [
        ("trials flown / measured", f"{s['trials']} / {s['measured']}"),
        ("trials not measured", ", ".join(f"{k}: {v}" for k, v in s["not_measured"].items()) or "none"),
        ("position error, first trial", f"{s['first_m']:.3f} m"),
        ("position error, mean of the last 10", f"{s['last10_m']:.3f} m"),
        ("firmware loop (gyro) rate", ", ".join(f"{r} Hz" for r in s["gyro_rate_hz"])),
        ("maneuver frames sent / late (> half a period)", f"{s['maneuver_frames']} / {s['maneuver_late_frames']}"),
        ("frame lateness after its deadline: median, max", f"{s['frame_lateness_median_ms']:.2f} ms, "
                                                             f"{s['frame_lateness_max_ms']:.1f} ms"),
        ("frame interval spread (std, median over trials)", f"{s['frame_interval_std_ms']:.2f} ms"),
        ("command to firmware (first rotation frame sent → rate set point jumps): median, max",
         f"{s['command_latency_median_ms']:.1f} ms, {s['command_latency_max_ms']:.1f} ms"),
        ("frame → its acknowledgement read back (the SITL's TCP reply path included): median, max",
         f"{s['ack_round_trip_median_ms']:.1f} ms, {s['ack_round_trip_max_ms']:.1f} ms"),
        ("world behind the wall clock: chunks late, largest lag", f"{100 * s['world_late_chunk_fraction']:.0f} %, "
                                                                 f"{s['world_max_lag_ms']:.0f} ms"),
        ("every trial ended with the motors stopped", "yes" if s["all_disarmed"] else "NO"),
    ]
    return "\n".join(["| what | measured |", "|---|---|", *(f"| {a} | {b} |" for a, b in rows)])


def lockstep(seed: int, trials: int) -> dict[str, Any]:
    """The same maneuver, seed and pilot through the Betaflight plant in lockstep, open loop."""
    from aerobat.core.design import design
    from aerobat.core.learning import learn
    from aerobat.plants.betaflight.plant import BetaflightPlant
    from aerobat.quadrotor.maneuvers import MultiFlip
    from aerobat.quadrotor.simulate import NominalModel
    from aerobat.quadrotor.vehicle import fpv5

    config = fpv5()
    maneuver = MultiFlip(vehicle=config.vehicle, flips=3, max_rate_rad_s=math.radians(1800), dims=3)
    session = learn(maneuver, design(maneuver, NominalModel(config)),
                    BetaflightPlant(config, seed=seed, feedback="none"), iterations=trials)
    position = _position_rows(np.array([it.error for it in session.measured]),
                              [e.kind is ErrorKind.POSITION for e in maneuver.errors])
    return {"seed": seed, "status": session.status.value, "trials": len(session.iterations),
            "measured": len(session.measured), "first_m": float(position[0]),
            "last10_m": float(position[-10:].mean())}


@contextlib.contextmanager
def busy_loops(count: int) -> Iterator[None]:
    """``count`` processes that spin on a core each until the block ends (a loaded machine)."""
    loops = [subprocess.Popen(["sh", "-c", "while :; do :; done"], start_new_session=True) for _ in range(count)]
    try:
        yield
    finally:
        for loop in loops:
            loop.kill()
            loop.wait(timeout=10)


def _ground_priority_off() -> None:
    """Measure without the ground's real-time priority (the A of an A/B): its threads stay as they are."""
    import aerobat.plants.fc.plant as fc_plant

    @contextlib.contextmanager
    def unchanged(thread_ids: Any, priority: int = 0) -> Any:
        del thread_ids, priority
        yield "off (scripts/results_fc.py --ground-priority off)"

    fc_plant.real_time_threads = unchanged  # type: ignore[assignment]


def lag(seed: int, trials: int) -> list[dict[str, Any]]:
    """How the rehearsal's world kept to the wall clock, trial by trial (the nominal 3D triple flip at 8 kHz).

    Load the machine first to see the scheduling at work (e.g. ``sh -c 'while :; do :; done' &`` three
    times on two cores); the world says how it was scheduled (``fifo`` as root, else ``nice``/``normal``).
    """
    from aerobat.core.design import design
    from aerobat.plants.fc.plant import FlightControllerPlant, RehearsalConnection
    from aerobat.quadrotor.maneuvers import MultiFlip
    from aerobat.quadrotor.simulate import NominalModel
    from aerobat.quadrotor.vehicle import fpv5

    config = fpv5()
    maneuver = MultiFlip(vehicle=config.vehicle, flips=3, max_rate_rad_s=math.radians(1800), dims=3)
    program = maneuver.program(design(maneuver, NominalModel(config)).p_nominal)
    plant = FlightControllerPlant(config, RehearsalConnection({}), seed=seed)
    rows = []
    for _ in range(trials):
        trial = plant.fly(program)
        world = trial.info["world"]
        frames = trial.info.get("maneuver_frames", {})
        rows.append({"status": trial.status.value, "message": trial.message, "scheduling": world.get("scheduling"),
                     "ground_scheduling": trial.info.get("ground_scheduling"),
                     "lateness_median_ms": frames.get("lateness_median_ms"),
                     "lateness_max_ms": frames.get("lateness_max_ms"),
                     "late_chunk_fraction": world["late_chunks"] / max(1, world["chunks"]),
                     "max_lag_ms": 1e3 * world["max_lag_s"],
                     "late_maneuver_frames": trial.info.get("maneuver_frames", {}).get("late_frames")})
    return rows


def first_attempts(seeds: list[int], repeats: int, design_model: str) -> dict[str, Any]:
    """The nominal 3D triple flip's first trial, seed by seed: once in lockstep (deterministic), ``repeats``
    times in real time (the wall clock makes each rehearsal differ)."""
    from aerobat.experiments.designing import nominal_design
    from aerobat.plants import PlantChoice
    from aerobat.plants.betaflight.plant import BetaflightPlant
    from aerobat.plants.fc.plant import FlightControllerPlant, RehearsalConnection
    from aerobat.quadrotor.maneuvers import MultiFlip
    from aerobat.quadrotor.vehicle import fpv5

    config = fpv5()
    maneuver = MultiFlip(vehicle=config.vehicle, flips=3, max_rate_rad_s=math.radians(1800), dims=3)
    nominal = nominal_design(maneuver, config, plant=PlantChoice("betaflight", feedback="none"),
                             design_model=design_model)
    program = maneuver.program(nominal.design.p_nominal)
    mask = [e.kind is ErrorKind.POSITION for e in maneuver.errors]

    def miss(trial: Any) -> float | None:
        return float(_position_rows(maneuver.error(trial.final_state)[None, :], mask)[0]) if trial.ok else None

    rows = []
    for seed in seeds:
        locked = miss(BetaflightPlant(config, seed=seed, feedback="none").fly(program))
        rehearsed = [miss(FlightControllerPlant(config, RehearsalConnection({}), seed=seed).fly(program))
                     for _ in range(repeats)]
        rows.append({"seed": seed, "lockstep_m": locked, "rehearsal_m": rehearsed})
        print(f"seed {seed}: lockstep {locked}, rehearsal {rehearsed}", flush=True)
    lock = np.array([r["lockstep_m"] for r in rows], dtype=float)
    real = np.array([v for r in rows for v in r["rehearsal_m"]], dtype=float)
    return {"design_model": nominal.model.value, "rows": rows,
            "lockstep_median_m": float(np.nanmedian(lock)), "lockstep_range_m": [float(np.nanmin(lock)),
                                                                                  float(np.nanmax(lock))],
            "rehearsal_median_m": float(np.nanmedian(real)), "rehearsal_range_m": [float(np.nanmin(real)),
                                                                                    float(np.nanmax(real))],
            "rehearsal_not_measured": int(np.isnan(real).sum())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    s = sub.add_parser("summary", help="the figures of a stored --plant fc session")
    s.add_argument("--db", type=Path, required=True)
    s.add_argument("--session", type=int, default=1)
    lk = sub.add_parser("lockstep", help="the same maneuver through the lockstep Betaflight plant")
    lk.add_argument("--seed", type=int, default=1)
    lk.add_argument("--trials", type=int, default=30)
    lg = sub.add_parser("lag", help="how the rehearsal's world kept to the wall clock, trial by trial")
    lg.add_argument("--seed", type=int, default=1)
    lg.add_argument("--trials", type=int, default=2)
    lg.add_argument("--busy", type=int, default=0, help="busy loops to start beside the rehearsal (ended after)")
    lg.add_argument("--ground-priority", choices=("on", "off"), default="on",
                    help="off: the ground station's threads keep their scheduling (for an A/B under load)")
    fa = sub.add_parser("first", help="the first attempt in real time against lockstep, seed by seed")
    fa.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    fa.add_argument("--repeats", type=int, default=2, help="rehearsals per seed")
    fa.add_argument("--design-model", choices=("paper", "firmware"), default="firmware")
    args = parser.parse_args()
    if args.what == "first":
        print(json.dumps(first_attempts(args.seeds, args.repeats, args.design_model), indent=1))
    elif args.what == "summary":
        result = summarize(args.db, args.session)
        out = args.db.with_suffix(f".session{args.session}.json")
        out.write_text(json.dumps(result, indent=1))
        print(table(result))
        print(f"\n(written to {out})")
    elif args.what == "lag":
        if args.ground_priority == "off":
            _ground_priority_off()
        with busy_loops(args.busy):
            print(json.dumps(lag(args.seed, args.trials), indent=1))
    else:
        print(json.dumps(lockstep(args.seed, args.trials), indent=1))


if __name__ == "__main__":
    main()
