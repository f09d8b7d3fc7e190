"""Reading the store: sessions, their parts and their iterations, every row checked against its checksum."""

from __future__ import annotations

import json
import numbers
import zlib
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from aerobat.config import check_int, check_type, short_repr
from aerobat.core.maneuver import ErrorKind
from aerobat.core.outcomes import IterationStatus, SessionStatus
from aerobat.core.plant import Signals
from aerobat.errors import ConfigError, SessionNotFound, StoreFormatError
from aerobat.store import checksums
from aerobat.store.codec import TRAJECTORY_CODEC, decode_trajectory, from_columns, unpack_f8
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

__all__ = ["Reading"]


class Reading(StudyTables):
    """The store's reading methods (the :class:`~aerobat.store.Store` has these)."""

    _position_masks: dict[int, np.ndarray]

    # ---------------------------------------------------------- helpers
    def _loads(self, text: Any, what: str) -> Any:
        """JSON stored in the store; :class:`StoreFormatError` naming the record if it is not JSON."""
        try:
            return json.loads(text)
        except (TypeError, ValueError) as exc:
            raise StoreFormatError(f"{self.path}: {what}: damaged JSON ({exc}); restore the store from a "
                                   f"backup") from None

    def _enum(self, cls: type[Any], value: Any, what: str, noun: str = "status") -> Any:
        """A stored status (or other ``noun``) as its enum; :class:`StoreFormatError` naming the record if it is
        none of them."""
        try:
            return cls(value)
        except ValueError:
            raise StoreFormatError(f"{self.path}: {what}: unknown {noun} {short_repr(value)} (written by another "
                                   f"aerobat?)") from None

    def _state(self, row: Mapping[str, Any]) -> SessionStatus:
        return self._enum(SessionStatus, row["state"], f"session {row['id']}")  # type: ignore[no-any-return]

    def _fetch(self, table: str, key: Mapping[str, Any], action: str) -> dict[str, Any] | None:
        with self._guard(action):
            return checksums.fetch(self._db, self.path, table, key)

    def _part(self, table: str, row_id: int, what: str) -> dict[str, Any]:
        row = self._fetch(table, {"id": row_id}, f"reading a {what}")
        if row is None:
            raise StoreFormatError(f"{self.path}: damaged: {what} {row_id} is missing")
        return row

    def _session_id(self, session_id: Any) -> int:
        """A session id that exists; :class:`SessionNotFound` for anything else (a bool, a string, 99999)."""
        if isinstance(session_id, bool) or not isinstance(session_id, numbers.Integral):
            raise SessionNotFound(f"{self.path}: session {short_repr(session_id)}: expected a session id (an "
                                  f"integer >= 1); `Store.resolve_session` also takes 'last'")
        return self.resolve_session(int(session_id))

    def _position_mask(self, session_id: int) -> np.ndarray:
        if session_id not in self._position_masks:
            with self._guard(f"reading session {session_id}"):
                row = self._db.execute("SELECT maneuver_id FROM sessions WHERE id = ?", (session_id,)).fetchone()
            kinds = self.maneuver(row[0]).error_kinds if row else ()
            self._position_masks[session_id] = np.array([k is ErrorKind.POSITION for k in kinds], dtype=bool)
        return self._position_masks[session_id]

    # ---------------------------------------------------------- sessions
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

    def _names(self, row: Mapping[str, Any], cache: dict[tuple[str, int], Any]) -> dict[str, Any]:
        """The maneuver's name, the plant's kind, vehicles and feedback of a session row (verified rows)."""
        def part(table: str, row_id: int) -> dict[str, Any]:
            if (table, row_id) not in cache:
                cache[table, row_id] = self._part(table, row_id, table[:-1])
            return cache[table, row_id]

        plant = part("plants", row["plant_id"])
        design = part("designs", row["design_id"])
        config = self._loads(plant["config"], f"plant {plant['id']}")
        feedback = config.get("feedback") if isinstance(config, dict) else None
        scheme = feedback.get("scheme", "none") if isinstance(feedback, dict) else "none"
        return {"maneuver_name": part("maneuvers", row["maneuver_id"])["name"], "plant_kind": plant["kind"],
                "vehicle": part("vehicles", design["vehicle_id"])["name"],
                "plant_vehicle": part("vehicles", plant["vehicle_id"])["name"], "feedback": str(scheme),
                "tags": tuple(self._loads(row["tags"], f"session {row['id']} tags") if row["tags"] else ())}

    def list_sessions(self, *, limit: int | None = None, newest_first: bool = False) -> list[SessionSummary]:
        """Every session's summary row (no iteration is read), each verified against its checksum."""
        check_type("newest_first", newest_first, (bool, np.bool_), "True or False")
        order = "DESC" if newest_first else "ASC"
        sql = f"SELECT {checksums.select_list('sessions')} FROM sessions ORDER BY id {order}"
        args: tuple[Any, ...] = ()
        if limit is not None:
            sql += " LIMIT ?"
            args = (check_int("limit", limit, low=0, high=2**63 - 1),)
        with self._guard("listing sessions"):
            rows = self._db.execute(sql, args).fetchall()
        return self._summaries(rows)

    def _summaries(self, selected: Sequence[Sequence[Any]]) -> list[SessionSummary]:
        """Session rows (as ``checksums.select_list('sessions')`` selects them) verified, as summaries."""
        rows = [checksums.verify(self.path, "sessions", r) for r in selected]
        alive: dict[str | None, bool | None] = {}
        cache: dict[tuple[str, int], Any] = {}
        out = []
        for r in rows:
            state = self._state(r)
            display = state.value
            if state is SessionStatus.RUNNING:
                if r["owner"] not in alive:
                    alive[r["owner"]] = owner_alive(r["owner"])
                if alive[r["owner"]] is False:
                    display = "killed"
            names = self._names(r, cache)  # fills the cache with the session's parts
            out.append(SessionSummary(
                id=r["id"], seed=r["seed"], n_records=r["n_records"], n_measured=r["n_measured"],
                target_iterations=r["target_iterations"], last_position_error_m=r["last_position_error_m"],
                state=state, display_state=display, started_at=r["started_at"], updated_at=r["updated_at"],
                study_id=r["study_id"], **names, maneuver_kind=str(cache["maneuvers", r["maneuver_id"]]["kind"] or ""),
                rule=self._rule_name(r)))
        return out

    def _rule_name(self, row: Mapping[str, Any]) -> str:
        rule = self._loads(row["rule"], f"session {row['id']} rule")
        return str(rule.get("name", "")) if isinstance(rule, dict) else ""

    def session(self, session_id: int) -> SessionRecord:
        """The session and its summary."""
        session_id = self._session_id(session_id)
        r = self._fetch("sessions", {"id": session_id}, f"reading session {session_id}")
        if r is None:
            raise SessionNotFound(f"{self.path}: no session {session_id} (see `aerobat sessions --db {self.path}`)")
        state = self._state(r)
        display = "killed" if state is SessionStatus.RUNNING and owner_alive(r["owner"]) is False else state.value
        names = self._names(r, {})
        notes = self._loads(r["notes"], f"session {session_id} notes") if r["notes"] else []
        return SessionRecord(
            id=r["id"], maneuver_id=r["maneuver_id"], design_id=r["design_id"], plant_id=r["plant_id"],
            seed=r["seed"], rule=self._loads(r["rule"], f"session {session_id} rule"),
            target_iterations=r["target_iterations"], start_params=unpack_f8(r["start_params"]),
            warm_start_from=r["warm_start_from"], state=state, display_state=display, message=r["message"],
            started_at=r["started_at"], updated_at=r["updated_at"], ended_at=r["ended_at"], host=r["host"],
            pid=r["pid"], owner=r["owner"],
            command=tuple(self._loads(r["command"] or "[]", f"session {session_id} command")),
            aerobat_version=r["aerobat_version"], n_records=r["n_records"], n_measured=r["n_measured"],
            last_index=r["last_index"], last_correction=r["last_correction"],
            last_error=None if r["last_error"] is None else unpack_f8(r["last_error"]),
            last_position_error_m=r["last_position_error_m"],
            current_params=unpack_f8(r["current_params"] if r["current_params"] is not None else r["start_params"]),
            study_id=r["study_id"], notes=tuple((str(n.get("at", "")), str(n.get("text", ""))) for n in notes
                                                if isinstance(n, dict)), **names)

    # ---------------------------------------------------------- a session's parts
    def maneuver(self, maneuver_id: int) -> ManeuverRecord:
        """A stored maneuver specification."""
        r = self._part("maneuvers", maneuver_id, "maneuver")
        what = f"maneuver {maneuver_id}"
        names = self._loads(r["error_names"], what)
        return ManeuverRecord(
            id=r["id"], kind=r["kind"], name=r["name"], spec=self._loads(r["spec"], what),
            parameter_names=tuple(self._loads(r["parameter_names"], what)),
            parameter_units=tuple(self._loads(r["parameter_units"], what)), error_names=tuple(names),
            error_units=tuple(self._loads(r["error_units"], what)),
            error_scales=tuple(float(v) for v in self._loads(r["error_scales"], what)),
            error_kinds=tuple(self._enum(ErrorKind, kind, what, "error kind") for kind in (
                self._loads(r["error_kinds"], what) if r["error_kinds"] else [ErrorKind.OTHER] * len(names))))

    def design(self, design_id: int) -> DesignRecord:
        """A stored design, arrays bit for bit as computed."""
        r = self._part("designs", design_id, "design")
        n_par, n_err = r["n_par"], r["n_err"]
        try:
            jacobian, correction = unpack_f8(r["jacobian"], (n_err, n_par)), unpack_f8(r["correction"], (n_par, n_err))
        except ValueError as exc:
            raise StoreFormatError(f"{self.path}: design {design_id}: damaged arrays ({exc})") from None
        try:
            return from_columns(DesignRecord, r, jacobian=jacobian, correction=correction)  # type: ignore[no-any-return]
        except ValueError as exc:
            raise StoreFormatError(f"{self.path}: design {design_id}: damaged ({exc})") from None

    def vehicle(self, vehicle_id: int) -> VehicleRecord:
        """A stored vehicle configuration."""
        r = self._part("vehicles", vehicle_id, "vehicle")
        return VehicleRecord(id=r["id"], name=r["name"], config=self._loads(r["config"], f"vehicle {vehicle_id}"))

    def plant(self, plant_id: int) -> PlantRecord:
        """A stored plant configuration."""
        r = self._part("plants", plant_id, "plant")
        return PlantRecord(id=r["id"], kind=r["kind"], vehicle_id=r["vehicle_id"],
                           config=self._loads(r["config"], f"plant {plant_id}"))

    # ---------------------------------------------------------- iterations
    def _signals(self, r: Mapping[str, Any], blob: bytes | None, where: str) -> Signals | None:
        """The plant's signals of a verified row (schema 7), verified against their checksum."""
        checksums.verify_blob(self.path, where, blob, r["signal_checksum"], what="plant's signals")
        if blob is None or not r["signal_rows"]:
            return None
        names = self._loads(r["signal_names"], where)
        if r["signal_codec"] != TRAJECTORY_CODEC or not isinstance(names, list):
            raise StoreFormatError(f"{self.path}: {where}: unknown signals encoding {r['signal_codec']!r}")
        try:
            times, values = decode_trajectory(blob, r["signal_rows"], 1 + len(names))
            return Signals(times, tuple(names), values)
        except (ValueError, zlib.error) as exc:
            raise StoreFormatError(f"{self.path}: {where}: damaged signals ({exc})") from None

    def _iteration(self, r: Mapping[str, Any], blobs: tuple[bytes | None, bytes | None] | None, plant_state: bool,
                   learner_state: bool) -> IterationRecord:
        """A verified row as a record; ``blobs``: its trajectory and signals, to decode (None: not read)."""
        where = f"iteration {r['idx']} of session {r['session_id']}"
        times = states = signals = None
        if blobs is not None:
            blob = blobs[0]
            checksums.verify_blob(self.path, where, blob, r["traj_checksum"])
            if blob is not None and r["traj_rows"]:
                if r["traj_codec"] != TRAJECTORY_CODEC:
                    raise StoreFormatError(f"{self.path}: {where}: unknown trajectory encoding {r['traj_codec']!r}")
                try:
                    times, states = decode_trajectory(blob, r["traj_rows"], r["traj_cols"])
                except (ValueError, zlib.error) as exc:
                    raise StoreFormatError(f"{self.path}: {where}: damaged trajectory ({exc})") from None
            signals = self._signals(r, blobs[1], where)
        status = self._enum(IterationStatus, r["status"], where)
        info = self._loads(r["info"], where) if r["info"] else {}
        plant = self._loads(r["plant_state"], where) if plant_state and r["plant_state"] else None
        learner = self._loads(r["learner_state"], where) if learner_state and r["learner_state"] else None
        try:  # the notes column (JSON) is decoded by the codec, from IterationRecord.notes' type
            return from_columns(  # type: ignore[no-any-return]
                IterationRecord, r, index=r["idx"], status=status, trajectory_rows=r["traj_rows"], info=info,
                times_s=times, states=states, plant_state=plant, learner_state=learner, signals=signals)
        except (ValueError, TypeError, KeyError) as exc:
            raise StoreFormatError(f"{self.path}: {where}: damaged notes ({type(exc).__name__}: {exc}); restore "
                                   f"the store from a backup") from None

    def iterations(self, session_id: int, *, trajectories: bool = False, plant_state: bool = False,
                   indices: Sequence[int] | None = None) -> list[IterationRecord]:
        """The session's iterations in order (optionally only ``indices``), each verified against its checksum.

        Parameters
        ----------
        trajectories : also decode the measured trajectories (verified against theirs).
        plant_state : also load the plant states.

        Raises
        ------
        SessionNotFound
            No such session (or ``session_id`` is not an id).
        ConfigError
            ``indices`` holds something that is not an iteration number.
        StoreFormatError
            A record fails its checksum, or the session's iterations are not the 1 … N its summary counts.
        """
        session_id = self._session_id(session_id)
        wanted: list[int] | None = None
        if indices is not None:
            if isinstance(indices, str | bytes) or not isinstance(indices, Sequence | set | frozenset | np.ndarray):
                raise ConfigError(f"indices: expected a list of iteration numbers, got {short_repr(indices)}")
            wanted = sorted({check_int("indices", i, low=1, high=2**63 - 1) for i in indices})
            if not wanted:
                return []
        sql = f"SELECT {checksums.select_list('iterations')}{', trajectory, signals' if trajectories else ''} " \
              f"FROM iterations " \
              f"WHERE session_id = ?"
        args: list[Any] = [session_id]
        if wanted is not None:
            sql += f" AND idx IN ({', '.join('?' * len(wanted))})"
            args += wanted
        n = len(checksums.COVERED["iterations"]) + 1
        with self._guard(f"reading iterations of session {session_id}"):
            # one read transaction: both answers describe the same moment (read apart, a writer's commit
            # in between made the summary count one more iteration than the rows: "damaged", falsely)
            own = not self._db.in_transaction
            if own:
                self._db.execute("BEGIN")
            try:
                rows = self._db.execute(sql + " ORDER BY idx", args).fetchall()
                count = None if wanted is not None else self._db.execute(
                    "SELECT n_records FROM sessions WHERE id = ?", (session_id,)).fetchone()[0]
            finally:
                if own:
                    self._db.execute("COMMIT")
        checked = [(checksums.verify(self.path, "iterations", r[:n]), (r[n], r[n + 1]) if trajectories else None)
                   for r in rows]
        found = [r["idx"] for r, _ in checked]
        if any(r["session_id"] != session_id for r, _ in checked) or (
                count is not None and found != list(range(1, count + 1))):
            raise StoreFormatError(f"{self.path}: session {session_id}: its summary counts {count} iterations but "
                                   f"the store holds {len(found)} (damaged)")
        return [self._iteration(r, blobs, plant_state, False) for r, blobs in checked]

    def last_iteration(self, session_id: int) -> IterationRecord | None:
        """The session's last stored iteration, with the plant's and the learner's states (None if it has none)."""
        session_id = self._session_id(session_id)
        with self._guard(f"reading iterations of session {session_id}"):
            r = self._db.execute(f"SELECT {checksums.select_list('iterations')} FROM iterations WHERE session_id = ? "
                                 f"ORDER BY idx DESC LIMIT 1", (session_id,)).fetchone()
        return None if r is None else self._iteration(checksums.verify(self.path, "iterations", r), None,
                                                      True, True)

    def verify_session(self, session_id: int) -> None:
        """Check every record a session consists of against its checksum, trajectories included.

        Its row, its design, maneuver, plant and vehicles, and every iteration. ``learn --resume``
        and ``export`` call it first, so neither goes on from a record that changed on disk.

        Raises
        ------
        StoreFormatError
            A record fails its checksum or is missing.
        """
        rec = self.session(session_id)
        self.design(rec.design_id)
        self.vehicle(self.plant(rec.plant_id).vehicle_id)
        self.iterations(rec.id, trajectories=True, plant_state=True)

    def session_summaries(self, session_ids: Sequence[int]) -> list[SessionSummary]:
        """The summaries of these sessions, in the order given (:class:`SessionNotFound` for one not stored)."""
        ids = [self._session_id(sid) for sid in session_ids]
        found: dict[int, SessionSummary] = {}
        with self._guard("listing sessions"):
            for start in range(0, len(ids), 500):
                chunk = ids[start:start + 500]
                rows = self._db.execute(f"SELECT {checksums.select_list('sessions')} FROM sessions WHERE id IN "
                                        f"({', '.join('?' * len(chunk))})", chunk).fetchall()
                found.update((s.id, s) for s in self._summaries(rows))
        return [found[sid] for sid in ids]

    def sessions_per_study(self) -> dict[int, int]:
        """``study → sessions it learned in``, counted by the database."""
        with self._guard("counting sessions"):
            return {int(sid): int(n) for sid, n in self._db.execute(
                "SELECT study_id, count(*) FROM sessions WHERE study_id IS NOT NULL GROUP BY study_id")}

    def study_sessions(self, study_id: int) -> list[SessionSummary]:
        """Summaries of the sessions that learned for this study, oldest first."""
        with self._guard("listing sessions"):
            rows = self._db.execute(f"SELECT {checksums.select_list('sessions')} FROM sessions WHERE study_id = ? "
                                    f"ORDER BY id", (study_id,)).fetchall()
        return self._summaries(rows)
