"""The store's study tables: a row per study, a row per job (done or failed), written as each job ends."""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Mapping, Sequence
from typing import Any

from aerobat.config import short_repr
from aerobat.errors import ConfigError, SessionNotFound
from aerobat.store.codec import canonical_json, json_ready, utc_now
from aerobat.store.database import Database
from aerobat.store.records import StudyJobRecord, StudyRecord

__all__ = ["StudyTables"]


class StudyTables(Database):
    """Studies and their jobs (the :class:`~aerobat.store.Store` has these methods)."""

    def create_study(self, kind: str, spec: Mapping[str, Any], *, command: Sequence[str] = (),
                     out_dir: str | None = None) -> int:
        """Record a new study; its id."""
        spec_json = canonical_json(json_ready(dict(spec)))

        def write(conn: sqlite3.Connection) -> int:
            cursor = conn.execute(
                "INSERT INTO studies (kind, spec, created_at, command, out_dir) VALUES (?, ?, ?, ?, ?)",
                (str(kind), spec_json, utc_now(), json.dumps(list(command)), out_dir))
            return int(cursor.lastrowid or 0)

        return int(self._write("creating a study", write))

    def set_study_out_dir(self, study_id: int, out_dir: str) -> None:
        """Where the study's report and figures go."""
        self._write(f"updating study {study_id}", lambda conn: conn.execute(
            "UPDATE studies SET out_dir = ? WHERE id = ?", (out_dir, study_id)))

    def resolve_study(self, ref: int | str) -> int:
        """A study id from ``ref`` (an id or ``last``); :class:`SessionNotFound` if there is none."""
        with self._guard("reading studies"):
            if str(ref).strip().lower() == "last":
                row = self._db.execute("SELECT max(id) FROM studies").fetchone()
                if row is None or row[0] is None:
                    raise SessionNotFound(f"{self.path}: holds no studies yet")
                return int(row[0])
            try:
                if isinstance(ref, bool) or (isinstance(ref, float) and int(ref) != ref):
                    raise TypeError
                study_id = int(ref)
            except (TypeError, ValueError, OverflowError):
                raise SessionNotFound(f"{self.path}: study {short_repr(ref)}: expected a study id or 'last'") from None
            if not 1 <= study_id < 2**63 or self._db.execute(
                    "SELECT 1 FROM studies WHERE id = ?", (study_id,)).fetchone() is None:
                raise SessionNotFound(f"{self.path}: no study {study_id} (see `aerobat studies`)")
            return study_id

    _STUDY_COLUMNS = ("s.id, s.kind, s.spec, s.created_at, s.command, s.out_dir, "
                      "(SELECT count(*) FROM study_jobs j WHERE j.study_id = s.id AND j.status = 'done'), "
                      "(SELECT count(*) FROM study_jobs j WHERE j.study_id = s.id AND j.status = 'failed')")

    @staticmethod
    def _study(r: Sequence[Any]) -> StudyRecord:
        return StudyRecord(id=int(r[0]), kind=str(r[1]), spec=json.loads(r[2]), created_at=str(r[3]),
                           command=tuple(json.loads(r[4] or "[]")), out_dir=r[5], jobs_done=int(r[6]),
                           jobs_failed=int(r[7]))

    def list_studies(self) -> list[StudyRecord]:
        """Every study, oldest first, with its job counts."""
        with self._guard("reading studies"):
            rows = self._db.execute(f"SELECT {self._STUDY_COLUMNS} FROM studies s ORDER BY s.id").fetchall()
        return [self._study(r) for r in rows]

    def study(self, study_id: int) -> StudyRecord:
        """One study with its job counts."""
        with self._guard("reading studies"):
            r = self._db.execute(f"SELECT {self._STUDY_COLUMNS} FROM studies s WHERE s.id = ?",
                                 (study_id,)).fetchone()
        if r is None:
            raise SessionNotFound(f"{self.path}: no study {study_id} (see `aerobat studies`)")
        return self._study(r)

    def finished_study_jobs(self, study_id: int) -> set[str]:
        """Keys of the jobs that are done (failed jobs are not: they run again on resume)."""
        with self._guard("reading study jobs"):
            return {r[0] for r in self._db.execute(
                "SELECT key FROM study_jobs WHERE study_id = ? AND status = 'done'", (study_id,))}

    def record_study_job(self, study_id: int, key: str, spec: Mapping[str, Any], result: Mapping[str, Any], *,
                         status: str = "done", error: str | None = None, session_id: int | None = None) -> None:
        """Store one finished (or failed) job, committed before the next result is taken.

        A job recorded again (a failed job run on resume) replaces its row; ``attempts`` counts the runs.
        """
        if status not in ("done", "failed"):
            raise ConfigError(f"study job status {status!r}: allowed 'done' or 'failed'")
        self._write("recording a study job", lambda conn: self._insert_study_job(
            conn, study_id, key, spec, result, status, error, session_id))

    @staticmethod
    def _insert_study_job(conn: sqlite3.Connection, study_id: int, key: str, spec: Mapping[str, Any],
                          result: Mapping[str, Any], status: str, error: str | None, session_id: int | None) -> None:
        spec_json = canonical_json(json_ready(dict(spec)))
        result_json = json.dumps(json_ready(dict(result)), allow_nan=True)
        row = conn.execute("SELECT attempts FROM study_jobs WHERE study_id = ? AND key = ?",
                           (study_id, key)).fetchone()
        attempts = 1 + (int(row[0]) if row else 0)
        conn.execute("INSERT OR REPLACE INTO study_jobs (study_id, key, spec, result, recorded_at, status, error, "
                     "attempts, session_id) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                     (study_id, key, spec_json, result_json, utc_now(), status, error, attempts, session_id))

    def study_jobs(self, study_id: int) -> list[StudyJobRecord]:
        """Every recorded job of the study (done and failed), by key."""
        with self._guard("reading study jobs"):
            rows = self._db.execute(
                "SELECT study_id, key, status, spec, result, error, attempts, session_id, recorded_at FROM study_jobs "
                "WHERE study_id = ? ORDER BY key", (study_id,)).fetchall()
        return [StudyJobRecord(study_id=r[0], key=r[1], status=r[2], spec=json.loads(r[3]), result=json.loads(r[4]),
                               error=r[5], attempts=int(r[6]), session_id=r[7], recorded_at=r[8]) for r in rows]

    def study_results(self, study_id: int) -> dict[str, dict[str, Any]]:
        """Results of the jobs that are done, by key."""
        return {job.key: job.result for job in self.study_jobs(study_id) if job.status == "done"}
