"""The experiment store: one SQLite file with every design, learning session, trial and study.

Layout and guarantees are described in ``docs/store.md``. In short:

* stdlib :mod:`sqlite3`, WAL journal, foreign keys on, ``busy_timeout`` and short
  ``BEGIN IMMEDIATE`` transactions (retried on ``SQLITE_BUSY``), so several
  ``aerobat learn`` processes can write one file at once;
* every iteration is one transaction (the iteration row, the learner's state after
  it and its session's summary row together), committed before the next trial
  starts: a killed process loses at most the trial in flight, and resumes exactly;
* the schema version is ``PRAGMA user_version``; older files are migrated in
  place (:mod:`aerobat.store.migrations`), newer, foreign or corrupted files are
  refused with a message and never modified.

The store knows nothing about quadrocopters: maneuvers and designs are taken
through the generic :class:`~aerobat.core.maneuver.Maneuver` protocol and plain
JSON tables; arrays are stored as little-endian float64 bytes (exact), measured
trajectories as compressed float32.
"""

from __future__ import annotations

import json
import os
import socket
import sqlite3
import zlib
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from aerobat.config import check_int, check_type, short_repr
from aerobat.errors import ConfigError, SessionInUse, SessionNotFound, StoreError, StoreFormatError
from aerobat.store.codec import (
    TRAJECTORY_CODEC,
    canonical_json,
    decode_trajectory,
    digest,
    encode_trajectory,
    json_ready,
    nan_if_none,
    pack_f8,
    unpack_f8,
    utc_now,
)
from aerobat.store.owners import owner_alive
from aerobat.store.records import (
    DesignRecord,
    IterationRecord,
    ManeuverRecord,
    PlantRecord,
    SessionRecord,
    SessionSummary,
    VehicleRecord,
)
from aerobat.store.studies import StudyTables

__all__ = ["SESSION_STATES", "Store"]

SESSION_STATES = ("running", "completed", "interrupted", "crashed", "aborted", "failed")
"""States a session can be stored in. ``running`` sessions whose process is gone are shown as ``killed``."""


class Store(StudyTables):
    """An aerobat experiment store: sessions, their iterations and studies (see :class:`Database` for opening)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._position_masks: dict[int, np.ndarray] = {}
        super().__init__(*args, **kwargs)

    # ---------------------------------------------------------- writing
    @staticmethod
    def _upsert(conn: sqlite3.Connection, table: str, columns: dict[str, Any]) -> int:
        names = ", ".join(columns)
        marks = ", ".join("?" * len(columns))
        conn.execute(f"INSERT OR IGNORE INTO {table} ({names}) VALUES ({marks})", tuple(columns.values()))
        return int(conn.execute(f"SELECT id FROM {table} WHERE digest = ?", (columns["digest"],)).fetchone()[0])

    def create_session(self, **session: Any) -> int:
        """Store a new session (with its vehicle, plant, maneuver and design, deduplicated); its id.

        Other Parameters
        ----------------
        vehicle : the plant's vehicle configuration table (``{"name", "vehicle", "controller"}``).
        plant_kind, plant_config : the plant (e.g. ``"arena"``, ``{"settings": {...}}``).
        maneuver : a :class:`~aerobat.core.maneuver.Maneuver` with ``spec()``.
        design : a :class:`~aerobat.core.design.Design` (any object with its attributes).
        design_vehicle : the design model's vehicle table (default: ``vehicle``).
        seed : the plant's seed.
        rule : the update rule and schedule as a JSON table.
        target_iterations : measured iterations to learn.
        start_params : (n_par,) parameters of the first trial.
        warm_start_from : session whose learned parameters ``start_params`` are.
        command : command-line arguments, kept for reference.
        study_id : the study this session runs for.
        """
        return int(self._write("creating a session", self._session_writer(**session)))

    def _session_writer(
        self,
        *,
        vehicle: Mapping[str, Any],
        plant_kind: str,
        plant_config: Mapping[str, Any],
        maneuver: Any,
        design: Any,
        design_vehicle: Mapping[str, Any] | None = None,
        seed: int | None,
        rule: Mapping[str, Any],
        target_iterations: int,
        start_params: np.ndarray,
        warm_start_from: int | None = None,
        command: Sequence[str] = (),
        study_id: int | None = None,
    ) -> Callable[[sqlite3.Connection], int]:
        """The transaction body that inserts a session (see :meth:`create_session`), checked and prepared."""
        from aerobat import __version__

        vehicle_json = canonical_json(json_ready(dict(vehicle)))
        model_json = canonical_json(json_ready(dict(design_vehicle if design_vehicle is not None else vehicle)))
        plant_json = canonical_json(json_ready(dict(plant_config)))
        spec_json = canonical_json(json_ready(maneuver.spec()))
        pnames = json.dumps([p.name for p in maneuver.parameters])
        punits = json.dumps([p.unit for p in maneuver.parameters])
        enames = json.dumps([e.name for e in maneuver.errors])
        eunits = json.dumps([e.unit for e in maneuver.errors])
        escales = json.dumps([float(e.scale) for e in maneuver.errors])
        ekinds = json.dumps([str(getattr(e, "kind", "other")) for e in maneuver.errors])
        n_par, n_err = len(maneuver.parameters), len(maneuver.errors)
        start = np.asarray(start_params, dtype=np.float64)
        if start.shape != (n_par,):
            raise ConfigError(f"start_params: expected {n_par} values, got shape {start.shape}")
        if isinstance(target_iterations, bool) or not isinstance(target_iterations, int) or target_iterations < 1:
            raise ConfigError(f"target_iterations = {target_iterations!r}: expected an integer >= 1")
        design_arrays = {
            "p_guess": pack_f8(design.p_guess), "p_nominal": pack_f8(design.p_nominal),
            "residual": pack_f8(design.residual),
            "jacobian": pack_f8(design.jacobian), "correction": pack_f8(design.correction),
            "singular_values": pack_f8(design.singular_values),
        }
        now = utc_now()

        def write(conn: sqlite3.Connection) -> int:
            vehicle_id = self._upsert(conn, "vehicles", {
                "name": str(vehicle.get("name", "")), "config": vehicle_json, "digest": digest(vehicle_json)})
            model_id = vehicle_id if model_json == vehicle_json else self._upsert(conn, "vehicles", {
                "name": str((design_vehicle or {}).get("name", "")), "config": model_json,
                "digest": digest(model_json)})
            plant_id = self._upsert(conn, "plants", {
                "kind": plant_kind, "vehicle_id": vehicle_id, "config": plant_json,
                "digest": digest(plant_kind, vehicle_id, plant_json)})
            maneuver_id = self._upsert(conn, "maneuvers", {
                "kind": str(maneuver.spec().get("kind", "")), "name": maneuver.name, "spec": spec_json,
                "parameter_names": pnames, "parameter_units": punits, "error_names": enames,
                "error_units": eunits, "error_scales": escales, "error_kinds": ekinds, "digest": digest(spec_json)})
            design_id = self._upsert(conn, "designs", {
                "maneuver_id": maneuver_id, "vehicle_id": model_id, "n_par": n_par, "n_err": n_err,
                **design_arrays,
                "residual_norm": float(design.residual_norm), "correction_kind": str(design.correction_kind),
                "condition_number": float(design.condition_number), "rank": int(design.rank),
                "converged": int(bool(design.converged)), "status": str(getattr(design.status, "value", design.status)),
                "message": str(design.message), "duration_s": float(design.duration_s),
                "compute_s": float(design.compute_s), "evaluations": int(getattr(design, "evaluations", 0)),
                "created_at": now,
                "digest": digest(maneuver_id, model_id, design.correction_kind, *design_arrays.values()),
            })
            cursor = conn.execute(
                """INSERT INTO sessions (maneuver_id, design_id, plant_id, seed, rule, target_iterations,
                       start_params, warm_start_from, state, message, started_at, updated_at, host, pid, owner,
                       command, aerobat_version, current_params, study_id)
                   VALUES (?, ?, ?, ?, ?, ?, ?, ?, 'running', 'started', ?, ?, ?, ?, ?, ?, ?, ?, ?)""",
                (maneuver_id, design_id, plant_id, seed, canonical_json(json_ready(dict(rule))), target_iterations,
                 pack_f8(start), warm_start_from, now, now, socket.gethostname(), os.getpid(), self.owner,
                 json.dumps(list(command)), __version__, pack_f8(start), study_id))
            return int(cursor.lastrowid or 0)

        return write

    def append_iteration(
        self,
        session_id: int,
        *,
        index: int,
        correction: int,
        status: str,
        params: np.ndarray,
        next_params: np.ndarray,
        error: np.ndarray,
        gamma: float,
        scale: float,
        message: str,
        final_state: np.ndarray | None = None,
        start_state: np.ndarray | None = None,
        times_s: np.ndarray | None = None,
        states: np.ndarray | None = None,
        plant_state: Mapping[str, Any] | None = None,
        learner_state: Mapping[str, Any] | None = None,
        info: Mapping[str, Any] | None = None,
    ) -> None:
        """Store one trial and update its session's summary, in one committed transaction.

        ``next_params`` are the parameters after this trial's correction exactly as applied,
        and ``learner_state`` everything needed to continue from here: one commit holds the
        whole iteration, so a process killed at any instant resumes from the right place.

        Only the process that owns the session (created or resumed it) may append, and
        ``index`` must be the session's last index + 1: a gap or a duplicate is refused.

        Raises
        ------
        StoreWriteError
            The disk is full or the write failed; nothing of this iteration is stored.
        StoreError
            Wrong index, or the session belongs to another process.
        """
        row, ok, position = self._iteration_row(
            session_id, index=index, correction=correction, status=status, params=params, next_params=next_params,
            error=error, gamma=gamma, scale=scale, message=message, final_state=final_state,
            start_state=start_state, times_s=times_s, states=states, plant_state=plant_state,
            learner_state=learner_state, info=info)
        self._write(f"storing iteration {index} of session {session_id}",
                    lambda conn: self._insert_iteration(conn, row, ok, position))

    def record_study_run(self, study_id: int, key: str, spec: Mapping[str, Any], result: Mapping[str, Any], *,
                         session: Mapping[str, Any], iterations: Sequence[Mapping[str, Any]], state: str,
                         message: str) -> int:
        """A study's finished learning job, all in one transaction: its session, iterations and job row.

        ``session`` holds :meth:`create_session`'s arguments. A process killed at any instant
        leaves either all of it or none of it; returns the new session's id.
        """
        insert_session = self._session_writer(**session)
        state = str(getattr(state, "value", state))
        if state not in SESSION_STATES:
            raise ConfigError(f"session state {state!r}: allowed {', '.join(SESSION_STATES)}")

        def write(conn: sqlite3.Connection) -> int:
            session_id = insert_session(conn)
            for it in iterations:
                row, ok, position = self._iteration_row(session_id, **dict(it))
                self._insert_iteration(conn, row, ok, position)
            now = utc_now()
            conn.execute("UPDATE sessions SET state = ?, message = ?, ended_at = ?, updated_at = ? WHERE id = ?",
                         (state, message, now, now, session_id))
            self._insert_study_job(conn, study_id, key, spec, result, "done", None, session_id)
            return session_id

        return int(self._write(f"recording study {study_id} job {key}", write))

    def append_iterations(self, session_id: int, iterations: Sequence[Mapping[str, Any]]) -> None:
        """Store several trials in one transaction (each a mapping of :meth:`append_iteration`'s arguments).

        Used to record a study's finished learning run as a session: all of it, or nothing.
        """
        rows = [self._iteration_row(session_id, **dict(it)) for it in iterations]

        def write(conn: sqlite3.Connection) -> None:
            for row, ok, position in rows:
                self._insert_iteration(conn, row, ok, position)

        self._write(f"storing {len(rows)} iterations of session {session_id}", write)

    def _iteration_row(self, session_id: int, *, index: int, correction: int, status: str, params: np.ndarray,
                       next_params: np.ndarray, error: np.ndarray, gamma: float, scale: float, message: str,
                       final_state: np.ndarray | None = None, start_state: np.ndarray | None = None,
                       times_s: np.ndarray | None = None, states: np.ndarray | None = None,
                       plant_state: Mapping[str, Any] | None = None,
                       learner_state: Mapping[str, Any] | None = None,
                       info: Mapping[str, Any] | None = None) -> tuple[tuple[Any, ...], bool, float | None]:
        traj: tuple[int, int, bytes | None] = (0, 0, None)
        if times_s is not None and states is not None and np.asarray(times_s).size:
            traj = encode_trajectory(times_s, states)
        err = np.asarray(error, dtype=np.float64)
        ok = str(status) == "ok"
        mask = self._position_mask(session_id)
        position = float(np.linalg.norm(err[mask])) if ok and mask.shape == err.shape and mask.any() else None
        row = (
            session_id, index, correction, str(status), pack_f8(params), pack_f8(next_params), pack_f8(err),
            float(gamma), float(scale), message, None if final_state is None else pack_f8(final_state),
            None if start_state is None else pack_f8(start_state), traj[0], traj[1],
            TRAJECTORY_CODEC if traj[2] is not None else None, traj[2],
            json.dumps(json_ready(dict(info or {}))), utc_now(),
            None if plant_state is None else json.dumps(plant_state, separators=(",", ":")),
            None if learner_state is None else json.dumps(json_ready(dict(learner_state)), separators=(",", ":")),
        )
        return row, ok, position

    def _insert_iteration(self, conn: sqlite3.Connection, row: tuple[Any, ...], ok: bool,
                          position: float | None) -> None:
        session_id, index, correction = row[0], row[1], row[2]
        cursor = conn.execute(
            """UPDATE sessions SET n_records = n_records + 1, n_measured = n_measured + ?,
                   last_index = ?, last_correction = CASE WHEN ? THEN ? ELSE last_correction END,
                   last_error = CASE WHEN ? THEN ? ELSE last_error END,
                   last_position_error_m = CASE WHEN ? THEN ? ELSE last_position_error_m END,
                   current_params = ?, updated_at = ?
               WHERE id = ? AND owner = ? AND last_index = ?""",
            (int(ok), index, ok, correction, ok, row[6], ok, position, row[5], row[17], session_id,
             self.owner, index - 1))
        if cursor.rowcount != 1:
            found = conn.execute("SELECT last_index, owner FROM sessions WHERE id = ?", (session_id,)).fetchone()
            if found is None:
                raise SessionNotFound(f"{self.path}: no session {session_id}")
            if found[1] != self.owner:
                raise StoreError(f"{self.path}: session {session_id} is now run by another process "
                                 f"({found[1]}); this process stops writing to it")
            raise StoreError(f"{self.path}: session {session_id}: iteration {index} does not follow the "
                             f"stored iteration {found[0]} (no gaps, no duplicates)")
        conn.execute(
            """INSERT INTO iterations (session_id, idx, correction, status, params, next_params, error, gamma,
                   scale, message, final_state, start_state, traj_rows, traj_cols, traj_codec, trajectory,
                   info, recorded_at, plant_state, learner_state)
               VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)""", row)

    def claim_session(self, session_id: int, *, take_over: bool = False) -> SessionRecord:
        """Take over a session to resume it: it becomes ``running`` under this process.

        A session marked running by a live process on this machine is never taken. One marked
        running by a process on another machine cannot be checked from here; ``take_over``
        says its process is gone (the caller's responsibility).

        Raises
        ------
        SessionNotFound
            No such session.
        SessionInUse
            Its process is still running, or ran on another machine and ``take_over`` is not given.
        """

        def write(conn: sqlite3.Connection) -> None:
            row = conn.execute("SELECT state, owner, pid, host FROM sessions WHERE id = ?", (session_id,)).fetchone()
            if row is None:
                raise SessionNotFound(f"{self.path}: no session {session_id} (see `aerobat sessions --db {self.path}`)")
            state, owner, pid, host = row
            alive = owner_alive(owner) if state == "running" and owner != self.owner else False
            if alive is None and not take_over:
                raise SessionInUse(f"{self.path}: session {session_id} was last run by process {pid} on another "
                                   f"machine ({host}), which this one cannot check; if that process is gone, "
                                   f"resume with --take-over")
            if alive:
                raise SessionInUse(f"{self.path}: session {session_id} is still being run by process {pid} on "
                                   f"{host}; stop that process before resuming")
            now = utc_now()
            conn.execute("UPDATE sessions SET state = 'running', owner = ?, pid = ?, host = ?, ended_at = NULL, "
                         "updated_at = ?, message = ? WHERE id = ?",
                         (self.owner, os.getpid(), socket.gethostname(), now, f"resumed (was {state})", session_id))

        self._write(f"claiming session {session_id}", write)
        return self.session(session_id)

    def set_target(self, session_id: int, target_iterations: int) -> None:
        """Change how many measured iterations the session aims for."""
        self._write(f"updating session {session_id}", lambda conn: conn.execute(
            "UPDATE sessions SET target_iterations = ?, updated_at = ? WHERE id = ?",
            (int(target_iterations), utc_now(), session_id)))

    def finish_session(self, session_id: int, state: str, message: str) -> None:
        """Record how the session ended (``state`` one of :data:`SESSION_STATES`)."""
        state = str(getattr(state, "value", state))
        if state not in SESSION_STATES:
            raise ConfigError(f"session state {state!r}: allowed {', '.join(SESSION_STATES)}")
        now = utc_now()
        self._write(f"closing session {session_id}", lambda conn: conn.execute(
            "UPDATE sessions SET state = ?, message = ?, ended_at = ?, updated_at = ? WHERE id = ? AND owner = ?",
            (state, message, None if state == "running" else now, now, session_id, self.owner)))

    # ---------------------------------------------------------- reading
    def _position_mask(self, session_id: int) -> np.ndarray:
        if session_id not in self._position_masks:
            with self._guard(f"reading session {session_id}"):
                row = self._db.execute("SELECT m.error_kinds FROM sessions s JOIN maneuvers m ON m.id = "
                                       "s.maneuver_id WHERE s.id = ?", (session_id,)).fetchone()
            kinds = json.loads(row[0]) if row and row[0] else []
            self._position_masks[session_id] = np.array([k == "position" for k in kinds], dtype=bool)
        return self._position_masks[session_id]

    def resolve_session(self, ref: int | str) -> int:
        """A session id from ``ref``: a positive id or ``"last"`` (the newest session)."""
        if isinstance(ref, str) and ref.strip().lower() == "last":
            with self._guard("listing sessions"):
                row = self._db.execute("SELECT max(id) FROM sessions").fetchone()
            if row is None or row[0] is None:
                raise SessionNotFound(f"{self.path}: holds no sessions yet")
            return int(row[0])
        try:
            if isinstance(ref, bool) or (isinstance(ref, float) and int(ref) != ref):
                raise TypeError
            session_id = int(ref)
        except (TypeError, ValueError, OverflowError):
            raise SessionNotFound(f"{self.path}: session {short_repr(ref)}: expected a session id or 'last'") from None
        if not 1 <= session_id < 2**63:
            raise SessionNotFound(f"{self.path}: no session {session_id} (see `aerobat sessions --db {self.path}`)")
        with self._guard("reading sessions"):
            found = self._db.execute("SELECT 1 FROM sessions WHERE id = ?", (session_id,)).fetchone()
        if not found:
            raise SessionNotFound(f"{self.path}: no session {session_id} (see `aerobat sessions --db {self.path}`)")
        return session_id

    _SUMMARY_COLUMNS = ("s.id, m.name, p.kind, s.seed, s.n_records, s.n_measured, s.target_iterations, "
                        "s.last_position_error_m, s.state, s.owner, s.started_at, s.updated_at, s.study_id")

    def list_sessions(self, *, limit: int | None = None, newest_first: bool = False) -> list[SessionSummary]:
        """Every session's summary row (no iteration is read)."""
        check_type("newest_first", newest_first, (bool, np.bool_), "True or False")
        order = "DESC" if newest_first else "ASC"
        sql = (f"SELECT {self._SUMMARY_COLUMNS} FROM sessions s JOIN maneuvers m ON m.id = s.maneuver_id "
               f"JOIN plants p ON p.id = s.plant_id ORDER BY s.id {order}")
        args: tuple[Any, ...] = ()
        if limit is not None:
            sql += " LIMIT ?"
            args = (check_int("limit", limit, low=0, high=2**63 - 1),)
        with self._guard("listing sessions"):
            rows = self._db.execute(sql, args).fetchall()
        alive: dict[str | None, bool | None] = {}
        out = []
        for r in rows:
            state, owner = r[8], r[9]
            display = state
            if state == "running":
                if owner not in alive:
                    alive[owner] = owner_alive(owner)
                if alive[owner] is False:
                    display = "killed"
            out.append(SessionSummary(id=r[0], maneuver_name=r[1], plant_kind=r[2], seed=r[3], n_records=r[4],
                                      n_measured=r[5], target_iterations=r[6], last_position_error_m=r[7],
                                      state=state, display_state=display, started_at=r[10], updated_at=r[11],
                                      study_id=r[12]))
        return out

    def session(self, session_id: int) -> SessionRecord:
        """The session and its summary."""
        with self._guard(f"reading session {session_id}"):
            r = self._db.execute(
                """SELECT s.id, s.maneuver_id, s.design_id, s.plant_id, s.seed, s.rule, s.target_iterations,
                          s.start_params, s.warm_start_from, s.state, s.message, s.started_at, s.updated_at,
                          s.ended_at, s.host, s.pid, s.owner, s.command, s.aerobat_version, s.n_records,
                          s.n_measured, s.last_index, s.last_correction, s.last_error, s.last_position_error_m,
                          s.current_params, m.name, p.kind, s.study_id
                   FROM sessions s JOIN maneuvers m ON m.id = s.maneuver_id JOIN plants p ON p.id = s.plant_id
                   WHERE s.id = ?""", (session_id,)).fetchone()
        if r is None:
            raise SessionNotFound(f"{self.path}: no session {session_id} (see `aerobat sessions --db {self.path}`)")
        state, owner = r[9], r[16]
        display = "killed" if state == "running" and owner_alive(owner) is False else state
        return SessionRecord(
            id=r[0], maneuver_id=r[1], design_id=r[2], plant_id=r[3], seed=r[4], rule=json.loads(r[5]),
            target_iterations=r[6], start_params=unpack_f8(r[7]), warm_start_from=r[8], state=state,
            display_state=display, message=r[10], started_at=r[11], updated_at=r[12], ended_at=r[13], host=r[14],
            pid=r[15], owner=owner, command=tuple(json.loads(r[17] or "[]")), aerobat_version=r[18],
            n_records=r[19], n_measured=r[20], last_index=r[21], last_correction=r[22],
            last_error=None if r[23] is None else unpack_f8(r[23]), last_position_error_m=r[24],
            current_params=unpack_f8(r[25] if r[25] is not None else r[7]), maneuver_name=r[26], plant_kind=r[27],
            study_id=r[28])

    def maneuver(self, maneuver_id: int) -> ManeuverRecord:
        """A stored maneuver specification."""
        with self._guard("reading a maneuver"):
            r = self._db.execute("SELECT id, kind, name, spec, parameter_names, parameter_units, error_names, "
                                 "error_units, error_scales, error_kinds FROM maneuvers WHERE id = ?",
                                 (maneuver_id,)).fetchone()
        if r is None:
            raise StoreFormatError(f"{self.path}: damaged: maneuver {maneuver_id} is missing")
        return ManeuverRecord(id=r[0], kind=r[1], name=r[2], spec=json.loads(r[3]),
                              parameter_names=tuple(json.loads(r[4])), parameter_units=tuple(json.loads(r[5])),
                              error_names=tuple(json.loads(r[6])), error_units=tuple(json.loads(r[7])),
                              error_scales=tuple(float(v) for v in json.loads(r[8])),
                              error_kinds=tuple(json.loads(r[9]) if r[9] else ["other"] * len(json.loads(r[6]))))

    def design(self, design_id: int) -> DesignRecord:
        """A stored design, arrays bit for bit as computed."""
        with self._guard("reading a design"):
            r = self._db.execute(
                """SELECT id, maneuver_id, vehicle_id, n_par, n_err, p_guess, p_nominal, residual, residual_norm,
                          jacobian, correction, correction_kind, singular_values, condition_number, rank,
                          converged, status, message, duration_s, compute_s, evaluations, created_at
                   FROM designs WHERE id = ?""", (design_id,)).fetchone()
        if r is None:
            raise StoreFormatError(f"{self.path}: damaged: design {design_id} is missing")
        n_par, n_err = r[3], r[4]
        return DesignRecord(
            id=r[0], maneuver_id=r[1], vehicle_id=r[2], p_guess=unpack_f8(r[5]), p_nominal=unpack_f8(r[6]),
            residual=unpack_f8(r[7]), residual_norm=nan_if_none(r[8]), jacobian=unpack_f8(r[9], (n_err, n_par)),
            correction=unpack_f8(r[10], (n_par, n_err)), correction_kind=r[11], singular_values=unpack_f8(r[12]),
            condition_number=nan_if_none(r[13]), rank=r[14], converged=bool(r[15]), status=r[16], message=r[17],
            duration_s=nan_if_none(r[18]), compute_s=nan_if_none(r[19]), evaluations=r[20], created_at=r[21])

    def vehicle(self, vehicle_id: int) -> VehicleRecord:
        """A stored vehicle configuration."""
        with self._guard("reading a vehicle"):
            r = self._db.execute("SELECT id, name, config FROM vehicles WHERE id = ?", (vehicle_id,)).fetchone()
        if r is None:
            raise StoreFormatError(f"{self.path}: damaged: vehicle {vehicle_id} is missing")
        return VehicleRecord(id=r[0], name=r[1], config=json.loads(r[2]))

    def plant(self, plant_id: int) -> PlantRecord:
        """A stored plant configuration."""
        with self._guard("reading a plant"):
            r = self._db.execute("SELECT id, kind, vehicle_id, config FROM plants WHERE id = ?",
                                 (plant_id,)).fetchone()
        if r is None:
            raise StoreFormatError(f"{self.path}: damaged: plant {plant_id} is missing")
        return PlantRecord(id=r[0], kind=r[1], vehicle_id=r[2], config=json.loads(r[3]))

    _ITERATION_COLUMNS = ("session_id, idx, correction, status, params, next_params, error, gamma, scale, message, "
                          "final_state, start_state, traj_rows, recorded_at, info")

    def _iteration(self, r: Sequence[Any], extra: Sequence[Any], trajectories: bool,
                   plant_state: bool, learner_state: bool = False) -> IterationRecord:
        times = states = None
        k = 0
        if trajectories:
            blob, rows, cols, codec = extra[0], extra[1], extra[2], extra[3]
            k = 4
            if blob is not None and rows:
                if codec != TRAJECTORY_CODEC:
                    raise ValueError(f"iteration {r[1]}: unknown trajectory encoding {codec!r}")
                times, states = decode_trajectory(blob, rows, cols)
        pstate = json.loads(extra[k]) if plant_state and extra[k] else None
        lstate = json.loads(extra[k + int(plant_state)]) if learner_state and extra[k + int(plant_state)] else None
        return IterationRecord(
            session_id=r[0], index=r[1], correction=r[2], status=r[3], params=unpack_f8(r[4]),
            next_params=unpack_f8(r[5]), error=unpack_f8(r[6]), gamma=r[7], scale=r[8], message=r[9],
            final_state=None if r[10] is None else unpack_f8(r[10]),
            start_state=None if r[11] is None else unpack_f8(r[11]), trajectory_rows=r[12], recorded_at=r[13],
            info=json.loads(r[14]) if r[14] else {}, times_s=times, states=states, plant_state=pstate,
            learner_state=lstate)

    def iterations(self, session_id: int, *, trajectories: bool = False, plant_state: bool = False,
                   indices: Sequence[int] | None = None) -> list[IterationRecord]:
        """The session's iterations in order (optionally only ``indices``).

        Parameters
        ----------
        trajectories : also decode the measured trajectories.
        plant_state : also load the plant states.
        """
        columns = self._ITERATION_COLUMNS
        if trajectories:
            columns += ", trajectory, traj_rows, traj_cols, traj_codec"
        if plant_state:
            columns += ", plant_state"
        sql = f"SELECT {columns} FROM iterations WHERE session_id = ?"
        args: list[Any] = [session_id]
        if indices is not None:
            wanted = sorted({int(i) for i in indices})
            if not wanted:
                return []
            sql += f" AND idx IN ({', '.join('?' * len(wanted))})"
            args += wanted
        sql += " ORDER BY idx"
        with self._guard(f"reading iterations of session {session_id}"):
            rows = self._db.execute(sql, args).fetchall()
        n = 15
        try:
            return [self._iteration(r[:n], r[n:], trajectories, plant_state) for r in rows]
        except (ValueError, zlib.error) as exc:
            raise StoreFormatError(f"{self.path}: session {session_id}: damaged iteration data ({exc})") from None

    def last_iteration(self, session_id: int) -> IterationRecord | None:
        """The session's last stored iteration, with the plant's and the learner's states (None if it has none)."""
        with self._guard(f"reading iterations of session {session_id}"):
            r = self._db.execute(f"SELECT {self._ITERATION_COLUMNS}, plant_state, learner_state FROM iterations "
                                 f"WHERE session_id = ? ORDER BY idx DESC LIMIT 1", (session_id,)).fetchone()
        return None if r is None else self._iteration(r[:15], r[15:], False, True, True)

    def study_sessions(self, study_id: int) -> list[SessionSummary]:
        """Summaries of the sessions that learned for this study."""
        return [s for s in self.list_sessions() if s.study_id == study_id]
