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
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from aerobat.config import short_repr
from aerobat.core.bounds import ITERATIONS
from aerobat.core.design import Design
from aerobat.core.maneuver import ErrorKind, Maneuver
from aerobat.core.outcomes import Iteration, IterationStatus, SessionStatus
from aerobat.errors import ConfigError, SessionInUse, SessionNotFound, StoreError
from aerobat.store import checksums
from aerobat.store.browse import SESSION_STATES, Browsing
from aerobat.store.codec import (
    TRAJECTORY_CODEC,
    canonical_json,
    columns_of,
    digest,
    encode_trajectory,
    json_ready,
    pack_f8,
    utc_now,
)
from aerobat.store.database import next_id
from aerobat.store.owners import owner_alive
from aerobat.store.records import JobStatus, SessionRecord

__all__ = ["DESIGN_ARRAYS", "DESIGN_COLUMNS", "SESSION_STATES", "Store"]

DESIGN_ARRAYS = ("p_guess", "p_nominal", "residual", "jacobian", "correction", "singular_values")
"""A design's arrays, stored exact (float64 bytes); the design's digest covers them in this order."""
DESIGN_COLUMNS = (*DESIGN_ARRAYS, "residual_norm", "correction_kind", "condition_number", "rank", "converged",
                  "status", "message", "duration_s", "compute_s", "evaluations")
"""The fields of a :class:`~aerobat.core.design.Design` the ``designs`` table keeps (its maneuver has a row)."""


def _session_state(state: SessionStatus | str) -> SessionStatus:
    """A session state as its enum (the store's tables hold its value)."""
    try:
        return SessionStatus(state)
    except ValueError:
        raise ConfigError(f"session state {short_repr(state)}: allowed {', '.join(SESSION_STATES)}") from None


def _maneuver_columns(maneuver: Maneuver) -> dict[str, Any]:
    """The ``maneuvers`` row of a maneuver: its spec, and its parameters' and errors' names, units and scales."""
    spec_json = canonical_json(json_ready(maneuver.spec()))
    return {
        "kind": str(maneuver.spec().get("kind", "")), "name": maneuver.name, "spec": spec_json,
        "parameter_names": json.dumps([p.name for p in maneuver.parameters]),
        "parameter_units": json.dumps([p.unit for p in maneuver.parameters]),
        "error_names": json.dumps([e.name for e in maneuver.errors]),
        "error_units": json.dumps([e.unit for e in maneuver.errors]),
        "error_scales": json.dumps([float(e.scale) for e in maneuver.errors]),
        "error_kinds": json.dumps([ErrorKind(e.kind).value for e in maneuver.errors]),
        "digest": digest(spec_json)}

class Store(Browsing):
    """An aerobat experiment store: sessions, their iterations and studies.

    Opening (and what is refused) is :class:`~aerobat.store.database.Database`'s.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._position_masks: dict[int, np.ndarray] = {}
        super().__init__(*args, **kwargs)

    # ---------------------------------------------------------- writing
    def _upsert(self, conn: sqlite3.Connection, table: str, columns: dict[str, Any]) -> int:
        """The id of the row with this content's digest, inserted if new (an existing one is verified)."""
        found = conn.execute(f"SELECT {checksums.select_list(table)} FROM {table} WHERE digest = ?",
                             (columns["digest"],)).fetchone()
        if found is not None:
            return int(checksums.verify(self.path, table, found)["id"])
        row_id = next_id(conn, table)
        checksums.insert(conn, table, {"id": row_id, **columns})
        return row_id

    def create_session(self, **session: Any) -> int:
        """Store a new session (with its vehicle, plant, maneuver and design, deduplicated); its id.

        Other Parameters
        ----------------
        vehicle : the plant's vehicle configuration table (``{"name", "vehicle", "controller"}``).
        plant_kind, plant_config : the plant (e.g. ``"arena"``, ``{"settings": {...}}``).
        maneuver : a :class:`~aerobat.core.maneuver.Maneuver` with ``spec()``.
        design : the :class:`~aerobat.core.design.Design` it learns from.
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
        maneuver: Maneuver,
        design: Design,
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
        maneuver_columns = _maneuver_columns(maneuver)
        start = np.asarray(start_params, dtype=np.float64)
        if start.shape != (len(maneuver.parameters),):
            raise ConfigError(f"start_params: expected {len(maneuver.parameters)} values, got shape {start.shape}")
        target_iterations = ITERATIONS.check("target_iterations", target_iterations)
        design_columns = columns_of(design, DESIGN_COLUMNS)
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
            maneuver_id = self._upsert(conn, "maneuvers", maneuver_columns)
            design_id = self._upsert(conn, "designs", {
                "maneuver_id": maneuver_id, "vehicle_id": model_id, "n_par": len(maneuver.parameters),
                "n_err": len(maneuver.errors), **design_columns, "created_at": now,
                "digest": digest(maneuver_id, model_id, design.correction_kind,
                                 *(design_columns[name] for name in DESIGN_ARRAYS))})
            session_id = next_id(conn, "sessions")
            checksums.insert(conn, "sessions", {
                "id": session_id, "maneuver_id": maneuver_id, "design_id": design_id, "plant_id": plant_id,
                "seed": seed, "rule": canonical_json(json_ready(dict(rule))), "target_iterations": target_iterations,
                "start_params": pack_f8(start), "warm_start_from": warm_start_from,
                "state": SessionStatus.RUNNING.value, "message": "started", "started_at": now, "updated_at": now,
                "ended_at": None, "host": socket.gethostname(), "pid": os.getpid(), "owner": self.owner,
                "command": json.dumps(list(command)), "aerobat_version": __version__, "n_records": 0,
                "n_measured": 0, "last_index": 0, "last_correction": 0, "last_error": None,
                "last_position_error_m": None, "current_params": pack_f8(start), "study_id": study_id,
                "tags": None, "notes": None})
            return session_id

        return write

    def append_iteration(self, session_id: int, iteration: Iteration, *,
                         plant_state: Mapping[str, Any] | None = None,
                         learner_state: Mapping[str, Any] | None = None) -> None:
        """Store one trial and update its session's summary, in one committed transaction.

        ``iteration`` is the core's record of the trial (its measured trajectory, final and start
        states and the plant's extras come from ``iteration.trial``, if it has one); its
        ``next_params`` are stored exactly as applied. ``plant_state`` and ``learner_state``
        are everything needed to continue from here: one commit holds the whole iteration, so
        a process killed at any instant resumes from the right place.

        Only the process that owns the session (created or resumed it) may append, and
        ``iteration.index`` must be the session's last index + 1: a gap or a duplicate is refused.

        Raises
        ------
        StoreWriteError
            The disk is full or the write failed; nothing of this iteration is stored.
        StoreError
            Wrong index, or the session belongs to another process.
        """
        row, ok, position = self._iteration_row(session_id, iteration, plant_state, learner_state)
        self._write(f"storing iteration {iteration.index} of session {session_id}",
                    lambda conn: self._insert_iteration(conn, row, ok, position))

    def record_study_run(self, study_id: int, key: str, spec: Mapping[str, Any], result: Mapping[str, Any], *,
                         session: Mapping[str, Any], iterations: Sequence[Iteration], state: SessionStatus,
                         message: str) -> int:
        """A study's finished learning job, all in one transaction: its session, iterations and job row.

        ``session`` holds :meth:`create_session`'s arguments. A process killed at any instant
        leaves either all of it or none of it; returns the new session's id.
        """
        insert_session = self._session_writer(**session)
        state = _session_state(state)

        def write(conn: sqlite3.Connection) -> int:
            session_id = insert_session(conn)
            for it in iterations:
                row, ok, position = self._iteration_row(session_id, it)
                self._insert_iteration(conn, row, ok, position)
            now = utc_now()
            checksums.update(conn, self.path, "sessions", {"id": session_id},
                             {"state": state.value, "message": message, "ended_at": now, "updated_at": now})
            self._insert_study_job(conn, study_id, key, spec, result, JobStatus.DONE, None, session_id)
            return session_id

        return int(self._write(f"recording study {study_id} job {key}", write))

    def _iteration_row(self, session_id: int, iteration: Iteration, plant_state: Mapping[str, Any] | None = None,
                       learner_state: Mapping[str, Any] | None = None) -> tuple[dict[str, Any], bool, float | None]:
        trial = iteration.trial
        traj: tuple[int, int, bytes | None] = (0, 0, None)
        if trial is not None and trial.times_s is not None and trial.states is not None and \
                np.asarray(trial.times_s).size:
            traj = encode_trajectory(trial.times_s, trial.states)
        signals = None if trial is None else trial.signals
        sig: tuple[int, int, bytes | None] = (0, 0, None)
        if signals is not None and signals.times_s.size:
            sig = encode_trajectory(signals.times_s, signals.values)
        err = np.asarray(iteration.error, dtype=np.float64)
        ok = iteration.status is IterationStatus.OK
        mask = self._position_mask(session_id)
        position = float(np.linalg.norm(err[mask])) if ok and mask.shape == err.shape and mask.any() else None
        row = {
            "session_id": int(session_id), "idx": int(iteration.index),
            **columns_of(iteration, ("correction", "status", "params", "next_params", "message", "notes")),
            "gamma": float(iteration.gamma), "scale": float(iteration.scale), "error": pack_f8(err),
            "final_state": None if trial is None or trial.final_state is None else pack_f8(trial.final_state),
            "start_state": None if trial is None or trial.start_state is None else pack_f8(trial.start_state),
            "traj_rows": traj[0], "traj_cols": traj[1],
            "traj_codec": TRAJECTORY_CODEC if traj[2] is not None else None,
            "info": json.dumps(json_ready(dict({} if trial is None else trial.info))), "recorded_at": utc_now(),
            "plant_state": None if plant_state is None else json.dumps(plant_state, separators=(",", ":")),
            "learner_state": None if learner_state is None else json.dumps(json_ready(dict(learner_state)),
                                                                           separators=(",", ":")),
            "traj_checksum": checksums.blob_checksum(traj[2]),
            "signal_names": None if sig[2] is None else json.dumps(list(signals.names)),  # type: ignore[union-attr]
            "signal_rows": sig[0], "signal_codec": TRAJECTORY_CODEC if sig[2] is not None else None,
            "signal_checksum": checksums.blob_checksum(sig[2]), "trajectory": traj[2], "signals": sig[2],
        }
        return row, ok, position

    def _insert_iteration(self, conn: sqlite3.Connection, row: dict[str, Any], ok: bool,
                          position: float | None) -> None:
        session_id, index, correction = row["session_id"], row["idx"], row["correction"]
        found = checksums.fetch(conn, self.path, "sessions", {"id": session_id})
        if found is None:
            raise SessionNotFound(f"{self.path}: no session {session_id}")
        if found["owner"] != self.owner:
            raise StoreError(f"{self.path}: session {session_id} is now run by another process "
                             f"({found['owner']}); this process stops writing to it")
        if found["last_index"] != index - 1:
            raise StoreError(f"{self.path}: session {session_id}: iteration {index} does not follow the "
                             f"stored iteration {found['last_index']} (no gaps, no duplicates)")
        summary: dict[str, Any] = {"n_records": found["n_records"] + 1, "last_index": index,
                                   "current_params": row["next_params"], "updated_at": row["recorded_at"]}
        if ok:
            summary.update(n_measured=found["n_measured"] + 1, last_correction=correction, last_error=row["error"],
                           last_position_error_m=position)
        checksums.update(conn, self.path, "sessions", {"id": session_id}, summary, old=found)
        checksums.insert(conn, "iterations", {k: v for k, v in row.items() if k not in ("trajectory", "signals")},
                         extra={"trajectory": row["trajectory"], "signals": row["signals"]})

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
            row = checksums.fetch(conn, self.path, "sessions", {"id": session_id})
            if row is None:
                raise SessionNotFound(f"{self.path}: no session {session_id} (see `aerobat sessions --db {self.path}`)")
            state, owner, pid, host = _session_state(row["state"]), row["owner"], row["pid"], row["host"]
            alive = owner_alive(owner) if state is SessionStatus.RUNNING and owner != self.owner else False
            if alive is None and not take_over:
                raise SessionInUse(f"{self.path}: session {session_id} was last run by process {pid} on another "
                                   f"machine ({host}), which this one cannot check; if that process is gone, "
                                   f"resume with --take-over")
            if alive:
                raise SessionInUse(f"{self.path}: session {session_id} is still being run by process {pid} on "
                                   f"{host}; stop that process before resuming")
            checksums.update(conn, self.path, "sessions", {"id": session_id}, {
                "state": SessionStatus.RUNNING.value, "owner": self.owner, "pid": os.getpid(),
                "host": socket.gethostname(), "ended_at": None, "updated_at": utc_now(),
                "message": f"resumed (was {state})"}, old=row)

        self._write(f"claiming session {session_id}", write)
        return self.session(session_id)

    def set_target(self, session_id: int, target_iterations: int) -> None:
        """Change how many measured iterations the session aims for."""
        target = ITERATIONS.check("target_iterations", target_iterations)
        self._write(f"updating session {session_id}", lambda conn: checksums.update(
            conn, self.path, "sessions", {"id": session_id}, {"target_iterations": target, "updated_at": utc_now()}))

    def finish_session(self, session_id: int, state: SessionStatus, message: str) -> None:
        """Record how the session ended (a :class:`~aerobat.core.learning.SessionStatus`)."""
        state = _session_state(state)
        now = utc_now()

        def write(conn: sqlite3.Connection) -> None:
            row = checksums.fetch(conn, self.path, "sessions", {"id": session_id})
            if row is not None and row["owner"] == self.owner:
                checksums.update(conn, self.path, "sessions", {"id": session_id}, {
                    "state": state.value, "message": message,
                    "ended_at": None if state is SessionStatus.RUNNING else now,
                    "updated_at": now}, old=row)

        self._write(f"closing session {session_id}", write)
