"""The experiment store (issue 6): schema, records, migrations, refusals, and the CLI on top of it."""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import socket
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from aerobat import hummingbird
from aerobat.cli import main
from aerobat.config import ConfigError, dataclass_to_table
from aerobat.core.design import design
from aerobat.core.learning import Iteration, IterationStatus
from aerobat.core.registry import from_spec, register_maneuver, registered_kinds
from aerobat.plants import Arena, NominalPlant, Trial
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel
from aerobat.store import (
    SessionInUse,
    SessionNotFound,
    Store,
    StoreAccessError,
    StoreError,
    StoreFormatError,
    StoreVersionError,
    StoreWriteError,
    checksums,
    decode_trajectory,
    encode_trajectory,
)
from aerobat.store.migrations import APPLICATION_ID, SCHEMA_V1, SCHEMA_VERSION

CONFIG = hummingbird()
FLIP = MultiFlip(vehicle=CONFIG.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
DESIGN = design(FLIP, NominalModel(CONFIG))
VEHICLE = {"name": CONFIG.name, "vehicle": dataclass_to_table(CONFIG.vehicle),
           "controller": dataclass_to_table(CONFIG.controller)}
SMALL = ["flip", "--dims", "2", "--flips", "1", "--max-rate-deg-s", "800"]


def new_session(store: Store, *, target: int = 5, seed: int = 1) -> int:
    return store.create_session(vehicle=VEHICLE, plant_kind="arena", plant_config={"arena": {}}, maneuver=FLIP,
                                design=DESIGN, seed=seed, rule={"name": "paper", "schedule": {"kind": "paper"}},
                                target_iterations=target, start_params=DESIGN.p_nominal)


def append(store: Store, sid: int, index: int, *, status: str = "ok", trial: Trial | None = None,
           plant_state: dict | None = None, params: np.ndarray | None = None) -> np.ndarray:
    params = DESIGN.p_nominal + 0.001 * index if params is None else params
    nxt = params + 0.0005 if status == "ok" else params
    error = np.arange(5.0) * 0.01 * index if status == "ok" else np.full(5, np.nan)
    store.append_iteration(sid, Iteration(index, index if status == "ok" else 0, IterationStatus(status), params, error,
                                          1.0 / index, 1.0, nxt - params, f"trial {index}", trial),
                           plant_state=plant_state)
    return nxt


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line(err: str, code: int, expected: int = 2, *fragments: str) -> None:
    assert code == expected, err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("aerobat: error:" if expected == 2 else "aerobat: failed:"), err
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in lines[0], err


# ------------------------------------------------------------------ schema and records


def test_new_store_has_current_schema_wal_and_foreign_keys(tmp_path):
    path = tmp_path / "a.sqlite"
    with Store(path) as store:
        assert store.schema_version == SCHEMA_VERSION == 7
        assert store.integrity_check() == []
        conn = store._db
        assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert conn.execute("PRAGMA foreign_keys").fetchone()[0] == 1
        assert conn.execute("PRAGMA application_id").fetchone()[0] == APPLICATION_ID
        assert conn.execute("SELECT value FROM meta WHERE key = 'application'").fetchone()[0] == "aerobat"
        with pytest.raises(sqlite3.IntegrityError):  # foreign keys are enforced
            conn.execute("INSERT INTO plants (kind, vehicle_id, config, digest) VALUES ('x', 999, '{}', 'd')")


def test_session_design_and_maneuver_round_trip_exactly(tmp_path):
    with Store(tmp_path / "a.sqlite") as store:
        sid = new_session(store)
        rec = store.session(sid)
        assert rec.state == "running" and rec.display_state == "running" and rec.n_records == 0
        assert np.array_equal(rec.start_params, DESIGN.p_nominal)
        assert np.array_equal(rec.current_params, DESIGN.p_nominal)
        d = store.design(rec.design_id)
        for name in ("p_guess", "p_nominal", "residual", "jacobian", "correction", "singular_values"):
            assert np.array_equal(getattr(d, name), getattr(DESIGN, name)), name  # bit for bit
        assert d.correction.shape == (5, 5) and d.converged and d.correction_kind == "tsvd"
        m = store.maneuver(rec.maneuver_id)
        assert from_spec(m.spec) == FLIP
        assert m.error_names == ("y", "vy", "z", "vz", "flip_angle") and m.error_units[0] == "m"
        assert store.vehicle(d.vehicle_id).config == VEHICLE
        # a second session of the same maneuver and design reuses the rows
        sid2 = new_session(store, seed=2)
        rec2 = store.session(sid2)
        assert (rec2.design_id, rec2.maneuver_id) == (rec.design_id, rec.maneuver_id)
        assert rec2.plant_id == rec.plant_id and rec2.seed == 2


def test_iterations_round_trip_and_keep_the_summary(tmp_path):
    arena = Arena(CONFIG, seed=4)
    trial = arena.fly(FLIP.program(DESIGN.p_nominal))
    assert trial.ok
    state = arena.get_state()
    with Store(tmp_path / "a.sqlite") as store:
        sid = new_session(store)
        nxt = append(store, sid, 1, trial=trial, plant_state=state)
        append(store, sid, 2, status="no_trigger")
        rec = store.session(sid)
        assert (rec.n_records, rec.n_measured, rec.last_index, rec.last_correction) == (2, 1, 2, 1)
        assert np.array_equal(rec.current_params, DESIGN.p_nominal + 0.002)  # a lost trial changes nothing
        assert rec.last_position_error_m == pytest.approx(math.hypot(0.0, 0.02))
        first, second = store.iterations(sid, trajectories=True, plant_state=True)
        assert np.array_equal(first.next_params, nxt) and first.status == "ok" and second.status == "no_trigger"
        assert np.array_equal(first.final_state, trial.final_state, equal_nan=True)
        assert first.trajectory_rows == trial.times_s.size > 50
        assert np.allclose(first.times_s, trial.times_s, atol=1e-6)
        assert np.allclose(first.states, trial.states, rtol=1e-6, atol=1e-6, equal_nan=True)
        assert first.plant_state == json.loads(json.dumps(state))
        assert second.times_s is None and np.all(np.isnan(second.error))
        assert store.last_iteration(sid).index == 2
        assert store.list_sessions()[0].n_measured == 1


def test_gaps_duplicates_and_other_writers_are_refused(tmp_path):
    with Store(tmp_path / "a.sqlite") as store:
        sid = new_session(store)
        append(store, sid, 1)
        with pytest.raises(StoreError, match="does not follow"):
            append(store, sid, 1)  # duplicate
        with pytest.raises(StoreError, match="does not follow"):
            append(store, sid, 3)  # gap
        checksums.update(store._db, store.path, "sessions", {"id": sid}, {"owner": "elsewhere:1:1"})
        with pytest.raises(StoreError, match="another process"):
            append(store, sid, 2)
        assert [it.index for it in store.iterations(sid)] == [1]
        with pytest.raises(SessionNotFound):
            store.session(99)
        with pytest.raises(SessionNotFound):
            store.resolve_session("zz")
        assert store.resolve_session("last") == sid


def test_resuming_a_session_of_a_live_process_is_refused_and_a_dead_one_shows_killed(tmp_path):
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        with Store(tmp_path / "a.sqlite") as store:
            sid = new_session(store)
            stat = Path(f"/proc/{sleeper.pid}/stat").read_text()
            start = stat[stat.rfind(")") + 2:].split()[19]
            checksums.update(store._db, store.path, "sessions", {"id": sid},
                             {"owner": f"{socket.gethostname()}:{sleeper.pid}:{start}", "pid": sleeper.pid})
            assert store.session(sid).display_state == "running"
            with pytest.raises(SessionInUse, match=f"process {sleeper.pid}"):
                store.claim_session(sid)
            sleeper.kill()
            sleeper.wait()
            assert store.session(sid).display_state == "killed"
            assert store.list_sessions()[0].display_state == "killed"
            assert store.claim_session(sid).owner == store.owner
    finally:
        sleeper.kill()
        sleeper.wait()


@settings(max_examples=60, deadline=None)
@given(hnp.arrays(np.float64, st.tuples(st.integers(1, 40), st.integers(1, 22)),
                  elements=st.floats(allow_nan=True, allow_infinity=True, width=64)))
def test_trajectory_codec_is_float32_exact(matrix):
    rows, cols, blob = encode_trajectory(matrix[:, 0], matrix[:, 1:])
    assert (rows, cols) == matrix.shape
    times, states = decode_trajectory(blob, rows, cols)
    with np.errstate(over="ignore"):
        expected = matrix.astype(np.float32).astype(np.float64)
    assert np.array_equal(times, expected[:, 0], equal_nan=True)
    assert np.array_equal(states, expected[:, 1:], equal_nan=True)


# ------------------------------------------------------------ files that are not ours


@pytest.mark.parametrize("content", [
    b"",  # an empty file is an empty database
    None,
])
def test_empty_files_become_stores(tmp_path, content):
    path = tmp_path / "a.sqlite"
    if content is not None:
        path.write_bytes(content)
    else:
        sqlite3.connect(path).close()  # a valid SQLite file with no tables
    with Store(path) as store:
        assert store.schema_version == SCHEMA_VERSION


def _foreign_sqlite(path: Path) -> None:
    conn = sqlite3.connect(path)
    conn.execute("CREATE TABLE customers (id INTEGER PRIMARY KEY, name TEXT)")
    conn.execute("INSERT INTO customers (name) VALUES ('ada')")
    conn.commit()
    conn.close()


def _corrupted_sqlite(path: Path) -> None:
    _foreign_sqlite(path)
    data = bytearray(path.read_bytes())
    data[100:] = bytes((b * 7 + 3) % 256 for b in range(len(data) - 100))  # valid header, garbage pages
    path.write_bytes(bytes(data))


def _newer_store(path: Path) -> None:
    Store(path).close()
    conn = sqlite3.connect(path)
    conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    conn.close()


@pytest.mark.parametrize("make, error, fragment", [
    (lambda p: p.write_bytes(bytes(range(256)) * 40), StoreFormatError, "not an SQLite file"),
    (lambda p: p.write_text("name = 'not a database'\n"), StoreFormatError, "not an SQLite file"),
    (_foreign_sqlite, StoreFormatError, "another application: tables customers"),
    (_corrupted_sqlite, StoreFormatError, "not a usable aerobat database"),
    (_newer_store, StoreVersionError, f"schema version {SCHEMA_VERSION + 1}"),
])
def test_foreign_corrupted_and_newer_files_are_refused_untouched(tmp_path, capsys, make, error, fragment):
    path = tmp_path / "x.sqlite"
    make(path)
    before = digest(path)
    listing = sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(error, match=fragment):
        Store(path)
    for argv in (["sessions"], ["show", "1"], ["export", "1"],
                 ["learn", *SMALL, "--plant", "nominal", "--iterations", "1", "--out", str(tmp_path / "o")]):
        code, out, err = run(capsys, *argv, "--db", str(path))
        assert_one_line(err, code, 2, str(path), fragment)
    assert digest(path) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == listing  # no -wal, no -shm, no output


def test_unwritable_and_missing_locations_are_clear_errors(tmp_path, capsys):
    with pytest.raises(StoreAccessError, match="cannot open or create"):
        Store("/proc/aerobat-test.sqlite")  # read-only even for root
    with Store(tmp_path / "missing" / "deeper" / "a.sqlite"):  # issue 44: a new store's folders are made
        pass
    (tmp_path / "a-file").write_text("")
    with pytest.raises(StoreAccessError, match="cannot make the directory"):
        Store(tmp_path / "a-file" / "a.sqlite")
    with pytest.raises(StoreAccessError, match="is a directory"):
        Store(tmp_path)
    with pytest.raises(StoreAccessError, match="no such database"):
        Store(tmp_path / "none.sqlite", create=False)
    code, _, err = run(capsys, "learn", *SMALL, "--db", "/proc/aerobat-test.sqlite", "--out", str(tmp_path))
    assert_one_line(err, code, 2, "/proc/aerobat-test.sqlite", "cannot open or create the file")
    code, _, err = run(capsys, "sessions", "--db", str(tmp_path / "none.sqlite"))
    assert_one_line(err, code, 2, "none.sqlite", "no such database")
    assert not (tmp_path / "none.sqlite").exists()


def test_a_full_disk_stores_nothing_of_the_iteration_and_keeps_the_rest(tmp_path):
    arena = Arena(CONFIG, seed=4)
    trial = arena.fly(FLIP.program(DESIGN.p_nominal))
    with Store(tmp_path / "a.sqlite") as store:
        sid = new_session(store)
        append(store, sid, 1, trial=trial)
        pages = store._db.execute("PRAGMA page_count").fetchone()[0]
        store._db.execute(f"PRAGMA max_page_count = {pages}")  # the file may not grow: as good as a full disk
        with pytest.raises(StoreWriteError, match="disk is full"):
            append(store, sid, 2, trial=trial)
        rec = store.session(sid)
        assert rec.n_records == 1 and [it.index for it in store.iterations(sid)] == [1]
        store._db.execute("PRAGMA max_page_count = 1073741823")
        append(store, sid, 2, trial=trial)  # space again: continues with no gap
        assert store.integrity_check() == []


# ------------------------------------------------------------------ migration


def _v1_fixture(path: Path) -> dict:
    """A version-1 store written by hand: two sessions, five iterations."""
    conn = sqlite3.connect(path)
    for statement in SCHEMA_V1.split(";"):
        if statement.strip():
            conn.execute(statement)
    conn.execute(f"PRAGMA application_id = {APPLICATION_ID}")
    conn.execute("PRAGMA user_version = 1")
    conn.execute("INSERT INTO meta VALUES ('application', 'aerobat'), ('created_by', '0.0.9')")
    f8 = lambda a: np.asarray(a, dtype="<f8").tobytes()  # noqa: E731
    conn.execute("INSERT INTO vehicles VALUES (1, 'hummingbird', ?, 'v1')", (json.dumps(VEHICLE),))
    conn.execute("INSERT INTO plants VALUES (1, 'arena', 1, ?, 'p1')", (json.dumps({"arena": {}}),))
    units = [e.unit for e in FLIP.errors]
    conn.execute("INSERT INTO maneuvers VALUES (1, 'flip', ?, ?, ?, ?, ?, ?, ?, 'm1')", (
        FLIP.name, json.dumps(FLIP.spec()), json.dumps([p.name for p in FLIP.parameters]),
        json.dumps([p.unit for p in FLIP.parameters]), json.dumps([e.name for e in FLIP.errors]),
        json.dumps(units), json.dumps([e.scale for e in FLIP.errors])))
    conn.execute(
        "INSERT INTO designs VALUES (1, 1, 1, 5, 5, ?, ?, ?, ?, ?, ?, 'tsvd', ?, ?, ?, 1, 'converged', 'ok', 1.0, "
        "0.5, 99, '2025-01-01T00:00:00.000+00:00', 'd1')",
        (f8(DESIGN.p_guess), f8(DESIGN.p_nominal), f8(DESIGN.residual), DESIGN.residual_norm,
         f8(DESIGN.jacobian), f8(DESIGN.correction), f8(DESIGN.singular_values), DESIGN.condition_number,
         DESIGN.rank))
    rule = json.dumps({"name": "paper", "schedule": {"kind": "paper", "minimum": 0.1}})
    for sid, state in ((1, "completed"), (2, "interrupted")):
        conn.execute(
            "INSERT INTO sessions (id, maneuver_id, design_id, plant_id, seed, rule, target_iterations, "
            "start_params, state, message, started_at, updated_at, host, pid, owner, command, aerobat_version) "
            "VALUES (?, 1, 1, 1, ?, ?, 3, ?, ?, 'old', '2025-01-01', '2025-01-01', 'h', 1, 'h:1:1', '[]', '0.0.9')",
            (sid, sid, rule, f8(DESIGN.p_nominal), state))
    expected = {}
    rows = [(1, 1, "ok"), (1, 2, "no_trigger"), (1, 3, "ok"), (2, 1, "ok"), (2, 2, "rejected")]
    correction = {1: 0, 2: 0}
    for sid, idx, status in rows:
        params = DESIGN.p_nominal + 0.01 * idx + sid
        nxt = params + 0.001 if status == "ok" else params
        error = np.array([0.03, 0.1, -0.04, 0.2, 0.01]) * idx if status != "no_trigger" else np.full(5, np.nan)
        if status == "ok":
            correction[sid] += 1
        conn.execute(
            "INSERT INTO iterations (session_id, idx, correction, status, params, next_params, error, gamma, scale, "
            "message, recorded_at) VALUES (?, ?, ?, ?, ?, ?, ?, 0.5, 1.0, ?, '2025-01-01')",
            (sid, idx, correction[sid] if status == "ok" else 0, status, f8(params), f8(nxt), f8(error),
             f"v1 {sid}/{idx}"))
        expected[(sid, idx)] = (params, nxt, error, status)
    conn.commit()
    conn.close()
    return expected


def test_a_version_1_store_is_migrated_in_place_with_its_data_intact(tmp_path, capsys):
    path = tmp_path / "old.sqlite"
    expected = _v1_fixture(path)
    with Store(path) as store:
        assert store.migrated_from == [1, 2, 3, 4, 5, 6]  # version 1 → 2 → … → 7
        assert store.schema_version == SCHEMA_VERSION
        assert store.integrity_check() == []
        for (sid, idx), (params, nxt, error, status) in expected.items():
            it = store.iterations(sid, indices=[idx])[0]
            assert it.status == status and it.message == f"v1 {sid}/{idx}"
            assert np.array_equal(it.params, params) and np.array_equal(it.next_params, nxt)
            assert np.array_equal(it.error, error, equal_nan=True)
            assert it.plant_state is None
        one, two = store.session(1), store.session(2)
        assert (one.n_records, one.n_measured, one.last_index, one.last_correction) == (3, 2, 3, 2)
        assert (two.n_records, two.n_measured, two.last_index, two.last_correction) == (2, 1, 2, 1)
        assert np.array_equal(one.current_params, expected[(1, 3)][1])  # after the last correction
        assert np.array_equal(two.current_params, expected[(2, 2)][1])  # a rejected trial changes nothing
        assert np.array_equal(one.last_error, expected[(1, 3)][2])
        assert one.last_position_error_m == pytest.approx(math.hypot(0.09, -0.12))
        assert two.last_position_error_m == pytest.approx(math.hypot(0.03, -0.04))
        assert np.array_equal(store.design(1).correction, DESIGN.correction)
        assert store._db.execute("SELECT value FROM meta WHERE key = 'created_by'").fetchone()[0] == "0.0.9"
    with Store(path) as store:  # opening again changes nothing
        assert store.migrated_from == []
    code, out, _ = run(capsys, "sessions", "--db", str(path))
    assert code == 0 and "completed" in out and "interrupted" in out and "2/3" in out


def test_a_failed_migration_leaves_version_1(tmp_path, monkeypatch):
    from aerobat.store import migrations as store_migrations

    path = tmp_path / "old.sqlite"
    _v1_fixture(path)

    def broken(conn):
        conn.execute("ALTER TABLE sessions ADD COLUMN n_records INTEGER")
        raise sqlite3.OperationalError("simulated crash halfway")

    monkeypatch.setitem(store_migrations.MIGRATIONS, 1, broken)
    with pytest.raises(StoreError, match="simulated crash"):
        Store(path)
    conn = sqlite3.connect(path)
    assert conn.execute("PRAGMA user_version").fetchone()[0] == 1
    columns = [r[1] for r in conn.execute("PRAGMA table_info(sessions)")]
    assert "n_records" not in columns
    conn.close()


# ------------------------------------------------------------- registry and plant state


def test_registry_rebuilds_flips_and_names_bad_fields():
    for m in (FLIP, MultiFlip(vehicle=CONFIG.vehicle, flips=3, dims=3, axis="pitch", coast_collective="max",
                              ramp_collective_s=0.0)):
        assert from_spec(json.loads(json.dumps(m.spec()))) == m
    assert "flip" in registered_kinds()
    spec = FLIP.spec()
    cases = [
        ({**spec, "flips": "three"}, "maneuver spec.flips: expected an integer"),
        ({**spec, "flips": 11}, "flips = 11 is out of range"),
        ({k: v for k, v in spec.items() if k != "dims"}, "missing required field dims"),
        ({**spec, "max_rate_rad_s": float("nan")}, "max_rate_rad_s = nan: must be finite"),
        ({**spec, "vehicle": {**spec["vehicle"], "mass_kg": -1.0}}, "maneuver spec.vehicle"),
        ({**spec, "colour": "red"}, "unknown field(s) colour"),
        ({**spec, "kind": "loop"}, "unknown maneuver kind 'loop'"),
        ([1, 2], "expected a table"),
    ]
    for bad, fragment in cases:
        with pytest.raises(ConfigError) as info:
            from_spec(bad)
        assert fragment in str(info.value)
    with pytest.raises(ValueError, match="already registered"):
        register_maneuver("flip", lambda spec, source: FLIP)


def test_arena_state_continues_bit_for_bit_and_is_plain_json():
    program = FLIP.program(DESIGN.p_nominal)
    a = Arena(CONFIG, seed=11)
    a.fly(program)
    snapshot = json.loads(json.dumps(a.get_state(), allow_nan=False))
    ahead = [a.fly(program) for _ in range(3)]
    b = Arena(CONFIG, seed=0)
    b.set_state(snapshot)
    again = [b.fly(program) for _ in range(3)]
    for x, y in zip(ahead, again, strict=True):
        assert x.status == y.status and np.array_equal(x.final_state, y.final_state, equal_nan=True)
    assert b.get_state() == a.get_state()
    for broken, fragment in (({**snapshot, "x": [1.0]}, "state.x"), ({**snapshot, "tick": -1}, "state.tick"),
                             ({k: v for k, v in snapshot.items() if k != "rng"}, "missing field(s) rng"),
                             ({**snapshot, "rng": {"bit_generator": "MT19937"}}, "state.rng")):
        with pytest.raises(ValueError, match=fragment.replace("(", r"\(").replace(")", r"\)")):
            Arena(CONFIG, seed=0).set_state(broken)


# ------------------------------------------------------------------------- the CLI


def test_learn_stores_everything_and_sessions_show_plot_export_read_it(tmp_path, capsys):
    db = str(tmp_path / "a.sqlite")
    code, out, err = run(capsys, "learn", *SMALL, "--plant", "nominal", "--iterations", "3", "--db", db,
                         "--out", str(tmp_path / "learn"))
    assert code == 0, err
    assert "session 1 started" in out and "completed" in out
    code, out, _ = run(capsys, "sessions", "--db", db)
    assert code == 0
    header, rule, row = out.splitlines()
    assert header.split()[:3] == ["id", "maneuver", "plant"] and "state" in header
    assert row.split()[0] == "1" and "nominal" in row and "3/3" in row and "completed" in row
    code, out, _ = run(capsys, "sessions", "--db", db, "--json")
    assert json.loads(out)[0]["iterations"] == 3
    code, out, _ = run(capsys, "show", "last", "--db", db)
    assert code == 0 and "session 1:" in out and "position error [m]" in out and "learned" in out and "p⁰" in out
    code, out, _ = run(capsys, "show", "last", "--full", "--db", db)
    assert code == 0 and "flip_angle" in out
    code, out, _ = run(capsys, "show", "1", "--db", db, "--json")
    shown = json.loads(out)
    assert [it["i"] for it in shown["iterations"]] == [1, 2, 3]
    assert shown["design"]["correction_kind"] == "tsvd" and len(shown["iterations"][0]["final_state"]) == 20
    code, out, _ = run(capsys, "export", "1", "--db", db)
    rows = list(csv.DictReader(io.StringIO(out)))
    assert len(rows) == 3 and rows[0]["status"] == "ok" and float(rows[1]["p0 [m/s²]"]) == float(
        rows[0]["next p0 [m/s²]"])
    target = tmp_path / "export.json"
    code, _, _ = run(capsys, "export", "1", "--format", "json", "--trajectories", "--output", str(target),
                     "--db", db)
    exported = json.loads(target.read_text())
    assert exported["final_params"] == shown["final_params"]
    assert len(exported["iterations"][0]["trajectory"]["times_s"]) > 100
    code, out, _ = run(capsys, "plot", "1", "--db", db, "--out", str(tmp_path / "plots"))
    assert code == 0
    for name in ("learning.png", "side_views.png"):
        assert (tmp_path / "plots" / name).stat().st_size > 10_000
    session_json = json.loads((tmp_path / "learn" / "session.json").read_text())
    assert session_json["session_id"] == 1 and session_json["final_params"] == shown["final_params"]


def test_resume_in_process_equals_an_uninterrupted_run(tmp_path, capsys):
    base = ["learn", *SMALL, "--plant", "arena", "--seed", "5", "--out", str(tmp_path / "o")]
    db = str(tmp_path / "a.sqlite")
    assert main([*base, "--iterations", "3", "--db", db]) == 0
    assert main(["learn", "--resume", "1", "--iterations", "6", "--db", db, "--out", str(tmp_path / "o")]) == 0
    ref = str(tmp_path / "ref.sqlite")
    assert main([*base, "--iterations", "6", "--db", ref]) == 0
    capsys.readouterr()
    with Store(db) as a, Store(ref) as b:
        resumed, straight = a.session(1), b.session(1)
        assert np.array_equal(resumed.current_params, straight.current_params)
        assert [it.index for it in a.iterations(1)] == [1, 2, 3, 4, 5, 6]
        assert [it.gamma for it in a.iterations(1)] == [it.gamma for it in b.iterations(1)]
        assert resumed.state == "completed" and resumed.target_iterations == 6


def test_resume_and_warm_start_refuse_what_does_not_fit(tmp_path, capsys):
    db = str(tmp_path / "a.sqlite")
    out = ["--out", str(tmp_path / "o")]
    assert main(["learn", *SMALL, "--plant", "nominal", "--iterations", "2", "--db", db, *out]) == 0
    capsys.readouterr()
    cases = [
        (["learn", "--resume", "1", "--db", db], "already has 2 of 2"),
        (["learn", "--resume", "9", "--db", db], "no session 9"),
        (["learn", "--resume", "abc", "--db", db], "expected an id"),
        (["learn", *SMALL, "--resume", "1", "--from-session", "1", "--db", db], "exclude each other"),
        (["learn", *SMALL, "--plant", "arena", "--resume", "1", "--iterations", "4", "--db", db],
         "--plant arena (stored: nominal)"),
        (["learn", "flip", "--dims", "2", "--flips", "2", "--max-rate-deg-s", "800", "--plant", "nominal",
          "--from-session", "1", "--db", db], "flips = 1 (stored) vs 2"),
        (["learn", "--db", db], "name a maneuver"),
    ]
    for argv, fragment in cases:
        try:
            code = main([*argv, *out])
        except SystemExit as exc:  # argparse
            code = exc.code
        _, err = capsys.readouterr()
        assert_one_line(err, code, 2, fragment)
    # the same command line plus --resume is accepted
    code, text, err = run(capsys, "learn", *SMALL, "--plant", "nominal", "--iterations", "3", "--resume", "1",
                          "--db", db, *out)
    assert code == 0, err
    assert "session 1 resumed" in text
    code, text, err = run(capsys, "learn", *SMALL, "--plant", "nominal", "--iterations", "1", "--from-session",
                          "last", "--db", db, *out)
    assert code == 0, err
    with Store(db) as store:
        warm = store.session(2)
        assert warm.warm_start_from == 1
        assert np.array_equal(warm.start_params, store.session(1).current_params)
        assert np.array_equal(store.iterations(2)[0].params, warm.start_params)


class _FlakyPlant:
    """The nominal model, except that every second trial measures nonsense."""

    name = "flaky"

    def __init__(self, config):
        self.inner = NominalPlant(config)
        self.count = 0

    def fly(self, program):
        trial = self.inner.fly(program)
        self.count += 1
        if self.count % 2 == 0:
            bad = trial.final_state.copy()
            bad[1] = np.nan if self.count % 4 == 0 else 1e4
            return Trial("ok", "glitch", bad, trial.times_s, trial.states, trial.start_state)
        return trial


def test_rejected_measurements_are_stored_without_an_update(tmp_path, capsys, monkeypatch):
    from aerobat.plants import PlantChoice

    monkeypatch.setattr(PlantChoice, "build", lambda self, config, **_: _FlakyPlant(config))
    db = str(tmp_path / "a.sqlite")
    code, out, err = run(capsys, "learn", *SMALL, "--plant", "nominal", "--iterations", "3", "--db", db,
                         "--out", str(tmp_path / "o"))
    assert code == 0, err
    assert "rejected    non-finite measurement" in out and "rejected    absurd measurement" in out
    with Store(db) as store:
        its = store.iterations(1)
        assert [it.status for it in its] == ["ok", "rejected", "ok", "rejected", "ok"]
        for before, it in zip(its, its[1:], strict=False):
            assert np.array_equal(it.params, before.next_params)  # what was stored is what flew next
        for it in its:
            if it.status == "rejected":
                assert np.array_equal(it.next_params, it.params) and it.correction == 0 and it.gamma == 0.0
        assert store.session(1).n_measured == 3 and store.session(1).n_records == 5


def test_pinned_parameters_are_warned_about_in_the_output(tmp_path, capsys, monkeypatch):
    import dataclasses

    from aerobat.core.learning import Learner
    from aerobat.core.notes import IterationNote, NoteKind, message_with_notes

    tell = Learner.tell

    def tell_with_warning(self, trial):  # as if p1 sat at a bound for 8 corrections
        record = tell(self, trial)
        if record.index == 2:
            note = IterationNote(NoteKind.PINNED_AT_BOUND, "p1", "p1 (accelerate duration) pinned at a bound for "
                                 "8 corrections: maneuver poorly formulated or infeasible here")
            record = dataclasses.replace(record, message=message_with_notes(record.message, (note,)), notes=(note,))
        return record

    monkeypatch.setattr(Learner, "tell", tell_with_warning)
    code, out, err = run(capsys, "learn", *SMALL, "--plant", "nominal", "--iterations", "2",
                         "--db", str(tmp_path / "a.sqlite"), "--out", str(tmp_path / "o"))
    assert code == 0, err
    assert out.count("maneuver poorly formulated or infeasible here") == 2  # as it happens, and in the summary
    assert "warning: p1 (accelerate duration) pinned at a bound for 8 corrections" in out


def test_a_design_that_does_not_converge_exits_1_and_starts_no_session(tmp_path, capsys):
    vehicle = tmp_path / "weak.toml"
    vehicle.write_text("[vehicle]\ncollective_reduced_max_m_s2 = 11.0\n")
    db = tmp_path / "a.sqlite"
    code, _, err = run(capsys, "learn", "flip", "--dims", "2", "--vehicle", str(vehicle), "--db", str(db),
                       "--out", str(tmp_path))
    assert_one_line(err, code, 1, "design failed", "β̄")
    with Store(db) as store:
        assert store.list_sessions() == []


def test_resuming_a_session_killed_after_its_last_iteration_just_closes_it(tmp_path, capsys):
    db = str(tmp_path / "a.sqlite")
    out = ["--out", str(tmp_path / "o")]
    assert main(["learn", *SMALL, "--plant", "nominal", "--iterations", "2", "--db", db, *out]) == 0
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    conn = sqlite3.connect(db)  # as if killed between its last commit and closing the session
    checksums.update(conn, db, "sessions", {"id": 1}, {"state": "running", "ended_at": None, "pid": gone.pid,
                                                       "owner": f"{socket.gethostname()}:{gone.pid}:1"})
    conn.commit()
    conn.close()
    capsys.readouterr()
    code, text, err = run(capsys, "learn", "--resume", "1", "--db", db, *out)
    assert code == 0, err
    assert "2 of 2 measured iterations done" in text
    with Store(db) as store:
        rec = store.session(1)
        assert rec.state == "completed" and rec.n_records == 2 and "0 after resuming" in rec.message
