"""Schema of the experiment store and its forward migrations.

The schema version lives in SQLite's ``PRAGMA user_version`` (and the file is
tagged with ``PRAGMA application_id`` = :data:`APPLICATION_ID`). A migration
takes a database from version *n* to *n + 1* inside one write transaction, so a
crash halfway leaves the old version intact. A database whose version is newer
than :data:`SCHEMA_VERSION` is refused and never modified (see :mod:`aerobat.store`).

History
-------
1. First layout: vehicles, plants, maneuvers, designs, sessions, iterations.
   Listing sessions had to aggregate over all iterations, and the plant's
   random state was not kept, so a resumed arena session could not repeat an
   uninterrupted one.
2. Per-session summary columns (kept up to date in the same transaction as each
   iteration), the parameters the next trial flies (``current_params``), the
   plant's state after every trial (``iterations.plant_state``) and an index on
   session state.
3. Studies (``aerobat study …``): a ``studies`` row per study and a ``study_jobs``
   row per finished job (its specification and result as JSON), written as each
   job completes, so an interrupted study resumes with only the unfinished jobs.
4. What each error component measures (``maneuvers.error_kinds``: the position
   error no longer guessed from units), the learner's state after every trial
   (``iterations.learner_state``: counters, parameters and the update rule's own
   state, so every rule resumes exactly), failed study jobs kept with their error
   and attempts (``study_jobs.status``, ``error``, ``attempts``; only ``done`` jobs
   count as finished), the session a study job learned in (``study_jobs.session_id``,
   ``sessions.study_id``), and a study's command and output folder.
   Older maneuvers get their kinds from their units once, in the migration
   (m → position, m/s → velocity, rad → angle), the only information they have.
5. A checksum of every row (``checksum`` in every table, ``iterations.traj_checksum``
   for the trajectory; :mod:`aerobat.store.checksums`), verified on every read, and
   the user's tags and notes on sessions (``sessions.tags``, ``notes``). The migration
   computes the checksums of what the file holds.
6. An iteration's notes as data (``iterations.notes``: JSON list of ``{kind, parameter,
   text}``, :class:`~aerobat.core.notes.IterationNote`), written with the iteration; before,
   the store read them back out of the message's words. The migration gives older rows the
   notes their messages say (:func:`legacy_notes_from_message`, kept for this migration only)
   and their new checksums; a row that failed its checksum before keeps failing it.
7. What a plant sampled inside itself during each trial (``iterations.signals``: a flight
   controller's set point, PID terms and motors, :class:`~aerobat.core.plant.Signals`), kept
   apart like the trajectory: its names (``signal_names``, JSON), rows and codec in the row,
   the samples in a blob with its own checksum (``signal_checksum``). Older rows have none;
   the migration gives them their new checksums (a row that failed before keeps failing).
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Callable

import numpy as np

from aerobat.core.codec import Form, encode_value
from aerobat.core.notes import HELD_PREFIX, WARNING_PREFIX, IterationNote, NoteKind
from aerobat.errors import StoreFormatError
from aerobat.store.checksums import COVERED, backfill, record_checksum

__all__ = ["APPLICATION_ID", "MIGRATIONS", "SCHEMA", "SCHEMA_V1", "SCHEMA_VERSION", "TABLES", "TABLES_SINCE",
           "legacy_notes_from_message", "migrate", "sql_statements"]

SCHEMA_VERSION = 7
"""The version this aerobat writes; it reads 1 to 6 (migrating them) and 7."""

APPLICATION_ID = 0x41455242
"""``PRAGMA application_id`` of aerobat stores ("AERB")."""

TABLES = ("meta", "vehicles", "plants", "maneuvers", "designs", "sessions", "iterations", "studies", "study_jobs")
"""Tables of the current schema."""

TABLES_SINCE = {"studies": 3, "study_jobs": 3}
"""Tables added after version 1, with the version that added them (older files lack them)."""

_COMMON = """
CREATE TABLE meta (
    key   TEXT PRIMARY KEY,
    value TEXT NOT NULL
) WITHOUT ROWID;

CREATE TABLE vehicles (
    id     INTEGER PRIMARY KEY,
    name   TEXT NOT NULL,
    config TEXT NOT NULL,              -- JSON: {"name", "vehicle": {...}, "controller": {...}}
    digest TEXT NOT NULL UNIQUE        -- sha256 of the canonical JSON (deduplication)
);

CREATE TABLE plants (
    id         INTEGER PRIMARY KEY,
    kind       TEXT NOT NULL,          -- nominal, arena, rotorpy, ...
    vehicle_id INTEGER NOT NULL REFERENCES vehicles(id),
    config     TEXT NOT NULL,          -- JSON, e.g. {"arena": {...ArenaParams...}}
    digest     TEXT NOT NULL UNIQUE
);

CREATE TABLE maneuvers (
    id              INTEGER PRIMARY KEY,
    kind            TEXT NOT NULL,     -- spec["kind"]
    name            TEXT NOT NULL,
    spec            TEXT NOT NULL,     -- JSON: Maneuver.spec()
    parameter_names TEXT NOT NULL,     -- JSON lists
    parameter_units TEXT NOT NULL,
    error_names     TEXT NOT NULL,
    error_units     TEXT NOT NULL,
    error_scales    TEXT NOT NULL,
    digest          TEXT NOT NULL UNIQUE
);
CREATE TABLE designs (
    id               INTEGER PRIMARY KEY,
    maneuver_id      INTEGER NOT NULL REFERENCES maneuvers(id),
    vehicle_id       INTEGER NOT NULL REFERENCES vehicles(id),   -- the design model
    n_par            INTEGER NOT NULL,
    n_err            INTEGER NOT NULL,
    p_guess          BLOB NOT NULL,    -- float64 little-endian, (n_par,)
    p_nominal        BLOB NOT NULL,    -- (n_par,)
    residual         BLOB NOT NULL,    -- (n_err,)
    residual_norm    REAL,
    jacobian         BLOB NOT NULL,    -- (n_err, n_par), row-major
    correction       BLOB NOT NULL,    -- (n_par, n_err), row-major
    correction_kind  TEXT NOT NULL,
    singular_values  BLOB NOT NULL,
    condition_number REAL,
    rank             INTEGER NOT NULL,
    converged        INTEGER NOT NULL,
    status           TEXT NOT NULL,
    message          TEXT NOT NULL,
    duration_s       REAL,
    compute_s        REAL,
    evaluations      INTEGER NOT NULL,
    created_at       TEXT NOT NULL,
    digest           TEXT NOT NULL UNIQUE
);
"""

SCHEMA_V1 = _COMMON + """
CREATE TABLE sessions (
    id                INTEGER PRIMARY KEY,
    maneuver_id       INTEGER NOT NULL REFERENCES maneuvers(id),
    design_id         INTEGER NOT NULL REFERENCES designs(id),
    plant_id          INTEGER NOT NULL REFERENCES plants(id),
    seed              INTEGER,
    rule              TEXT NOT NULL,
    target_iterations INTEGER NOT NULL,
    start_params      BLOB NOT NULL,
    warm_start_from   INTEGER REFERENCES sessions(id),
    state             TEXT NOT NULL,
    message           TEXT NOT NULL DEFAULT '',
    started_at        TEXT NOT NULL,
    updated_at        TEXT NOT NULL,
    ended_at          TEXT,
    host              TEXT,
    pid               INTEGER,
    owner             TEXT,
    command           TEXT,
    aerobat_version   TEXT
);

CREATE TABLE iterations (
    session_id  INTEGER NOT NULL REFERENCES sessions(id) ON DELETE CASCADE,
    idx         INTEGER NOT NULL CHECK (idx >= 1),
    correction  INTEGER NOT NULL,
    status      TEXT NOT NULL,
    params      BLOB NOT NULL,
    next_params BLOB NOT NULL,
    error       BLOB NOT NULL,
    gamma       REAL NOT NULL,
    scale       REAL NOT NULL,
    message     TEXT NOT NULL,
    final_state BLOB,
    start_state BLOB,
    traj_rows   INTEGER NOT NULL DEFAULT 0,
    traj_cols   INTEGER NOT NULL DEFAULT 0,
    traj_codec  TEXT,
    trajectory  BLOB,
    info        TEXT,
    recorded_at TEXT NOT NULL,
    PRIMARY KEY (session_id, idx)
);
"""
"""Version 1 exactly as it was created (kept to test the migration)."""

SCHEMA = _COMMON + """
ALTER TABLE maneuvers ADD COLUMN error_kinds TEXT;  -- JSON list: position, velocity, angle… (version 4)

CREATE TABLE sessions (
    id                    INTEGER PRIMARY KEY,
    maneuver_id           INTEGER NOT NULL REFERENCES maneuvers(id),
    design_id             INTEGER NOT NULL REFERENCES designs(id),
    plant_id              INTEGER NOT NULL REFERENCES plants(id),
    seed                  INTEGER,
    rule                  TEXT NOT NULL,   -- JSON: {"name": "paper", "schedule": {...}}
    target_iterations     INTEGER NOT NULL,
    start_params          BLOB NOT NULL,
    warm_start_from       INTEGER REFERENCES sessions(id),
    state                 TEXT NOT NULL,   -- running, completed, interrupted, crashed, aborted, failed
    message               TEXT NOT NULL DEFAULT '',
    started_at            TEXT NOT NULL,
    updated_at            TEXT NOT NULL,
    ended_at              TEXT,
    host                  TEXT,
    pid                   INTEGER,
    owner                 TEXT,            -- host:pid:process start time of the writer
    command               TEXT,            -- JSON list of the command-line arguments
    aerobat_version       TEXT,
    -- summary, updated in the same transaction as every iteration (version 2)
    n_records             INTEGER NOT NULL DEFAULT 0,
    n_measured            INTEGER NOT NULL DEFAULT 0,
    last_index            INTEGER NOT NULL DEFAULT 0,
    last_correction       INTEGER NOT NULL DEFAULT 0,
    last_error            BLOB,
    last_position_error_m REAL,
    current_params        BLOB,            -- what the next trial flies
    study_id              INTEGER REFERENCES studies(id)   -- version 4: the study it learned for
);

CREATE INDEX sessions_state ON sessions(state);

CREATE TABLE iterations (
    session_id  INTEGER NOT NULL REFERENCES sessions(id) ON DELETE CASCADE,
    idx         INTEGER NOT NULL CHECK (idx >= 1),
    correction  INTEGER NOT NULL,          -- 0 if this trial drove no correction
    status      TEXT NOT NULL,             -- ok, rejected, no_trigger, crashed, aborted
    params      BLOB NOT NULL,             -- float64 (n_par,): flown
    next_params BLOB NOT NULL,             -- float64 (n_par,): after this record's correction
    error       BLOB NOT NULL,             -- float64 (n_err,), NaN if none
    gamma       REAL NOT NULL,
    scale       REAL NOT NULL,
    message     TEXT NOT NULL,
    final_state BLOB,                      -- float64 measured final state
    start_state BLOB,
    traj_rows   INTEGER NOT NULL DEFAULT 0,
    traj_cols   INTEGER NOT NULL DEFAULT 0,
    traj_codec  TEXT,
    trajectory  BLOB,                      -- [times_s | states], see aerobat.store.encode_trajectory
    info        TEXT,                      -- JSON: the plant's extras
    recorded_at TEXT NOT NULL,
    plant_state TEXT,                      -- JSON: the plant after this trial (version 2)
    learner_state TEXT,                    -- JSON: the learner and its rule after this trial (version 4)
    PRIMARY KEY (session_id, idx)
);
""" + """
CREATE TABLE studies (
    id         INTEGER PRIMARY KEY,
    kind       TEXT NOT NULL,              -- robustness, envelope, rules, map
    spec       TEXT NOT NULL,              -- JSON: everything that defines the study
    created_at TEXT NOT NULL,
    command    TEXT,                       -- JSON list of the command-line arguments (version 4)
    out_dir    TEXT                        -- where its report and figures go (version 4)
);

CREATE TABLE study_jobs (
    study_id    INTEGER NOT NULL REFERENCES studies(id) ON DELETE CASCADE,
    key         TEXT NOT NULL,             -- unique within the study
    spec        TEXT NOT NULL,             -- JSON job specification (seed included)
    result      TEXT NOT NULL,             -- JSON result, including every learning iteration
    recorded_at TEXT NOT NULL,
    status      TEXT NOT NULL DEFAULT 'done',   -- done or failed (version 4)
    error       TEXT,                           -- why it failed (version 4)
    attempts    INTEGER NOT NULL DEFAULT 1,     -- runs so far (version 4)
    session_id  INTEGER REFERENCES sessions(id),  -- the session it learned in (version 4)
    PRIMARY KEY (study_id, key)
);
"""
"""The current schema (version :data:`SCHEMA_VERSION`)."""

_V5_COLUMNS = (
    *(f"{table} ADD COLUMN checksum INTEGER" for table in TABLES),  # CRC-32 of the row (aerobat.store.checksums)
    "iterations ADD COLUMN traj_checksum INTEGER",  # CRC-32 of the trajectory blob
    "sessions ADD COLUMN tags TEXT",                # JSON list of the user's tags
    "sessions ADD COLUMN notes TEXT",               # JSON list of {"at", "text"}: the user's notes
)
SCHEMA += "".join(f"\nALTER TABLE {column};" for column in _V5_COLUMNS) + "\n"

_V6_COLUMN = "iterations ADD COLUMN notes TEXT"  # JSON list of {"kind", "parameter", "text"} (IterationNote)
SCHEMA += f"ALTER TABLE {_V6_COLUMN};\n"

_V7_COLUMNS = (
    "iterations ADD COLUMN signal_names TEXT",                    # JSON list of the columns' names (Signals.names)
    "iterations ADD COLUMN signal_rows INTEGER NOT NULL DEFAULT 0",
    "iterations ADD COLUMN signal_codec TEXT",
    "iterations ADD COLUMN signal_checksum INTEGER",              # CRC-32 of the signals blob
    "iterations ADD COLUMN signals BLOB",                         # [times_s | values], as the trajectory is stored
)
SCHEMA += "".join(f"ALTER TABLE {column};\n" for column in _V7_COLUMNS)

_STUDY_TABLES_V3 = """
CREATE TABLE studies (
    id         INTEGER PRIMARY KEY,
    kind       TEXT NOT NULL,
    spec       TEXT NOT NULL,
    created_at TEXT NOT NULL
);

CREATE TABLE study_jobs (
    study_id    INTEGER NOT NULL REFERENCES studies(id) ON DELETE CASCADE,
    key         TEXT NOT NULL,
    spec        TEXT NOT NULL,
    result      TEXT NOT NULL,
    recorded_at TEXT NOT NULL,
    PRIMARY KEY (study_id, key)
);
"""


def sql_statements(script: str) -> list[str]:
    """A schema script's statements, each ending where SQLite says one is complete (comments dropped)."""
    statements, pending = [], ""
    for line in script.splitlines():
        pending += line.split("--", 1)[0] + "\n"
        if sqlite3.complete_statement(pending):
            statements.append(pending.strip())
            pending = ""
    return statements + ([pending.strip()] if pending.strip() else [])


def _migrate_1_to_2(conn: sqlite3.Connection) -> None:
    for column in ("n_records INTEGER NOT NULL DEFAULT 0", "n_measured INTEGER NOT NULL DEFAULT 0",
                   "last_index INTEGER NOT NULL DEFAULT 0", "last_correction INTEGER NOT NULL DEFAULT 0",
                   "last_error BLOB", "last_position_error_m REAL", "current_params BLOB"):
        conn.execute(f"ALTER TABLE sessions ADD COLUMN {column}")
    conn.execute("ALTER TABLE iterations ADD COLUMN plant_state TEXT")
    conn.execute("CREATE INDEX sessions_state ON sessions(state)")
    conn.execute(
        """
        UPDATE sessions SET
            n_records = (SELECT count(*) FROM iterations i WHERE i.session_id = sessions.id),
            n_measured = (SELECT count(*) FROM iterations i WHERE i.session_id = sessions.id AND i.status = 'ok'),
            last_index = coalesce((SELECT max(idx) FROM iterations i WHERE i.session_id = sessions.id), 0),
            last_correction = coalesce((SELECT max(correction) FROM iterations i
                                        WHERE i.session_id = sessions.id), 0),
            current_params = coalesce((SELECT next_params FROM iterations i WHERE i.session_id = sessions.id
                                       ORDER BY idx DESC LIMIT 1), start_params),
            last_error = (SELECT error FROM iterations i WHERE i.session_id = sessions.id AND i.status = 'ok'
                          ORDER BY idx DESC LIMIT 1)
        """
    )
    rows = conn.execute(
        "SELECT s.id, s.last_error, m.error_units FROM sessions s JOIN maneuvers m ON m.id = s.maneuver_id "
        "WHERE s.last_error IS NOT NULL"
    ).fetchall()
    for session_id, blob, units in rows:
        error = np.frombuffer(blob, dtype="<f8")
        mask = np.array([u == "m" for u in json.loads(units)], dtype=bool)
        if mask.shape == error.shape and mask.any():
            conn.execute("UPDATE sessions SET last_position_error_m = ? WHERE id = ?",
                         (float(np.linalg.norm(error[mask])), session_id))


def _migrate_2_to_3(conn: sqlite3.Connection) -> None:
    for statement in sql_statements(_STUDY_TABLES_V3):
        if statement:
            conn.execute(statement)


_KIND_OF_UNIT = {"m": "position", "m/s": "velocity", "rad": "angle", "rad/s": "rate"}


def _migrate_3_to_4(conn: sqlite3.Connection) -> None:
    conn.execute("ALTER TABLE maneuvers ADD COLUMN error_kinds TEXT")
    for maneuver_id, units in conn.execute("SELECT id, error_units FROM maneuvers").fetchall():
        kinds = [_KIND_OF_UNIT.get(u, "other") for u in json.loads(units)]
        conn.execute("UPDATE maneuvers SET error_kinds = ? WHERE id = ?", (json.dumps(kinds), maneuver_id))
    conn.execute("ALTER TABLE iterations ADD COLUMN learner_state TEXT")
    conn.execute("ALTER TABLE sessions ADD COLUMN study_id INTEGER REFERENCES studies(id)")
    conn.execute("ALTER TABLE studies ADD COLUMN command TEXT")
    conn.execute("ALTER TABLE studies ADD COLUMN out_dir TEXT")
    for column in ("status TEXT NOT NULL DEFAULT 'done'", "error TEXT", "attempts INTEGER NOT NULL DEFAULT 1",
                   "session_id INTEGER REFERENCES sessions(id)"):
        conn.execute(f"ALTER TABLE study_jobs ADD COLUMN {column}")
    # version 3 recorded a failed job as a result with status "error" and counted it as finished
    conn.execute("""UPDATE study_jobs SET status = 'failed', error = json_extract(result, '$.message')
                    WHERE json_valid(result) AND json_extract(result, '$.status') = 'error'""")


_ADDED_IN_6 = {"iterations": ("notes",)}
"""Covered columns that version 5 does not have yet."""
_ADDED_IN_7 = {"iterations": ("signal_names", "signal_rows", "signal_codec", "signal_checksum")}
"""Covered columns that version 6 does not have yet."""


def _covered_before(table: str, version: int) -> list[str]:
    """The columns a version's checksum of ``table`` covers (``version`` 5 or 6)."""
    later = [_ADDED_IN_7] + ([_ADDED_IN_6] if version < 6 else [])
    return [c for c in COVERED[table] if not any(c in added.get(table, ()) for added in later)]


def _migrate_4_to_5(conn: sqlite3.Connection) -> None:
    for column in _V5_COLUMNS:
        conn.execute(f"ALTER TABLE {column}")
    for table in TABLES:
        backfill(conn, table, _covered_before(table, 5))


def legacy_notes_from_message(message: str) -> tuple[IterationNote, ...]:
    """The notes an iteration's message says in words — only to migrate rows written before schema 6.

    Until schema 6 the store kept an iteration's notes only in its message
    (:func:`~aerobat.core.notes.message_with_notes`: the parameters held at a bound in one
    clause, then each warning, whose first word is the parameter pinned). This reads them
    back once, when such a row is migrated; nothing else reads notes out of text.
    """
    head, *warnings = message.split(WARNING_PREFIX)
    held = head.partition(HELD_PREFIX)[2]
    notes = [IterationNote.held(name) for name in held.split(", ") if name]
    return tuple(notes + [IterationNote(NoteKind.PINNED_AT_BOUND, text.split(" (", 1)[0], text)
                          for text in warnings])


def _migrate_5_to_6(conn: sqlite3.Connection) -> None:
    conn.execute(f"ALTER TABLE {_V6_COLUMN}")
    old = _covered_before("iterations", 5)  # a version-5 row's checksum
    updates = []
    for row in conn.execute(f"SELECT {', '.join(old)}, checksum FROM iterations").fetchall():
        values = dict(zip(old, row, strict=False))
        notes = encode_value(legacy_notes_from_message(str(values["message"])), Form.COLUMNS)
        intact = row[-1] == record_checksum("iterations", row[:-1])
        checksum = record_checksum("iterations", [*row[:-1], notes]) if intact else row[-1]
        updates.append((notes, checksum, values["session_id"], values["idx"]))
    conn.executemany("UPDATE iterations SET notes = ?, checksum = ? WHERE session_id = ? AND idx = ?", updates)


def _migrate_6_to_7(conn: sqlite3.Connection) -> None:
    for column in _V7_COLUMNS:
        conn.execute(f"ALTER TABLE {column}")
    old = _covered_before("iterations", 6)  # a version-6 row's checksum
    updates = []
    for row in conn.execute(f"SELECT {', '.join(old)}, checksum FROM iterations").fetchall():
        values = dict(zip(old, row, strict=False))
        intact = row[-1] == record_checksum("iterations", row[:-1])
        # the new columns, as a row without signals holds them: no names, 0 rows, no codec, no checksum
        checksum = record_checksum("iterations", [*row[:-1], None, 0, None, None]) if intact else row[-1]
        updates.append((checksum, values["session_id"], values["idx"]))
    conn.executemany("UPDATE iterations SET checksum = ? WHERE session_id = ? AND idx = ?", updates)


MIGRATIONS: dict[int, Callable[[sqlite3.Connection], None]] = {1: _migrate_1_to_2, 2: _migrate_2_to_3,
                                                               3: _migrate_3_to_4, 4: _migrate_4_to_5,
                                                               5: _migrate_5_to_6, 6: _migrate_6_to_7}
"""``MIGRATIONS[n]`` takes a database from version n to n + 1 (inside the caller's transaction)."""


def migrate(conn: sqlite3.Connection, from_version: int) -> list[int]:
    """Apply every migration from ``from_version`` to :data:`SCHEMA_VERSION` on ``conn``.

    The caller holds a write transaction; ``PRAGMA user_version`` is updated in it.
    Returns the versions migrated from.
    """
    done = []
    version = from_version
    while version < SCHEMA_VERSION:
        step = MIGRATIONS.get(version)
        if step is None:
            raise StoreFormatError(f"no migration from schema version {version}")
        step(conn)
        done.append(version)
        version += 1
        conn.execute(f"PRAGMA user_version = {version}")
    return done
