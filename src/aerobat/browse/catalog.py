"""What the browser shows of a store, read in a few queries: one row per session and per study.

Everything here only reads (the store is opened read-only by :mod:`aerobat.browse.site`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from aerobat.store import Store
from aerobat.store.owners import owner_alive

__all__ = ["SessionRow", "StudyRow", "session_rows", "session_tags_and_notes", "study_rows"]


@dataclass(frozen=True)
class SessionRow:
    """One row of the sessions table (the columns it filters and sorts by)."""

    id: int
    maneuver: str
    maneuver_kind: str
    plant: str
    vehicle: str
    feedback: str
    rule: str
    status: str
    study_id: int | None
    started_at: str
    updated_at: str
    n_records: int
    n_measured: int
    target_iterations: int
    last_position_error_m: float | None
    seed: int | None
    tags: tuple[str, ...] = ()

    @property
    def date(self) -> str:
        """The start day, ``YYYY-MM-DD`` (UTC)."""
        return self.started_at[:10]


@dataclass(frozen=True)
class StudyRow:
    """One row of the studies table."""

    id: int
    kind: str
    created_at: str
    jobs_done: int
    jobs_failed: int
    n_sessions: int
    out_dir: str | None


_SESSIONS_SQL = """
SELECT s.id, m.name, m.kind, p.kind, v.name, json_extract(p.config, '$.feedback.scheme'),
       json_extract(s.rule, '$.name'), s.state, s.owner, s.study_id, s.started_at, s.updated_at, s.n_records,
       s.n_measured, s.target_iterations, s.last_position_error_m, s.seed
FROM sessions s JOIN maneuvers m ON m.id = s.maneuver_id JOIN plants p ON p.id = s.plant_id
     JOIN vehicles v ON v.id = p.vehicle_id
"""


def _query(store: Store, sql: str, args: tuple[Any, ...] = ()) -> list[Any]:
    with store._guard("reading the store for the browser"):
        return store._db.execute(sql, args).fetchall()


def session_tags_and_notes(store: Store, session_id: int | None = None) -> dict[int, dict[str, Any]]:
    """Tags and notes per session, if this store's version has them (``aerobat tag``, ``aerobat note``).

    TAGS AND NOTES: written by the CLI only. This reads whichever of the store's methods exist
    (``session_tags`` / ``session_notes``); a store without them gives ``{}`` and the pages say so.
    """
    found: dict[int, dict[str, Any]] = {}
    for key, name in (("tags", "session_tags"), ("notes", "session_notes")):
        method = getattr(store, name, None)
        if method is None:
            continue
        try:
            values = method(session_id) if session_id is not None else method()
        except TypeError:
            continue
        if session_id is not None:
            values = {session_id: values}
        if isinstance(values, dict):
            for sid, value in values.items():
                found.setdefault(int(sid), {})[key] = value
    return found


def session_rows(store: Store, *, session_id: int | None = None) -> list[SessionRow]:
    """Every session (or one), oldest first, with the names the table filters by."""
    sql = _SESSIONS_SQL + (" WHERE s.id = ?" if session_id is not None else "") + " ORDER BY s.id"
    rows = _query(store, sql, () if session_id is None else (session_id,))
    extras = session_tags_and_notes(store)
    alive: dict[str | None, bool | None] = {}
    out = []
    for r in rows:
        state = r[7]
        if state == "running":
            if r[8] not in alive:
                alive[r[8]] = owner_alive(r[8])
            if alive[r[8]] is False:
                state = "killed"
        tags = extras.get(int(r[0]), {}).get("tags", ())
        out.append(SessionRow(
            id=r[0], maneuver=r[1], maneuver_kind=r[2] or "", plant=r[3], vehicle=r[4] or "", feedback=r[5] or "none",
            rule=r[6] or "", status=state, study_id=r[9], started_at=r[10], updated_at=r[11], n_records=r[12],
            n_measured=r[13], target_iterations=r[14], last_position_error_m=r[15], seed=r[16],
            tags=tuple(str(t) for t in tags) if isinstance(tags, list | tuple) else ()))
    return out


def study_rows(store: Store) -> list[StudyRow]:
    """Every study with its job counts and how many sessions learned for it."""
    counts = dict(_query(store, "SELECT study_id, count(*) FROM sessions WHERE study_id IS NOT NULL GROUP BY study_id"))
    return [StudyRow(id=s.id, kind=s.kind, created_at=s.created_at, jobs_done=s.jobs_done, jobs_failed=s.jobs_failed,
                     n_sessions=int(counts.get(s.id, 0)), out_dir=s.out_dir) for s in store.list_studies()]


def json_text(value: Any) -> str:
    """Indented JSON for a page (non-JSON values as text)."""
    return json.dumps(value, indent=1, default=str)
