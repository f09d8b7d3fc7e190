"""Issue 31's store items: record checksums (S1), ids (S2, I7), damaged JSON (I6), locks (H3), creation (P3)."""

from __future__ import annotations

import contextlib
import hashlib
import io
import multiprocessing
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from aerobat.cli import main
from aerobat.errors import ConfigError, SessionNotFound, StoreAccessError, StoreBusyError, StoreFormatError
from aerobat.store import Store, checksums
from aerobat.store.migrations import MIGRATIONS, SCHEMA_V1

SMALL = ["flip", "--dims", "2", "--flips", "1", "--max-rate-deg-s", "800", "--plant", "nominal"]


def call(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def one_error_line(err: str, *fragments: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("aerobat: error:") and "Traceback" not in err, err
    for fragment in fragments:
        assert fragment in lines[0], err


@pytest.fixture(scope="module")
def learned(tmp_path_factory) -> Path:
    """A store with two sessions of a small flip on the nominal plant (3 and 2 iterations)."""
    folder = tmp_path_factory.mktemp("learned")
    db = folder / "s.sqlite"
    for seed, n in ((1, 3), (2, 2)):
        code, _, err = call(["learn", *SMALL, "--iterations", str(n), "--seed", str(seed), "--db", str(db),
                             "--out", str(folder / f"o{seed}")])
        assert code == 0, err
    return db


@pytest.fixture()
def db(learned, tmp_path) -> Path:
    copy = tmp_path / "s.sqlite"
    copy.write_bytes(learned.read_bytes())
    return copy


def raw(db: Path, sql: str, args: tuple = ()) -> None:
    """An edit outside aerobat (the checksum is not updated)."""
    with contextlib.closing(sqlite3.connect(db)) as conn:
        conn.execute(sql, args)
        conn.commit()


# ------------------------------------------------------------------ S1: checksums


@pytest.mark.parametrize(("table", "sql", "read"), [
    ("sessions", "UPDATE sessions SET seed = 7 WHERE id = 1", lambda s: s.session(1)),
    ("iterations", "UPDATE iterations SET gamma = gamma + 1e-9 WHERE session_id = 1 AND idx = 2",
     lambda s: s.iterations(1)),
    ("designs", "UPDATE designs SET p_nominal = zeroblob(length(p_nominal))", lambda s: s.design(1)),
    ("maneuvers", "UPDATE maneuvers SET name = 'flop'", lambda s: s.maneuver(1)),
    ("plants", "UPDATE plants SET kind = 'arena'", lambda s: s.plant(1)),
    ("vehicles", "UPDATE vehicles SET name = 'other'", lambda s: s.vehicle(1)),
    ("sessions", "UPDATE sessions SET checksum = (checksum | 1) - (checksum & 1) WHERE id = 2",
     lambda s: s.list_sessions()),
    ("iterations", "UPDATE iterations SET checksum = (checksum | 1024) - (checksum & 1024) WHERE session_id = 2 "
                   "AND idx = 1", lambda s: s.last_iteration(2) if s.iterations(2) else None),
])
def test_a_changed_value_or_checksum_is_refused_on_read(db, table, sql, read):
    raw(db, sql)
    with Store(db, create=False) as store, pytest.raises(StoreFormatError, match=f"the {table} record .* fails "
                                                                                  f"its checksum"):
        read(store)


def test_a_changed_trajectory_is_caught_when_it_is_read_and_before_resume_or_export(db):
    raw(db, "UPDATE iterations SET trajectory = CAST(zeroblob(4) || substr(trajectory, 5) AS BLOB) "
            "WHERE session_id = 2 AND idx = 1")
    with Store(db, create=False) as store:
        assert len(store.iterations(2)) == 2  # the trajectories are not read: nothing of them is used
        with pytest.raises(StoreFormatError, match="trajectory of iteration 1 of session 2 fails its checksum"):
            store.iterations(2, trajectories=True)
        with pytest.raises(StoreFormatError, match="fails its checksum"):
            store.verify_session(2)
        store.verify_session(1)  # the other session is intact
    before = hashlib.sha256(db.read_bytes()).hexdigest()
    code, _, err = call(["export", "2", "--db", str(db)])
    assert code == 2
    one_error_line(err, "fails its checksum")
    code, _, err = call(["learn", "--resume", "2", "--trials", "3", "--db", str(db), "--out", str(db.parent / "r")])
    assert code == 2
    one_error_line(err, "fails its checksum")
    assert hashlib.sha256(db.read_bytes()).hexdigest() == before  # nothing written into it


def test_text_that_is_not_utf8_is_a_failed_checksum(db):
    # a flipped bit in a record's header can turn a blob into text that is not UTF-8
    raw(db, "UPDATE iterations SET message = CAST(x'ff00fe' AS TEXT) WHERE session_id = 1 AND idx = 1")
    with Store(db, create=False) as store, pytest.raises(StoreFormatError, match="fails its checksum"):
        store.iterations(1)


def test_resume_and_export_refuse_a_flipped_bit_in_an_iteration(db):
    with contextlib.closing(sqlite3.connect(db)) as conn:
        blob = bytearray(conn.execute("SELECT error FROM iterations WHERE session_id = 2 AND idx = 2").fetchone()[0])
        blob[3] ^= 0x10  # one bit of one error component
        conn.execute("UPDATE iterations SET error = ? WHERE session_id = 2 AND idx = 2", (bytes(blob),))
        conn.commit()
    for argv in (["export", "2"], ["show", "2", "--json"],
                 ["learn", "--resume", "2", "--trials", "3", "--out", str(db.parent / "r")]):
        code, out, err = call([*argv, "--db", str(db)])
        assert code == 2 and out == "", (argv, out)
        one_error_line(err, "iterations record (session_id 2, idx 2) fails its checksum")
    code, out, _ = call(["export", "1", "--db", str(db)])  # the other session still exports
    assert code == 0 and out.count("\n") == 4


def test_the_bitflip_campaign_finds_no_silent_change(tmp_path):
    sys.path.insert(0, str(Path(__file__).parents[2] / "scripts"))
    try:
        from fuzz_store_bitflips import bitflip_campaign
    finally:
        sys.path.pop(0)
    report = bitflip_campaign(flips=12, seed=3, workdir=tmp_path)
    assert report["silent"] == 0, report["silent_cases"]
    reads = report["reads"]
    assert reads["caught"] + reads["unchanged"] == 12 * 5 and reads["caught"] >= 12  # each flip is seen somewhere
    assert sum(report["resumes"].values()) == 12


def test_a_version_4_store_is_migrated_with_every_record_checksummed(tmp_path):
    path = tmp_path / "v4.sqlite"
    conn = sqlite3.connect(path)
    conn.executescript(SCHEMA_V1)
    conn.execute("INSERT INTO meta VALUES ('application', 'aerobat')")
    conn.execute("INSERT INTO vehicles VALUES (1, 'hummingbird', '{\"name\": \"hummingbird\"}', 'v1')")
    conn.execute("INSERT INTO plants VALUES (1, 'nominal', 1, '{\"settings\": {}}', 'p1')")
    conn.execute("INSERT INTO maneuvers VALUES (1, 'flip', 'flip', '{}', '[\"a\"]', '[\"s\"]', '[\"y\"]', '[\"m\"]', "
                 "'[0.1]', 'm1')")
    f8 = sqlite3.Binary(b"\x00" * 8)
    conn.execute("INSERT INTO designs VALUES (1, 1, 1, 1, 1, ?, ?, ?, 0.0, ?, ?, 'tsvd', ?, 1.0, 1, 1, 'converged', "
                 "'', 0.1, 0.1, 3, '2024', 'd1')", (f8,) * 6)
    conn.execute("INSERT INTO sessions (id, maneuver_id, design_id, plant_id, seed, rule, target_iterations, "
                 "start_params, state, started_at, updated_at) VALUES (1, 1, 1, 1, 0, '{}', 2, ?, 'completed', "
                 "'t', 't')", (f8,))
    conn.execute("INSERT INTO iterations (session_id, idx, correction, status, params, next_params, error, gamma, "
                 "scale, message, recorded_at) VALUES (1, 1, 1, 'ok', ?, ?, ?, 1.0, 1.0, 'm', 't')", (f8,) * 3)
    for version in (1, 2, 3):
        MIGRATIONS[version](conn)
    conn.execute("PRAGMA user_version = 4")
    conn.execute("PRAGMA application_id = 1095062082")
    conn.commit()
    conn.close()
    with Store(path) as store:
        assert store.migrated_from == [4, 5, 6] and store.schema_version == 7
        assert [it.index for it in store.iterations(1)] == [1] and store.session(1).n_measured == 1
        store.verify_session(1)
        for table in checksums.COVERED:  # every row of every table has its checksum
            assert store._db.execute(f"SELECT count(*) FROM {table} WHERE checksum IS NULL").fetchone()[0] == 0
    raw(path, "UPDATE iterations SET message = 'n'")
    with Store(path, create=False) as store, pytest.raises(StoreFormatError, match="fails its checksum"):
        store.iterations(1)


def test_a_version_5_store_is_migrated_with_the_notes_its_messages_say(tmp_path):
    """Schema 6 keeps an iteration's notes in a column; a version-5 row gets the notes its message says, once."""
    import numpy as np

    from aerobat.core.learning import Iteration, IterationStatus
    from aerobat.core.notes import IterationNote, NoteKind, message_with_notes
    from browse_fixtures import DESIGN, FLIP, VEHICLE

    path = tmp_path / "v5.sqlite"
    notes = (IterationNote.held("t1"),
             IterationNote(NoteKind.PINNED_AT_BOUND, "t2", "t2 (coast) pinned at a bound for 8 corrections: bad"))
    params = DESIGN.p_nominal.copy()
    with Store(path) as store:
        sid = store.create_session(vehicle=VEHICLE, plant_kind="nominal", plant_config={}, maneuver=FLIP,
                                   design=DESIGN, seed=None, rule={"name": "paper"}, target_iterations=3,
                                   start_params=params)
        for i, said in enumerate(((), notes, (notes[0],)), start=1):
            store.append_iteration(sid, Iteration(i, i, IterationStatus.OK, params, np.full(len(FLIP.errors), 0.1),
                                                  0.5, 1.0, np.zeros_like(params),
                                                  message_with_notes("measured", said), None, said))
    with contextlib.closing(sqlite3.connect(path)) as conn:  # the file as version 5 wrote it
        for column in ("notes", *V7_COLUMNS):
            conn.execute(f"ALTER TABLE iterations DROP COLUMN {column}")
        checksums.backfill(conn, "iterations", [c for c in checksums.COVERED["iterations"]
                                                if c != "notes" and c not in V7_COLUMNS])
        conn.execute("UPDATE iterations SET gamma = 0.25 WHERE idx = 3")  # damaged before the migration
        conn.execute("PRAGMA user_version = 5")
        conn.commit()
    with Store(path) as store:
        assert store.migrated_from == [5, 6] and store.schema_version == 7
        got = store.iterations(sid, indices=[1, 2])
        assert [it.notes for it in got] == [(), notes] and got[1].message == message_with_notes("measured", notes)
        assert store._db.execute("SELECT count(*) FROM iterations WHERE notes IS NULL").fetchone()[0] == 0
        with pytest.raises(StoreFormatError, match=r"idx 3\) fails its checksum"):  # still caught
            store.iterations(sid)
    raw(path, "UPDATE iterations SET notes = '[]' WHERE idx = 2")  # the notes are covered by the checksum
    with Store(path, create=False) as store, pytest.raises(StoreFormatError, match="fails its checksum"):
        store.iterations(sid, indices=[2])


V7_COLUMNS = ("signal_names", "signal_rows", "signal_codec", "signal_checksum", "signals")


def _flip_session(store, trials):
    """A session of the browse fixtures' flip with one iteration per trial."""
    import numpy as np

    from aerobat.core.learning import Iteration, IterationStatus
    from browse_fixtures import DESIGN, FLIP, VEHICLE

    params = DESIGN.p_nominal.copy()
    sid = store.create_session(vehicle=VEHICLE, plant_kind="betaflight", plant_config={}, maneuver=FLIP,
                               design=DESIGN, seed=None, rule={"name": "paper"}, target_iterations=len(trials),
                               start_params=params)
    for i, trial in enumerate(trials, start=1):
        store.append_iteration(sid, Iteration(i, i, IterationStatus.OK, params, np.full(len(FLIP.errors), 0.1),
                                              0.5, 1.0, np.zeros_like(params), "measured", trial))
    return sid


def _trial(signals):
    import numpy as np

    from aerobat.core.plant import Trial, TrialStatus
    from aerobat.quadrotor.dynamics import N_STATE

    times = np.linspace(0.0, 0.5, 51)
    states = np.tile(np.arange(N_STATE, dtype=float), (51, 1))
    return Trial(TrialStatus.OK, "ok", states[-1], times, states, states[0], {}, signals)


def test_a_plants_signals_are_stored_read_back_and_covered_by_their_checksum(tmp_path):
    """Schema 7: the signals a plant sampled (a flight controller's set point, PID terms, motors) round-trip."""
    import numpy as np

    from aerobat.core.plant import Signals

    rng = np.random.default_rng(7)
    times = np.arange(40) / 250.0
    signals = Signals(times, ("motor1", "setpoint_roll_deg_s", "p_roll"), rng.normal(size=(40, 3)) * [1, 900, 300])
    path = tmp_path / "s.sqlite"
    with Store(path) as store:
        sid = _flip_session(store, [_trial(signals), _trial(None)])
        with_signals, without = store.iterations(sid, trajectories=True)
        assert without.signals is None and store.iterations(sid)[0].signals is None  # read only with trajectories
        got = with_signals.signals
        assert got is not None and got.names == signals.names
        np.testing.assert_allclose(got.times_s, times, rtol=1e-7)
        np.testing.assert_allclose(got.values, signals.values, rtol=1e-6)  # float32, as trajectories are
        np.testing.assert_array_equal(got.column("setpoint_roll_deg_s"), got.values[:, 1])
    raw(path, "UPDATE iterations SET signals = zeroblob(length(signals)) WHERE idx = 1")
    with Store(path, create=False) as store:
        assert len(store.iterations(sid)) == 2  # the rows themselves are intact
        with pytest.raises(StoreFormatError, match="plant's signals of iteration 1 of session 1 fails its checksum"):
            store.iterations(sid, trajectories=True)
    raw(path, "UPDATE iterations SET signal_names = '[\"a\", \"b\", \"c\"]' WHERE idx = 1")  # covered by the row's
    with Store(path, create=False) as store, pytest.raises(StoreFormatError, match="fails its checksum"):
        store.iterations(sid, indices=[1])


def test_a_version_6_store_is_migrated_with_its_checksums_kept(tmp_path):
    """Schema 7 adds the signals columns: a version-6 row gets its new checksum; a damaged one stays refused."""
    path = tmp_path / "v6.sqlite"
    with Store(path) as store:
        sid = _flip_session(store, [_trial(None), _trial(None), _trial(None)])
    with contextlib.closing(sqlite3.connect(path)) as conn:  # the file as version 6 wrote it
        for column in V7_COLUMNS:
            conn.execute(f"ALTER TABLE iterations DROP COLUMN {column}")
        checksums.backfill(conn, "iterations", [c for c in checksums.COVERED["iterations"] if c not in V7_COLUMNS])
        conn.execute("UPDATE iterations SET gamma = 0.25 WHERE idx = 3")  # damaged before the migration
        conn.execute("PRAGMA user_version = 6")
        conn.commit()
    with Store(path) as store:
        assert store.migrated_from == [6] and store.schema_version == 7
        got = store.iterations(sid, trajectories=True, indices=[1, 2])
        assert [it.signals for it in got] == [None, None] and got[0].times_s is not None
        with pytest.raises(StoreFormatError, match=r"idx 3\) fails its checksum"):  # still caught
            store.iterations(sid)


def test_docs_state_the_real_schema_version():
    text = (Path(__file__).parents[2] / "docs" / "store.md").read_text()
    from aerobat.store.migrations import SCHEMA_VERSION

    assert f"(currently {SCHEMA_VERSION})" in text and f"Version {SCHEMA_VERSION} adds" in text


# ------------------------------------------------------------------ S2, I7: ids and indices


def test_session_ids_that_are_not_sessions_are_refused(db):
    with Store(db, create=False) as store:
        for bad in (99999, "x", True, 1.5, None):
            with pytest.raises(SessionNotFound):
                store.iterations(bad)
        with pytest.raises(SessionNotFound):
            store.session(True)
        with pytest.raises(SessionNotFound):
            store.last_iteration(0)
        with pytest.raises(ConfigError, match="indices"):
            store.iterations(1, indices=["a"])
        with pytest.raises(ConfigError, match="indices"):
            store.iterations(1, indices="12")
        assert [it.index for it in store.iterations(1, indices=[3, 1])] == [1, 3]


# ------------------------------------------------------------------ I6: damaged JSON


def test_damaged_json_is_one_clear_line(db, tmp_path):
    with contextlib.closing(sqlite3.connect(db)) as conn:  # as a buggy writer or a pre-checksum file left it
        checksums.update(conn, db, "iterations", {"session_id": 2, "idx": 2}, {"learner_state": "{broken"})
        study = conn.execute("SELECT coalesce(max(id), 0) + 1 FROM studies").fetchone()[0]
        checksums.insert(conn, "studies", {"id": study, "kind": "rules", "spec": "{}", "created_at": "t",
                                           "command": "[]", "out_dir": None})
        checksums.insert(conn, "study_jobs", {"study_id": study, "key": "k", "spec": "{}", "result": "{nope",
                                              "recorded_at": "t", "status": "done", "error": None, "attempts": 1,
                                              "session_id": None})
        conn.commit()
    code, _, err = call(["studies", str(study), "--json", "--db", str(db)])
    assert code == 2
    one_error_line(err, f"study {study} job k: damaged JSON")
    code, _, err = call(["learn", "--resume", "2", "--trials", "3", "--db", str(db), "--out", str(tmp_path / "r")])
    assert code == 2
    one_error_line(err, "iteration 2 of session 2: damaged JSON")


# ------------------------------------------------------------------ H3: an exclusive lock


def test_an_exclusive_lock_is_reported_at_once(db):
    holder = subprocess.Popen([sys.executable, "-c", (
        "import sqlite3, sys, time\n"
        f"c = sqlite3.connect({str(db)!r}, isolation_level=None)\n"
        "c.execute('PRAGMA locking_mode = EXCLUSIVE'); c.execute('BEGIN EXCLUSIVE'); c.execute('COMMIT')\n"
        "c.execute('SELECT count(*) FROM sessions').fetchone()\n"
        "print('held', flush=True); time.sleep(60)\n")], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        told: list[tuple[float, str]] = []
        start = time.monotonic()
        with pytest.raises(StoreBusyError, match="exclusive lock.*close that program"):
            Store(db, create=False, busy_timeout_s=3,
                  on_wait=lambda message: told.append((time.monotonic() - start, message)))
        waited = time.monotonic() - start
        assert len(told) == 1 and told[0][0] < 1.5 and "locking_mode = EXCLUSIVE" in told[0][1], told
        assert 2.9 < waited < 6, waited
    finally:
        holder.kill()
        holder.wait()
    with Store(db, create=False) as store:  # once it lets go, everything reads
        assert len(store.list_sessions()) == 2


# ------------------------------------------------------------------ P3: creating a store while others read it


def test_a_reader_never_initialises_an_sqlite_file_without_tables(tmp_path):
    path = tmp_path / "s.sqlite"
    with contextlib.closing(sqlite3.connect(path)) as conn:  # what a store is for an instant while created
        conn.execute("PRAGMA journal_mode = WAL")
    before = path.read_bytes()
    with pytest.raises(StoreAccessError, match="no aerobat database yet"):
        Store(path, create=False)
    assert path.read_bytes() == before


def _writer(db: str, go: object) -> None:
    go.wait()  # type: ignore[attr-defined]
    Store(db).close()


def _reader(db: str, go: object, queue: object) -> None:
    go.wait()  # type: ignore[attr-defined]
    errors, deadline = [], time.monotonic() + 0.4
    while time.monotonic() < deadline:
        try:
            with Store(db, create=False) as store:
                store.list_sessions()
        except (StoreAccessError, StoreFormatError) as exc:
            if "no such database" not in str(exc) and "no aerobat database yet" not in str(exc):
                errors.append(str(exc))
    queue.put(errors)  # type: ignore[attr-defined]


def test_two_writers_creating_a_store_while_a_reader_reads_it(tmp_path):
    context = multiprocessing.get_context("fork")
    for k in range(8):  # before the fix, 27 of 30 such rounds gave the reader "attempt to write a readonly database"
        db = str(tmp_path / f"s{k}.sqlite")
        go, queue = context.Event(), context.Queue()
        procs = [context.Process(target=_writer, args=(db, go)) for _ in range(2)]
        procs.append(context.Process(target=_reader, args=(db, go, queue)))
        for p in procs:
            p.start()
        go.set()
        errors = queue.get(timeout=60)
        for p in procs:
            p.join(timeout=60)
        assert errors == [] and [p.exitcode for p in procs] == [0, 0, 0], errors
        with Store(db, create=False) as store:
            assert store.integrity_check() == []
    assert not list(tmp_path.glob(".*creating*"))  # no temporary file left behind
