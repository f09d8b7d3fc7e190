"""Browsing the store: finding sessions by what they flew, tagging, noting, comparing and deleting them."""

from __future__ import annotations

import json
import math
import sqlite3
from dataclasses import dataclass
from typing import Any

import numpy as np

from aerobat.config import check_type, short_repr
from aerobat.core.outcomes import IterationStatus, SessionStatus
from aerobat.errors import ConfigError, SessionInUse
from aerobat.store import checksums
from aerobat.store.codec import utc_now
from aerobat.store.owners import owner_alive
from aerobat.store.reading import Reading
from aerobat.store.records import SessionSummary

__all__ = ["Browsing", "SessionComparison", "SESSION_STATES", "SHOWN_STATES"]

SESSION_STATES: tuple[SessionStatus, ...] = tuple(SessionStatus)
"""States a session can be stored in. ``running`` sessions whose process is gone are shown as ``killed``."""

SHOWN_STATES = (*SESSION_STATES, "killed")
"""States ``aerobat sessions --status`` filters on (``killed``: running, but its process is gone)."""

_MAX_TAG = 64
_MAX_NOTE = 4000


@dataclass(frozen=True)
class SessionComparison:
    """Two sessions side by side (``aerobat compare A B``).

    Attributes
    ----------
    a, b : the session ids.
    rows : ``(field, value of a, value of b)``, every value as text; ``same`` says which agree.
    parameters : ``(name, unit, a's current value, b's current value)`` when both fly the same parameters.
    """

    a: int
    b: int
    rows: tuple[tuple[str, str, str], ...]
    parameters: tuple[tuple[str, str, float, float], ...]

    @property
    def differences(self) -> tuple[str, ...]:
        """The fields whose values differ."""
        return tuple(name for name, x, y in self.rows if x != y)

    def to_table(self) -> dict[str, Any]:
        return {"a": self.a, "b": self.b, "fields": [{"field": n, "a": x, "b": y, "same": x == y}
                                                     for n, x, y in self.rows],
                "parameters": [{"name": n, "unit": u, "a": x, "b": y} for n, u, x, y in self.parameters],
                "differences": list(self.differences)}


def _text(name: str, value: Any, limit: int) -> str:
    if not isinstance(value, str):
        raise ConfigError(f"{name}: expected text, got {short_repr(value)}")
    text = value.strip()
    if not text or len(text) > limit or not text.isprintable():
        raise ConfigError(f"{name} {short_repr(value)}: expected 1 to {limit} printable characters")
    return text


def _matches(wanted: str | None, *values: str) -> bool:
    return wanted is None or any(wanted.strip().lower() == v.lower() for v in values)


class Browsing(Reading):
    """Finding, tagging, noting, comparing and deleting sessions (the :class:`~aerobat.store.Store` has these)."""

    def find_sessions(self, *, plant: str | None = None, maneuver: str | None = None, vehicle: str | None = None,
                      feedback: str | None = None, status: str | None = None, study: int | str | None = None,
                      tag: str | None = None, include_studies: bool = False,
                      limit: int | None = None) -> list[SessionSummary]:
        """Sessions matching every filter given, oldest first (what ``aerobat sessions`` lists).

        Parameters
        ----------
        plant, maneuver, feedback : the plant's kind, the maneuver's name, the feedback scheme (``none``
            for the paper's open loop); case-insensitive.
        vehicle : the design model's or the flown vehicle's name.
        status : one of :data:`SHOWN_STATES`.
        study : only this study's sessions (an id or ``last``).
        tag : only sessions with this tag.
        include_studies : also the sessions studies learned in (hidden by default: a study stores hundreds).
        limit : only the newest ``limit`` of those that match.
        """
        for name, value in (("plant", plant), ("maneuver", maneuver), ("vehicle", vehicle),
                            ("feedback", feedback), ("tag", tag)):
            if value is not None:
                _text(name, value, 200)
        if status is not None and status not in SHOWN_STATES:
            raise ConfigError(f"status {short_repr(status)}: allowed {', '.join(SHOWN_STATES)}")
        check_type("include_studies", include_studies, (bool, np.bool_), "True or False")
        study_id = None if study is None else self.resolve_study(study)
        rows = [s for s in self.list_sessions()
                if _matches(plant, s.plant_kind) and _matches(maneuver, s.maneuver_name)
                and _matches(vehicle, s.vehicle, s.plant_vehicle) and _matches(feedback, s.feedback)
                and (status is None or s.display_state == status) and (tag is None or tag.strip() in s.tags)
                and (s.study_id == study_id if study_id is not None else include_studies or s.study_id is None)]
        if limit is not None:
            from aerobat.config import check_int

            rows = rows[max(0, len(rows) - check_int("limit", limit, low=1)):]
        return rows

    def tag_session(self, session_id: int, tag: str, *, remove: bool = False) -> tuple[str, ...]:
        """Add (or ``remove``) a tag; the session's tags afterwards."""
        session_id = self._session_id(session_id)
        tag = _text("tag", tag, _MAX_TAG)
        if any(c.isspace() or c == "," for c in tag):
            raise ConfigError(f"tag {short_repr(tag)}: no spaces or commas (give several tags one at a time)")

        def write(conn: sqlite3.Connection) -> tuple[str, ...]:
            row = checksums.fetch(conn, self.path, "sessions", {"id": session_id})
            assert row is not None
            tags = list(self._loads(row["tags"], f"session {session_id} tags") if row["tags"] else [])
            if remove and tag not in tags:
                raise ConfigError(f"session {session_id} has no tag {tag!r} (its tags: {', '.join(tags) or 'none'})")
            tags = [t for t in tags if t != tag] + ([] if remove else [tag])
            checksums.update(conn, self.path, "sessions", {"id": session_id},
                             {"tags": json.dumps(tags) if tags else None}, old=row)
            return tuple(tags)

        return tuple(self._write(f"tagging session {session_id}", write))

    def note_session(self, session_id: int, text: str) -> int:
        """Append a note to a session (kept with the time it was written); how many notes it has."""
        session_id = self._session_id(session_id)
        text = _text("note", text, _MAX_NOTE)

        def write(conn: sqlite3.Connection) -> int:
            row = checksums.fetch(conn, self.path, "sessions", {"id": session_id})
            assert row is not None
            notes = list(self._loads(row["notes"], f"session {session_id} notes") if row["notes"] else [])
            notes.append({"at": utc_now(), "text": text})
            checksums.update(conn, self.path, "sessions", {"id": session_id}, {"notes": json.dumps(notes)}, old=row)
            return len(notes)

        return int(self._write(f"noting session {session_id}", write))

    def delete_session(self, session_id: int) -> int:
        """Delete a session and its iterations, nothing else; the number of iterations deleted.

        Its vehicle, plant, maneuver and design stay (other sessions may share them). Refused,
        with nothing deleted, for a session still being run, one a study learned in (its job
        refers to it), and one other sessions were warm-started from.
        """
        session_id = self._session_id(session_id)

        def write(conn: sqlite3.Connection) -> int:
            row = checksums.fetch(conn, self.path, "sessions", {"id": session_id})
            assert row is not None
            running = self._state(row) is SessionStatus.RUNNING
            if running and row["owner"] != self.owner and owner_alive(row["owner"]) is not False:
                raise SessionInUse(f"{self.path}: session {session_id} is being run by process {row['pid']}; stop "
                                   f"it before deleting the session")
            jobs = conn.execute("SELECT study_id, key FROM study_jobs WHERE session_id = ?", (session_id,)).fetchall()
            if row["study_id"] is not None or jobs:
                study = row["study_id"] if row["study_id"] is not None else jobs[0][0]
                raise ConfigError(f"{self.path}: session {session_id} belongs to study {study} (its results refer "
                                  f"to it); it is not deleted")
            children = [r[0] for r in conn.execute("SELECT id FROM sessions WHERE warm_start_from = ? ORDER BY id",
                                                   (session_id,))]
            if children:
                raise ConfigError(f"{self.path}: session {session_id} is the warm start of session(s) "
                                  f"{', '.join(map(str, children))}; delete those first")
            count = conn.execute("DELETE FROM iterations WHERE session_id = ?", (session_id,)).rowcount
            conn.execute("DELETE FROM sessions WHERE id = ?", (session_id,))
            return int(count)

        deleted = int(self._write(f"deleting session {session_id}", write))
        self._position_masks.pop(session_id, None)
        return deleted

    def compare_sessions(self, a: int, b: int) -> SessionComparison:
        """Two sessions side by side: what they flew, how they learned, where they ended."""
        recs = [self.session(self._session_id(a)), self.session(self._session_id(b))]
        mans = [self.maneuver(r.maneuver_id) for r in recs]
        firsts, bests = [], []
        for rec in recs:
            found = [self._position_error(rec.id, it.error) for it in self.iterations(rec.id)
                     if it.status is IterationStatus.OK]
            errors = [e for e in found if e is not None]
            firsts.append(_metres(errors[0] if errors else None))
            bests.append(_metres(min(errors) if errors else None))

        def both(fn: Any) -> tuple[str, str]:
            return str(fn(recs[0], mans[0])), str(fn(recs[1], mans[1]))

        rows = [("maneuver", *both(lambda r, m: m.name)), ("plant", *both(lambda r, m: r.plant_kind)),
                ("vehicle (design model)", *both(lambda r, m: r.vehicle)),
                ("vehicle flown", *both(lambda r, m: r.plant_vehicle)),
                ("feedback", *both(lambda r, m: r.feedback)), ("seed", *both(lambda r, m: r.seed)),
                ("rule", *both(lambda r, m: json.dumps(r.rule, sort_keys=True))),
                ("state", *both(lambda r, m: r.display_state)),
                ("measured iterations", *both(lambda r, m: f"{r.n_measured}/{r.target_iterations}")),
                ("first position error [m]", firsts[0], firsts[1]),
                ("best position error [m]", bests[0], bests[1]),
                ("last position error [m]", *both(lambda r, m: _metres(r.last_position_error_m))),
                ("study", *both(lambda r, m: "—" if r.study_id is None else r.study_id)),
                ("tags", *both(lambda r, m: ", ".join(r.tags) or "—"))]
        parameters: list[tuple[str, str, float, float]] = []
        if mans[0].parameter_names == mans[1].parameter_names:
            parameters = [(n, u, float(x), float(y)) for n, u, x, y in zip(
                mans[0].parameter_names, mans[0].parameter_units, recs[0].current_params, recs[1].current_params,
                strict=True)]
        return SessionComparison(recs[0].id, recs[1].id, tuple(rows), tuple(parameters))

    def _position_error(self, session_id: int, error: np.ndarray) -> float | None:
        mask = self._position_mask(session_id)
        if mask.shape != error.shape or not mask.any() or not np.all(np.isfinite(error[mask])):
            return None
        return float(np.linalg.norm(error[mask]))


def _metres(value: float | None) -> str:
    return "—" if value is None or not math.isfinite(value) else f"{value:.4f}"

