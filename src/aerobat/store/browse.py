"""Browsing the store: finding sessions by what they flew, tagging, noting, comparing and deleting them."""

from __future__ import annotations

import json
import math
import sqlite3
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from aerobat.config import check_type, short_repr
from aerobat.core.outcomes import IterationStatus, SessionStatus
from aerobat.errors import ConfigError, SessionInUse
from aerobat.store import checksums
from aerobat.store import query as sql
from aerobat.store.codec import utc_now
from aerobat.store.owners import owner_alive
from aerobat.store.query import FACETS, SHOWN_STATES, SessionPage, SessionQuery, check_text
from aerobat.store.reading import Reading
from aerobat.store.records import SessionSummary

__all__ = ["MAX_SETTING_ROWS", "Browsing", "SessionComparison", "SessionsComparison", "SESSION_STATES",
           "SHOWN_STATES"]

SESSION_STATES: tuple[SessionStatus, ...] = tuple(SessionStatus)
"""States a session can be stored in. ``running`` sessions whose process is gone are shown as ``killed``."""

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


@dataclass(frozen=True)
class SessionsComparison:
    """Two or more sessions side by side (the browser's compare page; ``aerobat compare`` shows two).

    Attributes
    ----------
    ids : the session ids, in the order given.
    rows : ``(field, one value per session)``, every value as text: what they flew, how they learned,
        where they ended, then every plant setting (the tune, the simulator's settings) that differs.
    parameters : ``(name, unit, current value per session)`` when all fly the same parameters.
    """

    ids: tuple[int, ...]
    rows: tuple[tuple[str, tuple[str, ...]], ...]
    parameters: tuple[tuple[str, str, tuple[float, ...]], ...]

    @property
    def differences(self) -> tuple[str, ...]:
        """The fields whose values are not all the same."""
        return tuple(name for name, values in self.rows if len(set(values)) > 1)


MAX_SETTING_ROWS = 40
"""The most differing plant settings a comparison lists (the rest are counted)."""


def _flat(table: Any, prefix: str = "") -> dict[str, str]:
    """``{"settings.gains.p": "0.5", …}``: a nested table's leaves as text, by dotted name."""
    if isinstance(table, dict):
        out: dict[str, str] = {}
        for key, value in table.items():
            out.update(_flat(value, f"{prefix}{key}."))
        return out
    return {prefix.rstrip("."): json.dumps(table, sort_keys=True) if isinstance(table, list) else str(table)}


def _nocase(text: str) -> str:
    """``text`` with ASCII letters in lower case (as SQLite's NOCASE compares)."""
    return text.translate(_LOWER)


_LOWER = str.maketrans("ABCDEFGHIJKLMNOPQRSTUVWXYZ", "abcdefghijklmnopqrstuvwxyz")


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

        The filters run in the database (:meth:`query_sessions`): only the sessions returned are read.
        """
        check_type("include_studies", include_studies, (bool, np.bool_), "True or False")
        query = SessionQuery(plant=plant, maneuver=maneuver, vehicle=vehicle, feedback=feedback, status=status,
                             tag=tag, study=None if study is None else self.resolve_study(study),
                             include_studies=bool(include_studies), descending=limit is not None, limit=limit)
        return list(reversed(self.query_sessions(query).rows)) if limit is not None else \
            list(self.query_sessions(query).rows)

    def query_sessions(self, query: SessionQuery, *, counts: bool = False) -> SessionPage:
        """A page of the sessions ``query`` finds, how many match, and (``counts``) how many each filter value has.

        Everything but the page's rows is answered by SQL on the sessions table; the page's rows
        are read whole and verified against their checksums. With ``counts``, each of :data:`FACETS`
        gets its values with the number of sessions each would show under the other filters (one
        ``GROUP BY`` over the sessions that pass the text, tag and day filters, and one for the tags).
        """
        if not isinstance(query, SessionQuery):
            raise ConfigError(f"query: expected a SessionQuery, got {short_repr(query)}")
        check_type("counts", counts, (bool, np.bool_), "True or False")
        with self._guard("finding sessions"):
            dead = self._dead_owners()
            where, args = sql.where(query, dead)
            order, order_args = sql.order_by(query, dead)
            page = f" LIMIT {query.limit if query.limit is not None else -1} OFFSET {query.offset}"
            rows = self._db.execute(f"SELECT {checksums.select_list('sessions', 's')} FROM sessions s{where}{order}"
                                    f"{page}", [*args, *order_args]).fetchall()
            total = int(self._db.execute("SELECT count(*) FROM sessions").fetchone()[0])
            if counts:
                facets, matched, hidden = self._facet_counts(query, dead)
            else:
                facets = {}
                matched = int(self._db.execute(f"SELECT count(*) FROM sessions s{where}", args).fetchone()[0])
                hidden = 0
                if query.study is None and not query.include_studies:
                    studies_where, studies_args = sql.where(query, dead, studies=True)
                    hidden = int(self._db.execute(f"SELECT count(*) FROM sessions s{studies_where}",
                                                  studies_args).fetchone()[0])
        return SessionPage(query, tuple(self._summaries(rows)), matched, total, hidden, facets)

    def _dead_owners(self) -> tuple[str, ...]:
        """Owners of sessions stored as running whose process is gone (their sessions are shown ``killed``)."""
        owners = [r[0] for r in self._db.execute(
            "SELECT DISTINCT owner FROM sessions WHERE state = 'running' AND owner IS NOT NULL")]
        return tuple(o for o in owners if owner_alive(o) is False)

    def _facet_counts(self, query: SessionQuery, dead: tuple[str, ...]
                      ) -> tuple[dict[str, tuple[tuple[str, int], ...]], int, int]:
        """Counts per value of every facet, the sessions matching every filter, and those hidden as a study's."""
        state, state_args = sql.state_sql(dead)
        where, args = sql.where(query, dead, facets=False)
        grouped = sql.GROUPED_SQL.format(state=state)
        groups = self._db.execute(f"SELECT {grouped}{where} GROUP BY 1, 2, 3, 4, 5, 6, 7, 8",
                                  [*state_args, *args]).fetchall()
        wanted = {name: None if getattr(query, name) is None else _nocase(str(getattr(query, name)))
                  for name in ("maneuver", "plant", "vehicle", "feedback", "rule", "status")}

        def passes(group: tuple[Any, ...], skip: str) -> bool:
            maneuver, plant, flown, designed, feedback, rule, status, study_id, _ = group
            values = {"maneuver": (maneuver,), "plant": (plant,), "vehicle": (flown, designed),
                      "feedback": (feedback,), "rule": (rule,), "status": (status,)}
            for name, want in wanted.items():
                if want is not None and name != skip and not any(_nocase(str(v)) == want for v in values[name]):
                    return False
            if skip == "study":
                return True
            if query.study is not None:
                return bool(study_id == query.study)
            return query.include_studies or study_id is None

        counts: dict[str, dict[str, int]] = {name: {} for name in FACETS}
        matched = hidden = 0
        for group in groups:
            n = int(group[-1])
            if passes(group, ""):
                matched += n
            elif query.study is None and not query.include_studies and group[7] is not None and passes(
                    group[:7] + (None, n), ""):
                hidden += n
            for k, name in enumerate(FACETS[:-1]):
                if not passes(group, name):
                    continue
                if name == "vehicle":
                    values = {str(group[2] or group[3] or "")} | ({str(group[3])} if group[3] else set())
                elif name == "study":
                    values = set() if group[7] is None else {str(group[7])}
                else:
                    values = {str(group[k if k < 2 else k + 1] or "")}
                for value in values:
                    counts[name][value] = counts[name].get(value, 0) + n
        tag_where, tag_args = sql.where(query.without("tag"), dead)
        counts["tag"] = {str(value): int(n) for value, n in self._db.execute(
            f"SELECT j.value, count(*) FROM sessions s, json_each({sql.TAGS_SQL}) j{tag_where} GROUP BY j.value",
            tag_args).fetchall()}
        ordered = {name: tuple(sorted(values.items(), key=lambda item: (-item[1], item[0])))
                   for name, values in counts.items()}
        return ordered, matched, hidden

    def tag_session(self, session_id: int, tag: str, *, remove: bool = False) -> tuple[str, ...]:
        """Add (or ``remove``) a tag; the session's tags afterwards."""
        session_id = self._session_id(session_id)
        tag = check_text("tag", tag, _MAX_TAG)
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
        text = check_text("note", text, _MAX_NOTE)

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
        both = self.compare_many([a, b])
        return SessionComparison(both.ids[0], both.ids[1], tuple((n, x, y) for n, (x, y) in both.rows),
                                 tuple((n, u, x, y) for n, u, (x, y) in both.parameters))

    def compare_many(self, session_ids: Sequence[int]) -> SessionsComparison:
        """Sessions side by side: what they flew, how they learned, where they ended, the plant settings
        that differ (at most :data:`MAX_SETTING_ROWS`), and the learned parameters if all fly the same ones."""
        recs = [self.session(self._session_id(sid)) for sid in session_ids]
        mans = [self.maneuver(r.maneuver_id) for r in recs]
        plants = [self.plant(r.plant_id) for r in recs]
        firsts, bests = [], []
        for rec in recs:
            found = [self._position_error(rec.id, it.error) for it in self.iterations(rec.id)
                     if it.status is IterationStatus.OK]
            errors = [e for e in found if e is not None]
            firsts.append(_metres(errors[0] if errors else None))
            bests.append(_metres(min(errors) if errors else None))

        def each(fn: Any) -> tuple[str, ...]:
            return tuple(str(fn(r, m)) for r, m in zip(recs, mans, strict=True))

        rows = [("maneuver", each(lambda r, m: m.name)), ("plant", each(lambda r, m: r.plant_kind)),
                ("vehicle (design model)", each(lambda r, m: r.vehicle)),
                ("vehicle flown", each(lambda r, m: r.plant_vehicle)),
                ("feedback", each(lambda r, m: r.feedback)), ("seed", each(lambda r, m: r.seed)),
                ("rule", each(lambda r, m: json.dumps(r.rule, sort_keys=True))),
                ("state", each(lambda r, m: r.display_state)),
                ("measured iterations", each(lambda r, m: f"{r.n_measured}/{r.target_iterations}")),
                ("first position error [m]", tuple(firsts)), ("best position error [m]", tuple(bests)),
                ("last position error [m]", each(lambda r, m: _metres(r.last_position_error_m))),
                ("study", each(lambda r, m: "—" if r.study_id is None else r.study_id)),
                ("tags", each(lambda r, m: ", ".join(r.tags) or "—"))]
        settings = [_flat(p.config) for p in plants]
        names = sorted({k for table in settings for k in table})
        differing = [n for n in names if len({table.get(n, "—") for table in settings}) > 1]
        rows += [(f"plant setting {n}", tuple(table.get(n, "—") for table in settings))
                 for n in differing[:MAX_SETTING_ROWS]]
        if len(differing) > MAX_SETTING_ROWS:
            rows.append(("plant settings not listed", (f"{len(differing) - MAX_SETTING_ROWS} more differ",)
                         * len(recs)))
        parameters: list[tuple[str, str, tuple[float, ...]]] = []
        if all(m.parameter_names == mans[0].parameter_names for m in mans):
            parameters = [(n, u, tuple(float(r.current_params[k]) for r in recs)) for k, (n, u) in enumerate(zip(
                mans[0].parameter_names, mans[0].parameter_units, strict=True))]
        return SessionsComparison(tuple(r.id for r in recs), tuple(rows), tuple(parameters))

    def _position_error(self, session_id: int, error: np.ndarray) -> float | None:
        mask = self._position_mask(session_id)
        if mask.shape != error.shape or not mask.any() or not np.all(np.isfinite(error[mask])):
            return None
        return float(np.linalg.norm(error[mask]))


def _metres(value: float | None) -> str:
    return "—" if value is None or not math.isfinite(value) else f"{value:.4f}"

