"""The store's study tables: a row per study, a row per job (done or failed), written as each job ends."""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Mapping, Sequence
from typing import Any

from aerobat.config import short_repr
from aerobat.errors import ConfigError, SessionNotFound, StoreFormatError
from aerobat.store import checksums
from aerobat.store.codec import canonical_json, from_columns, json_ready, utc_now
from aerobat.store.database import Database, next_id
from aerobat.store.records import JobStatus, StudyJobRecord, StudyKind, StudyRecord

__all__ = ["StudyTables"]


class StudyTables(Database):
    """Studies and their jobs (the :class:`~aerobat.store.Store` has these methods)."""

    def create_study(self, kind: StudyKind | str, spec: Mapping[str, Any], *, command: Sequence[str] = (),
                     out_dir: str | None = None) -> int:
        """Record a new study of a :class:`~aerobat.store.records.StudyKind` (or its name); its id."""
        try:
            study_kind = StudyKind(kind)
        except ValueError:
            raise ConfigError(f"study kind {short_repr(kind)}: allowed {', '.join(StudyKind)}") from None
        spec_json = canonical_json(json_ready(dict(spec)))

        def write(conn: sqlite3.Connection) -> int:
            study_id = next_id(conn, "studies")
            checksums.insert(conn, "studies", {"id": study_id, "kind": study_kind.value, "spec": spec_json,
                                               "created_at": utc_now(), "command": json.dumps(list(command)),
                                               "out_dir": out_dir})
            return study_id

        return int(self._write("creating a study", write))

    def set_study_out_dir(self, study_id: int, out_dir: str) -> None:
        """Where the study's report and figures go."""
        self._write(f"updating study {study_id}", lambda conn: checksums.update(
            conn, self.path, "studies", {"id": study_id}, {"out_dir": out_dir}))

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

    def _json(self, text: Any, what: str) -> Any:
        try:
            return json.loads(text)
        except (TypeError, ValueError) as exc:
            raise StoreFormatError(f"{self.path}: {what}: damaged JSON ({exc}); restore the store from a "
                                   f"backup") from None

    def _jobs(self, study_id: int | None) -> list[dict[str, Any]]:
        """Job rows (of one study, or all), verified."""
        sql = f"SELECT {checksums.select_list('study_jobs')} FROM study_jobs"
        with self._guard("reading study jobs"):
            rows = (self._db.execute(sql + " ORDER BY study_id, key").fetchall() if study_id is None else
                    self._db.execute(sql + " WHERE study_id = ? ORDER BY key", (study_id,)).fetchall())
        jobs = [checksums.verify(self.path, "study_jobs", r) for r in rows]
        for job in jobs:
            try:
                job["status"] = JobStatus(job["status"])
            except ValueError:
                raise StoreFormatError(f"{self.path}: study {job['study_id']} job {job['key']}: unknown status "
                                       f"{short_repr(job['status'])} (written by another aerobat?)") from None
        return jobs

    def _job_counts(self, study_id: int | None) -> dict[tuple[int, str], int]:
        """``(study, status) → jobs`` counted by the database (of one study, or all; no job row is read)."""
        sql = "SELECT study_id, status, count(*) FROM study_jobs"
        with self._guard("reading study jobs"):
            rows = (self._db.execute(sql + " GROUP BY 1, 2").fetchall() if study_id is None else
                    self._db.execute(sql + " WHERE study_id = ? GROUP BY 1, 2", (study_id,)).fetchall())
        return {(int(sid), str(status)): int(n) for sid, status, n in rows}

    def _study(self, r: dict[str, Any], counts: Mapping[tuple[int, str], int]) -> StudyRecord:
        what = f"study {r['id']}"
        return from_columns(  # type: ignore[no-any-return]
            StudyRecord, r, kind=StudyKind.stored(r["kind"]), spec=self._json(r["spec"], what),
            command=tuple(self._json(r["command"] or "[]", what)),
            jobs_done=counts.get((r["id"], JobStatus.DONE.value), 0),
            jobs_failed=counts.get((r["id"], JobStatus.FAILED.value), 0))

    def list_studies(self) -> list[StudyRecord]:
        """Every study, oldest first, with its job counts (every study row verified against its checksum)."""
        with self._guard("reading studies"):
            rows = self._db.execute(f"SELECT {checksums.select_list('studies')} FROM studies ORDER BY id").fetchall()
        studies = [checksums.verify(self.path, "studies", r) for r in rows]
        counts = self._job_counts(None)
        return [self._study(r, counts) for r in studies]

    def study(self, study_id: int) -> StudyRecord:
        """One study with its job counts."""
        study_id = self.resolve_study(study_id)
        with self._guard("reading studies"):
            r = checksums.fetch(self._db, self.path, "studies", {"id": study_id})
        if r is None:
            raise SessionNotFound(f"{self.path}: no study {study_id} (see `aerobat studies`)")
        return self._study(r, self._job_counts(study_id))

    def finished_study_jobs(self, study_id: int) -> set[str]:
        """Keys of the jobs that are done (failed jobs are not: they run again on resume)."""
        return {j["key"] for j in self._jobs(study_id) if j["status"] is JobStatus.DONE}

    def record_study_job(self, study_id: int, key: str, spec: Mapping[str, Any], result: Mapping[str, Any], *,
                         status: JobStatus = JobStatus.DONE, error: str | None = None,
                         session_id: int | None = None) -> None:
        """Store one finished (or failed) job, committed before the next result is taken.

        A job recorded again (a failed job run on resume) replaces its row; ``attempts`` counts the runs.
        """
        try:
            job_status = JobStatus(status)
        except ValueError:
            raise ConfigError(f"study job status {short_repr(status)}: allowed 'done' or 'failed'") from None
        self._write("recording a study job", lambda conn: self._insert_study_job(
            conn, study_id, key, spec, result, job_status, error, session_id))

    @staticmethod
    def _insert_study_job(conn: sqlite3.Connection, study_id: int, key: str, spec: Mapping[str, Any],
                          result: Mapping[str, Any], status: JobStatus, error: str | None,
                          session_id: int | None) -> None:
        spec_json = canonical_json(json_ready(dict(spec)))
        result_json = json.dumps(json_ready(dict(result)), allow_nan=True)
        row = conn.execute("SELECT attempts FROM study_jobs WHERE study_id = ? AND key = ?",
                           (study_id, key)).fetchone()
        attempts = 1 + (int(row[0]) if row else 0)
        checksums.insert(conn, "study_jobs", {
            "study_id": study_id, "key": str(key), "spec": spec_json, "result": result_json,
            "recorded_at": utc_now(), "status": status.value, "error": error, "attempts": attempts,
            "session_id": session_id}, verb="INSERT OR REPLACE")

    def study_jobs(self, study_id: int) -> list[StudyJobRecord]:
        """Every recorded job of the study (done and failed), by key."""
        return [from_columns(StudyJobRecord, r, spec=self._json(r["spec"], f"study {study_id} job {r['key']}"),
                             result=self._json(r["result"], f"study {study_id} job {r['key']}"))
                for r in self._jobs(study_id)]

    def study_results(self, study_id: int) -> dict[str, dict[str, Any]]:
        """Results of the jobs that are done, by key."""
        return {job.key: job.result for job in self.study_jobs(study_id) if job.status is JobStatus.DONE}
