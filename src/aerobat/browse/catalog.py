"""What the browser shows of a store: one row per session and per study.

Everything here only reads (the store is opened read-only by :mod:`aerobat.browse.site`), and only
through the store's public readers, so every row is verified against its checksum.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from aerobat.store import Store

__all__ = ["SessionRow", "StudyRow", "session_rows", "study_rows"]


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


def _row(store: Store, session_id: int, kinds: dict[int, str]) -> SessionRow:
    rec = store.session(session_id)
    if rec.maneuver_id not in kinds:
        kinds[rec.maneuver_id] = store.maneuver(rec.maneuver_id).kind
    rule = rec.rule.get("name", "") if isinstance(rec.rule, dict) else ""
    return SessionRow(
        id=rec.id, maneuver=rec.maneuver_name, maneuver_kind=kinds[rec.maneuver_id] or "", plant=rec.plant_kind,
        vehicle=rec.plant_vehicle or rec.vehicle, feedback=rec.feedback or "none", rule=str(rule),
        status=rec.display_state, study_id=rec.study_id, started_at=rec.started_at, updated_at=rec.updated_at,
        n_records=rec.n_records, n_measured=rec.n_measured, target_iterations=rec.target_iterations,
        last_position_error_m=rec.last_position_error_m, seed=rec.seed, tags=tuple(rec.tags))


def session_rows(store: Store, *, session_id: int | None = None) -> list[SessionRow]:
    """Every session (or one), oldest first, with the names the table filters by."""
    kinds: dict[int, str] = {}
    ids = [session_id] if session_id is not None else [s.id for s in store.list_sessions()]
    return [_row(store, sid, kinds) for sid in ids]


def study_rows(store: Store) -> list[StudyRow]:
    """Every study with its job counts and how many sessions learned for it."""
    counts: dict[int, int] = {}
    for summary in store.list_sessions():
        if summary.study_id is not None:
            counts[summary.study_id] = counts.get(summary.study_id, 0) + 1
    return [StudyRow(id=s.id, kind=s.kind, created_at=s.created_at, jobs_done=s.jobs_done, jobs_failed=s.jobs_failed,
                     n_sessions=counts.get(s.id, 0), out_dir=s.out_dir) for s in store.list_studies()]


def json_text(value: Any) -> str:
    """Indented JSON for a page (non-JSON values as text)."""
    return json.dumps(value, indent=1, default=str)
