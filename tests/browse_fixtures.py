"""A store for the browser's tests and benchmark: plain sessions with flown trials and a large study.

Sessions are written through the store's own API (the CLI's ``learn`` writes the same rows);
the trials are real arena flights of one small flip, so figures and replays have data.
"""

from __future__ import annotations

import json
import math
import sqlite3
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from aerobat import hummingbird
from aerobat.config import dataclass_to_table
from aerobat.core.design import design
from aerobat.core.learning import Iteration, IterationStatus, SessionStatus
from aerobat.plants import Arena
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel
from aerobat.store import Store
from aerobat.store.records import JobStatus

CONFIG = hummingbird()
FLIP = MultiFlip(vehicle=CONFIG.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
DESIGN = design(FLIP, NominalModel(CONFIG))
VEHICLE = {"name": CONFIG.name, "vehicle": dataclass_to_table(CONFIG.vehicle),
           "controller": dataclass_to_table(CONFIG.controller)}
PLANTS = (("arena", {"settings": {}}), ("rotorpy", {"settings": {}, "feedback": {"scheme": "tracking"}}))
RULES = ("paper", "broyden")


def add_session(store: Store, *, plant: int = 0, rule: int = 0, trials: int = 3, flown: bool = True,
                study_id: int | None = None, seed: int = 1) -> int:
    """A session with ``trials`` iterations (the first and last with a measured arena flight if ``flown``)."""
    kind, config = PLANTS[plant % len(PLANTS)]
    sid = store.create_session(vehicle=VEHICLE, plant_kind=kind, plant_config=config, maneuver=FLIP, design=DESIGN,
                               seed=seed, rule={"name": RULES[rule % len(RULES)], "schedule": {"kind": "paper"}},
                               target_iterations=max(trials, 1), start_params=DESIGN.p_nominal, study_id=study_id)
    arena = Arena(CONFIG, seed=seed) if flown else None
    params = DESIGN.p_nominal.copy()
    for index in range(1, trials + 1):
        trial = arena.fly(FLIP.program(params)) if arena is not None and index in (1, trials) else None
        error = np.linspace(0.1, 0.5, len(FLIP.errors)) / index
        store.append_iteration(sid, Iteration(index, index, IterationStatus.OK, params, error, 1.0 / index, 1.0,
                                              np.full(params.shape, 1e-4), f"trial {index}", trial))
        params = params + 1e-4
    store.finish_session(sid, SessionStatus.COMPLETED, f"{trials} measured iterations")
    return sid


def build_store(path: Path, *, sessions: int = 5, study_vehicles: int = 200, failed_jobs: int = 2,
                flown: bool = True) -> dict[str, int]:
    """``sessions`` plain sessions (plants and rules alternating) and a study of ``study_vehicles`` sessions."""
    with Store(path) as store:
        plain = [add_session(store, plant=k, rule=k // 2, trials=3 + k % 3, flown=flown, seed=k + 1)
                 for k in range(sessions)]
        study = store.create_study("robustness", {"vehicles": study_vehicles}, command=["study", "robustness"])
        for k in range(study_vehicles):
            key = f"vehicle-{k:03d}"
            if k < failed_jobs:
                store.record_study_job(study, key, {"vehicle": k}, {}, status=JobStatus.FAILED,
                                       error=f"diverged at {k}")
                continue
            sid = add_session(store, trials=1, flown=False, study_id=study, seed=1000 + k)
            store.record_study_job(study, key, {"vehicle": k}, {"trials_to_tolerance": 1 + k % 7}, session_id=sid)
    return {"plain": len(plain), "study": study, "study_sessions": study_vehicles - failed_jobs}


def check_session_mcap(path: Path, store: Store, session_id: int) -> dict[str, int]:
    """Read an exported MCAP back and check it against the store: channels, schemas, counts, times, values."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    iterations = store.iterations(session_id, trajectories=True)
    flown = [it for it in iterations if it.times_s is not None and len(it.times_s)]
    assert flown, "the session has no measured trajectory"
    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        counts = {c.topic: summary.statistics.channel_message_counts[c.id] for c in summary.channels.values()}
        schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        for it in flown:
            rows = len(it.times_s)
            assert counts[f"/trial/{it.index}/pose"] == rows == it.trajectory_rows
            assert schemas[f"/trial/{it.index}/pose"] == "foxglove.PoseInFrame"
            assert counts[f"/trial/{it.index}/state"] == counts[f"/trial/{it.index}/command"] == rows
        assert schemas["/tf"] == "foxglove.FrameTransform" and counts["/tf"] == sum(len(it.times_s) for it in flown)
        assert counts["/errors"] == counts["/firmware"] == len(iterations)
        # the first trial's poses: time-stamped as flown, positions and attitude as stored
        it = flown[0]
        poses = [(m.log_time, d) for _, _, m, d in reader.iter_decoded_messages(topics=[f"/trial/{it.index}/pose"])]
        times = np.array([t for t, _ in poses], dtype=np.int64)
        assert np.allclose((times - times[0]) / 1e9, it.times_s - it.times_s[0], atol=2e-9)
        xyz = np.array([[d.pose.position.x, d.pose.position.y, d.pose.position.z] for _, d in poses])
        quat = np.array([[d.pose.orientation.w, d.pose.orientation.x, d.pose.orientation.y, d.pose.orientation.z]
                         for _, d in poses])
        assert np.array_equal(xyz, it.states[:, 0:3]) and np.array_equal(quat, it.states[:, 6:10])
        assert all(d.frame_id == "world" and d.timestamp.ToNanoseconds() == t for t, d in poses)
        states = [json.loads(m.data) for _, _, m in reader.iter_messages(topics=[f"/trial/{it.index}/state"])]
        def as_json(column: np.ndarray) -> list[float | None]:
            return [float(v) if np.isfinite(v) else None for v in column]

        assert [s["f1_n"] for s in states] == as_json(it.states[:, 13])  # null where not measured (the arena)
        assert [s["p_rad_s"] for s in states] == as_json(it.states[:, 10])
        assert [s["vz_m_s"] for s in states] == as_json(it.states[:, 5]) and states[0]["vz_m_s"] is not None
        # body rates estimated from the measured attitude: there whatever the plant measures (issue 44)
        from aerobat.quadrotor.attitude_rates import body_rates_from_attitude

        estimated = body_rates_from_attitude(it.times_s, it.states[:, 6:10])
        for k, name in enumerate(("p_est_rad_s", "q_est_rad_s", "r_est_rad_s")):
            assert [s[name] for s in states] == as_json(estimated[:, k]) and None not in [s[name] for s in states]
        for _, _, m in reader.iter_messages():
            if m.data[:1] == b"{":
                json.loads(m.data, parse_constant=lambda c: pytest.fail(f"{c} is not JSON"))
        errors = [json.loads(m.data) for _, _, m in reader.iter_messages(topics=["/errors"])]
        assert [e["trial"] for e in errors] == [i.index for i in iterations]
        assert [e["status"] for e in errors] == [i.status for i in iterations]
        last = iterations[-1]
        names = store.maneuver(store.session(session_id).maneuver_id).error_names
        assert [errors[-1]["error"][n] for n in names] == last.error.tolist()
        # trials follow one another on the timeline, never overlapping
        starts = [min(m.log_time for _, _, m in reader.iter_messages(
            topics=[f"/trial/{i.index}/pose", f"/trial/{i.index}/firmware"])) for i in flown]
        assert starts == sorted(starts) and summary.statistics.message_start_time == starts[0]
        # a plant's own signals (schema 7): every sample on its trial's channel and on the overlay, as stored,
        # on the trial's timeline (its first sample, measured or the plant's, at the trial's start)
        for it in flown:
            if it.signals is None:
                assert f"/trial/{it.index}/firmware" not in counts
                continue
            sent = [(m.log_time, json.loads(m.data))
                    for _, _, m in reader.iter_messages(topics=[f"/trial/{it.index}/firmware"])]
            assert len(sent) == len(it.signals.times_s) and [s["t_s"] for _, s in sent] == it.signals.times_s.tolist()
            for k, name in enumerate(it.signals.names):
                assert [s[name] for _, s in sent] == as_json(it.signals.values[:, k]), name
            pose_t0 = next(reader.iter_messages(topics=[f"/trial/{it.index}/pose"]))[2].log_time
            first_s = min(it.times_s[0], it.signals.times_s[0])
            assert abs(sent[0][0] - pose_t0 - round((it.signals.times_s[0] - it.times_s[0]) * 1e9)) <= 1
            assert min(sent[0][0], pose_t0) == starts[flown.index(it)] and first_s <= it.times_s[0]
        # every trial's samples on one channel (issue 44): t_s from the program's start each time, so a
        # Plot panel overlays the trials; the fields docs/browse.md says every plant fills are never null,
        # those only the nominal plant measures are null exactly where the store holds NaN
        from aerobat.quadrotor.dynamics import rotation_angles

        filled = ("x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s", "roll_rad", "pitch_rad", "yaw_rad",
                  "p_est_rad_s", "q_est_rad_s", "r_est_rad_s", "collective_m_s2", "p_hat_rad_s", "q_hat_rad_s",
                  "r_hat_rad_s")
        measured = ("p_rad_s", "q_rad_s", "r_rad_s", "f1_n", "f2_n", "f3_n", "f4_n")
        assert schemas["/trials/state"] == "aerobat.TrialSample"
        trajectories = [(it.index, np.asarray(it.times_s), np.asarray(it.states)) for it in flown]
        assert counts["/trials/state"] == sum(len(stored_t) for _, stored_t, _ in trajectories)
        samples = [(m.log_time, json.loads(m.data)) for _, _, m in reader.iter_messages(topics=["/trials/state"])]
        by_trial: dict[int, list[tuple[int, dict[str, Any]]]] = {}
        for stamp, sample in samples:
            by_trial.setdefault(sample["trial"], []).append((stamp, sample))
        assert list(by_trial) == [index for index, _, _ in trajectories]  # one trial after the other
        last_t_s = math.inf
        for index, stored_t, stored_x in trajectories:
            trial = by_trial[index]
            t_s = np.array([s["t_s"] for _, s in trial])
            period = float(np.median(np.diff(stored_t))) if len(stored_t) > 1 else 1.0
            assert len(trial) == len(stored_t) and np.array_equal(t_s, stored_t)
            assert -1e-6 < t_s[0] < period and t_s[0] < last_t_s  # restarts at the program's start for every trial
            assert np.all(np.diff(t_s) > 0)  # and grows within it
            last_t_s = t_s[-1]
            pose_stamps = [m.log_time for _, _, m in reader.iter_messages(topics=[f"/trial/{index}/pose"])]
            assert [stamp for stamp, _ in trial] == pose_stamps  # the same instants as the trial's poses
            for name in filled:
                assert None not in [s[name] for _, s in trial], name
            assert [s["z_m"] for _, s in trial] == stored_x[:, 2].tolist()
            assert np.allclose([s["roll_rad"] for _, s in trial], rotation_angles(stored_x)[:, 0])
            for k, name in enumerate(measured):
                assert [s[name] for _, s in trial] == as_json(stored_x[:, 10 + k]), name
        # the scene: one message at the start, an entity per measured trial with its whole path, and the maneuver
        assert schemas["/scene"] == "foxglove.SceneUpdate" and counts["/scene"] == 1
        ((_, _, message, scene),) = reader.iter_decoded_messages(topics=["/scene"])
        assert message.log_time == starts[0] <= samples[0][0]  # at the first trial's start
        entities = {e.id: e for e in scene.entities}
        assert list(entities) == [f"trial/{index}" for index, _, _ in trajectories] + ["maneuver"]
        for index, stored_t, stored_x in trajectories:
            entity = entities[f"trial/{index}"]
            (line,) = entity.lines
            assert entity.frame_id == "world" and line.type == 0  # LINE_STRIP
            assert len(line.points) == len(stored_t) == counts[f"/trial/{index}/pose"]
            assert np.array_equal([[p.x, p.y, p.z] for p in line.points], stored_x[:, 0:3])
            end = entity.spheres[0].pose.position
            assert [end.x, end.y, end.z] == stored_x[-1, 0:3].tolist()
            assert {kv.key: kv.value for kv in entity.metadata}["trial"] == str(index)
        colours = [(entities[f"trial/{index}"].lines[0].color.r, entities[f"trial/{index}"].lines[0].color.b)
                   for index, _, _ in trajectories]
        assert colours == sorted(colours) and (len(colours) == 1 or colours[0] != colours[-1])  # blue to red
        assert len(entities["maneuver"].spheres) == 1  # the start
    return counts


def _insert(conn: sqlite3.Connection, table: str, rows: list[dict[str, Any]]) -> None:
    """Rows into ``table``, each with its checksum (as the store writes them)."""
    from aerobat.store import checksums

    columns = checksums.COVERED[table]
    values = [[row[c] for c in columns] for row in rows]
    marks = ", ".join("?" * (len(columns) + 1))
    conn.executemany(f"INSERT INTO {table} ({', '.join(columns)}, checksum) VALUES ({marks})",
                     [[*v, checksums.record_checksum(table, v)] for v in values])


def _rows(conn: sqlite3.Connection, table: str, order: str = "") -> list[dict[str, Any]]:
    from aerobat.store import checksums

    columns = checksums.COVERED[table]
    return [dict(zip(columns, r, strict=True)) for r in conn.execute(
        f"SELECT {', '.join(columns)} FROM {table}{' ORDER BY ' + order if order else ''}")]


def build_large_store(path: Path, *, sessions: int = 100_000, study_size: int = 1000,
                      plain_fraction: float = 0.2) -> dict[str, int]:
    """A store of ``sessions`` sessions in seconds: a fifth plain, the rest in studies of ``study_size``.

    A few sessions are written through the store's API (every plant, rule and feedback of
    :func:`build_store`); the rest are copies of their rows made in SQL, each with its own id, start
    time (spread over 2026), seed, tags, notes and checksum, so that every row reads back verified.
    A study session flies its own sampled vehicle, with its own vehicle and plant rows, as a
    robustness study stores them. Copies keep their template's iterations (1 to 5, without
    trajectories) and study sessions have their study's job row.
    """
    from datetime import UTC, datetime, timedelta

    build_store(path, sessions=8, study_vehicles=2, failed_jobs=0, flown=False)
    n_plain = int(round(sessions * plain_fraction))
    n_studies = -(-(sessions - n_plain) // study_size)
    conn = sqlite3.connect(path)
    try:
        templates = _rows(conn, "sessions", "id")
        plain_t = [t for t in templates if t["study_id"] is None]
        study_t = [t for t in templates if t["study_id"] is not None]
        iterations: dict[int, list[dict[str, Any]]] = {}
        for it in _rows(conn, "iterations", "session_id, idx"):
            iterations.setdefault(it["session_id"], []).append(it)
        plants = {p["id"]: p for p in _rows(conn, "plants")}
        vehicles = {v["id"]: v for v in _rows(conn, "vehicles")}
        study0, job0 = _rows(conn, "studies")[0], _rows(conn, "study_jobs")[0]
        conn.execute("BEGIN")
        for table in ("study_jobs", "iterations", "sessions", "studies"):
            conn.execute(f"DELETE FROM {table}")
        start = datetime(2026, 1, 1, tzinfo=UTC)
        _insert(conn, "studies", [{**study0, "id": k + 1, "created_at": (start + timedelta(days=365 * k / n_studies))
                                   .isoformat()} for k in range(n_studies)])
        new: dict[str, list[dict[str, Any]]] = {t: [] for t in ("vehicles", "plants", "sessions", "iterations",
                                                                 "study_jobs")}
        next_vehicle, next_plant = max(vehicles) + 1, max(plants) + 1
        every = sessions / max(n_plain, 1)  # plain sessions spread among the studies' ones
        plain_done = 0
        for sid in range(1, sessions + 1):
            if plain_done < n_plain and sid - 1 >= plain_done * every:
                template, study_id, plant_id = plain_t[plain_done % len(plain_t)], None, None
                plain_done += 1
            else:
                template, study_id = study_t[sid % len(study_t)], (sid - plain_done - 1) // study_size + 1
                plant = plants[template["plant_id"]]
                config = {**json.loads(vehicles[plant["vehicle_id"]]["config"]), "sample": sid}
                new["vehicles"].append({**vehicles[plant["vehicle_id"]], "id": next_vehicle, "digest": f"v{sid}",
                                        "config": json.dumps(config, sort_keys=True)})
                new["plants"].append({**plant, "id": next_plant, "vehicle_id": next_vehicle, "digest": f"p{sid}"})
                plant_id = next_plant
                next_vehicle, next_plant = next_vehicle + 1, next_plant + 1
            when = (start + timedelta(seconds=365 * 86400 * (sid - 1) / sessions)).isoformat()
            new["sessions"].append({
                **template, "id": sid, "seed": sid, "plant_id": plant_id or template["plant_id"], "study_id": study_id,
                "started_at": when, "updated_at": when, "ended_at": when, "owner": None, "pid": None,
                "tags": (json.dumps(["good"] if sid % 97 == 0 else ["night", "windy"]) if sid % 31 == 0 else None),
                "notes": json.dumps([{"at": when, "text": f"battery {sid % 7} swapped"}]) if sid % 53 == 0 else None,
                "last_position_error_m": (template["last_position_error_m"] or 0.1) * (1 + (sid % 101) / 50)})
            new["iterations"] += [{**it, "session_id": sid} for it in iterations.get(template["id"], [])]
            if study_id is not None:
                new["study_jobs"].append({**job0, "study_id": study_id, "key": f"vehicle-{sid:06d}", "session_id": sid})
        for table, rows in new.items():
            _insert(conn, table, rows)
        conn.execute("COMMIT")
    finally:
        conn.close()
    return {"plain": n_plain, "study": sessions - n_plain, "studies": n_studies}
