"""What the browser shows of a store: one row per session and per study.

Everything here only reads (the store is opened read-only by :mod:`aerobat.browse.site`), and only
through the store's public readers, so every row is verified against its checksum.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from aerobat.store import Store
from aerobat.store.records import SessionSummary

__all__ = ["SessionRow", "StudyRow", "job_summary", "session_row", "session_rows", "study_rows"]


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


def session_row(summary: SessionSummary) -> SessionRow:
    """The table's row of a session (from its summary: nothing more is read)."""
    s = summary
    return SessionRow(
        id=s.id, maneuver=s.maneuver_name, maneuver_kind=s.maneuver_kind, plant=s.plant_kind,
        vehicle=s.plant_vehicle or s.vehicle, feedback=s.feedback or "none", rule=s.rule, status=s.display_state,
        study_id=s.study_id, started_at=s.started_at, updated_at=s.updated_at, n_records=s.n_records,
        n_measured=s.n_measured, target_iterations=s.target_iterations,
        last_position_error_m=s.last_position_error_m, seed=s.seed, tags=tuple(s.tags))


def session_rows(store: Store, *, session_id: int | None = None) -> list[SessionRow]:
    """Every session (or one), oldest first, with the names the table filters by."""
    if session_id is None:
        return [session_row(s) for s in store.list_sessions()]
    return [session_row(s) for s in store.session_summaries([session_id])]


def study_rows(store: Store) -> list[StudyRow]:
    """Every study with its job counts and how many sessions learned for it (counted by the database)."""
    counts = store.sessions_per_study()
    return [StudyRow(id=s.id, kind=s.kind, created_at=s.created_at, jobs_done=s.jobs_done, jobs_failed=s.jobs_failed,
                     n_sessions=counts.get(s.id, 0), out_dir=s.out_dir) for s in store.list_studies()]


def job_summary(result: Any, *, limit: int = 8) -> list[str]:
    """A study job's result as lines a person reads: ``name value`` for numbers and words, ``name: N values``
    for lists, ``name: {…}`` for tables; at most ``limit`` lines (the page shows the whole JSON on request)."""
    if not isinstance(result, dict):
        return [json_text(result)[:200]]
    lines = []
    for name, value in result.items():
        if isinstance(value, bool) or value is None or isinstance(value, str):
            lines.append(f"{name}: {value if value is not None else '—'}"[:120])
        elif isinstance(value, int | float):
            lines.append(f"{name}: {value:.4g}" if isinstance(value, float) else f"{name}: {value}")
        elif isinstance(value, list):
            lines.append(f"{name}: {len(value)} value{'' if len(value) == 1 else 's'}")
        elif isinstance(value, dict):
            lines.append(f"{name}: {{{', '.join(list(map(str, value))[:4])}{', …' if len(value) > 4 else ''}}}")
        else:
            lines.append(f"{name}: {str(value)[:80]}")
    return lines[:limit] + ([f"… {len(lines) - limit} more"] if len(lines) > limit else [])


def json_text(value: Any) -> str:
    """Indented JSON for a page (non-JSON values as text)."""
    return json.dumps(value, indent=1, default=str)
