"""Finding sessions in SQL: filters, text search, sorting, paging and counts per filter value.

A store of a lab's year holds hundreds of thousands of sessions (one robustness study stores a
thousand). Everything here is answered by the database: the filters are SQL conditions on the
sessions table (the names they match sit in the small tables a session refers to, reached by
sub-queries), a page is ``ORDER BY … LIMIT … OFFSET``, and the counts a browser shows beside each
filter value come from one ``GROUP BY``. Only the rows of the page are read whole and verified
against their checksums (:meth:`aerobat.store.Store.query_sessions`).
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from aerobat.config import check_type, short_repr
from aerobat.core.bounds import Integer, OneOf, bounded, validate
from aerobat.core.outcomes import SessionStatus
from aerobat.errors import ConfigError
from aerobat.store.records import SessionSummary

__all__ = ["FACETS", "SHOWN_STATES", "SessionPage", "SessionQuery", "SortKey", "check_text"]

SHOWN_STATES = (*tuple(SessionStatus), "killed")
"""States a session is shown in (``killed``: stored as running, but its process is gone)."""

FACETS = ("maneuver", "plant", "vehicle", "feedback", "rule", "status", "study", "tag")
"""The filters whose values :class:`SessionPage` counts."""

MAX_TEXT = 200
"""The longest filter value or search text [characters]."""


class SortKey(StrEnum):
    """What a page of sessions is sorted by (the sessions table's columns)."""

    ID = "id"
    MANEUVER = "maneuver"
    PLANT = "plant"
    VEHICLE = "vehicle"
    FEEDBACK = "feedback"
    RULE = "rule"
    STATUS = "status"
    TRIALS = "trials"
    ERROR = "error"
    STUDY = "study"
    SEED = "seed"
    STARTED = "started"


def check_text(name: str, value: Any, limit: int = MAX_TEXT) -> str:
    """A filter value or search text, stripped: 1 to ``limit`` printable characters."""
    if not isinstance(value, str):
        raise ConfigError(f"{name}: expected text, got {short_repr(value)}")
    text = value.strip()
    if not text or len(text) > limit or not text.isprintable():
        raise ConfigError(f"{name} {short_repr(value)}: expected 1 to {limit} printable characters")
    return text


def _day(name: str, value: Any) -> str:
    text = check_text(name, value, 10)
    try:
        return _dt.date.fromisoformat(text).isoformat()
    except ValueError:
        raise ConfigError(f"{name} {short_repr(value)}: expected a day, YYYY-MM-DD") from None


@dataclass(frozen=True, kw_only=True)
class SessionQuery:
    """Which sessions, in what order, which page (every filter optional; all given must hold).

    Attributes
    ----------
    maneuver, plant, feedback, rule : the maneuver's name, the plant's kind, the feedback scheme
        (``none``: the paper's open loop), the update rule's name; case-insensitive (ASCII).
    vehicle : the design model's or the flown vehicle's name.
    status : one of :data:`SHOWN_STATES`.
    study : only this study's sessions (they are shown whatever ``include_studies`` says).
    tag : only sessions with this tag.
    text : sessions whose maneuver, plant, vehicles, feedback, rule, tags or notes contain it.
    since, until : first and last day started (``YYYY-MM-DD``, UTC), both included.
    include_studies : also the sessions studies learned in (hidden by default: a study stores hundreds).
    sort, descending : the order (ties in id order).
    offset, limit : the page: skip ``offset`` sessions, then at most ``limit`` (None: all).
    """

    maneuver: str | None = None
    plant: str | None = None
    vehicle: str | None = None
    feedback: str | None = None
    rule: str | None = None
    status: str | None = None
    study: int | None = bounded(None, Integer(1, 2**63 - 1))
    tag: str | None = None
    text: str | None = None
    since: str | None = None
    until: str | None = None
    include_studies: bool = False
    sort: SortKey = bounded(SortKey.ID, OneOf(SortKey))
    descending: bool = False
    offset: int = bounded(0, Integer(0, 2**62))
    limit: int | None = bounded(None, Integer(1, 2**62))

    def __post_init__(self) -> None:
        for name in ("maneuver", "plant", "vehicle", "feedback", "rule", "tag", "text"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, check_text(name, value))
        for name in ("since", "until"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, _day(name, value))
        if self.status is not None and self.status not in SHOWN_STATES:
            raise ConfigError(f"status {short_repr(self.status)}: allowed {', '.join(SHOWN_STATES)}")
        check_type("include_studies", self.include_studies, bool, "True or False")
        check_type("descending", self.descending, bool, "True or False")
        validate(self, skip=[name for name in ("study", "limit") if getattr(self, name) is None])

    def without(self, facet: str) -> SessionQuery:
        """This query without the filter ``facet`` (one of :data:`FACETS`)."""
        from dataclasses import replace

        if facet not in FACETS:
            raise ConfigError(f"facet {short_repr(facet)}: allowed {', '.join(FACETS)}")
        cleared: dict[str, Any] = {facet: None}
        return replace(self, **cleared)


@dataclass(frozen=True)
class SessionPage:
    """One page of the sessions a :class:`SessionQuery` finds.

    Attributes
    ----------
    query : what was asked.
    rows : the page's sessions, in the query's order (each row verified against its checksum).
    matched : how many sessions match every filter (all pages).
    total : sessions in the store, studies' included.
    hidden : sessions that match every filter but are hidden because they are a study's.
    counts : per filter of :data:`FACETS` (when asked for), each value with the number of sessions
        it would show under the other filters, most first.
    """

    query: SessionQuery
    rows: tuple[SessionSummary, ...]
    matched: int
    total: int
    hidden: int = 0
    counts: Mapping[str, tuple[tuple[str, int], ...]] = field(default_factory=dict)

    @property
    def pages(self) -> int:
        """How many pages of ``query.limit`` rows the matching sessions fill (1 with no limit)."""
        size = self.query.limit
        return 1 if not size else max(1, -(-self.matched // size))

    @property
    def page(self) -> int:
        """This page's number, from 1."""
        size = self.query.limit
        return 1 if not size else self.query.offset // size + 1


# ------------------------------------------------------------------ SQL
# Every expression names the sessions table ``s``. Values a session refers to are reached by
# sub-queries on their (primary-key) ids: the sessions table is scanned once.
_JSON_NAME = "CASE WHEN json_valid({0}) THEN json_extract({0}, '$.name') END"
RULE_SQL = f"coalesce({_JSON_NAME.format('s.rule')}, '')"
MANEUVER_SQL = "(SELECT m.name FROM maneuvers m WHERE m.id = s.maneuver_id)"
PLANT_SQL = "(SELECT p.kind FROM plants p WHERE p.id = s.plant_id)"
FLOWN_SQL = ("(SELECT v.name FROM plants p JOIN vehicles v ON v.id = p.vehicle_id WHERE p.id = s.plant_id)")
DESIGNED_SQL = ("(SELECT v.name FROM designs d JOIN vehicles v ON v.id = d.vehicle_id WHERE d.id = s.design_id)")
FEEDBACK_SQL = ("(SELECT coalesce(CASE WHEN json_valid(p.config) THEN json_extract(p.config, '$.feedback.scheme') "
                "END, 'none') FROM plants p WHERE p.id = s.plant_id)")
GROUPED_SQL = ("m.name, p.kind, pv.name, dv.name, coalesce(CASE WHEN json_valid(p.config) THEN "
               "json_extract(p.config, '$.feedback.scheme') END, 'none'), " + RULE_SQL + ", {state}, s.study_id, "
               "count(*) FROM sessions s JOIN maneuvers m ON m.id = s.maneuver_id JOIN plants p ON p.id = s.plant_id "
               "JOIN vehicles pv ON pv.id = p.vehicle_id JOIN designs d ON d.id = s.design_id "
               "JOIN vehicles dv ON dv.id = d.vehicle_id")
"""What the counts per filter value group by: maneuver, plant, flown and designed vehicle, feedback, rule,
shown state and study of every session (joined: one pass over the sessions)."""

TAGS_SQL = "CASE WHEN json_valid(s.tags) THEN s.tags ELSE '[]' END"
NOTES_SQL = "CASE WHEN json_valid(s.notes) THEN s.notes ELSE '[]' END"


def state_sql(dead_owners: tuple[str, ...]) -> tuple[str, list[Any]]:
    """The shown state of a session (``killed`` for a running one whose owner is gone)."""
    if not dead_owners:
        return "s.state", []
    marks = ", ".join("?" * len(dead_owners))
    return f"CASE WHEN s.state = 'running' AND s.owner IN ({marks}) THEN 'killed' ELSE s.state END", \
        list(dead_owners)


def _like(text: str) -> str:
    return "%" + text.replace("\\", "\\\\").replace("%", "\\%").replace("_", "\\_") + "%"


def where(query: SessionQuery, dead_owners: tuple[str, ...], *, facets: bool = True,
          studies: bool | None = None) -> tuple[str, list[Any]]:
    """``WHERE`` conditions (and their arguments) for the filters of ``query``.

    ``facets``: False leaves out the filters :meth:`SessionPage.counts` counts by (all but the tag, the
    text and the days). ``studies``: True for only study sessions, False for none, None for what the
    query says.
    """
    skip = frozenset() if facets else frozenset(FACETS) - {"tag"}
    conds: list[str] = []
    args: list[Any] = []

    def add(cond: str, *values: Any) -> None:
        conds.append(cond)
        args.extend(values)

    if query.maneuver is not None and "maneuver" not in skip:
        add("s.maneuver_id IN (SELECT id FROM maneuvers WHERE name = ? COLLATE NOCASE)", query.maneuver)
    if query.plant is not None and "plant" not in skip:
        add("s.plant_id IN (SELECT id FROM plants WHERE kind = ? COLLATE NOCASE)", query.plant)
    if query.feedback is not None and "feedback" not in skip:
        add(f"{FEEDBACK_SQL} = ? COLLATE NOCASE", query.feedback)
    if query.vehicle is not None and "vehicle" not in skip:
        add("(s.plant_id IN (SELECT p.id FROM plants p JOIN vehicles v ON v.id = p.vehicle_id WHERE v.name = ? "
            "COLLATE NOCASE) OR s.design_id IN (SELECT d.id FROM designs d JOIN vehicles v ON v.id = d.vehicle_id "
            "WHERE v.name = ? COLLATE NOCASE))", query.vehicle, query.vehicle)
    if query.rule is not None and "rule" not in skip:
        add(f"{RULE_SQL} = ? COLLATE NOCASE", query.rule)
    if query.status is not None and "status" not in skip:
        state, state_args = state_sql(dead_owners)
        add(f"{state} = ?", *state_args, query.status)
    if query.tag is not None and "tag" not in skip:
        add(f"s.tags IS NOT NULL AND EXISTS (SELECT 1 FROM json_each({TAGS_SQL}) WHERE value = ?)", query.tag)
    if query.text is not None:
        like = _like(query.text)
        add("(s.maneuver_id IN (SELECT id FROM maneuvers WHERE name LIKE ? ESCAPE '\\') "
            "OR s.plant_id IN (SELECT p.id FROM plants p JOIN vehicles v ON v.id = p.vehicle_id "
            "WHERE p.kind LIKE ? ESCAPE '\\' OR v.name LIKE ? ESCAPE '\\' "
            "OR (CASE WHEN json_valid(p.config) THEN json_extract(p.config, '$.feedback.scheme') END) LIKE ? "
            "ESCAPE '\\') "
            "OR s.design_id IN (SELECT d.id FROM designs d JOIN vehicles v ON v.id = d.vehicle_id "
            "WHERE v.name LIKE ? ESCAPE '\\') "
            f"OR {RULE_SQL} LIKE ? ESCAPE '\\' "
            f"OR (s.tags IS NOT NULL AND EXISTS (SELECT 1 FROM json_each({TAGS_SQL}) WHERE value LIKE ? ESCAPE '\\')) "
            f"OR (s.notes IS NOT NULL AND EXISTS (SELECT 1 FROM json_each({NOTES_SQL}) "
            f"WHERE json_extract(value, '$.text') LIKE ? ESCAPE '\\')))", *[like] * 8)
    if query.since is not None:
        add("s.started_at >= ?", query.since)
    if query.until is not None:
        add("s.started_at < ?", (_dt.date.fromisoformat(query.until) + _dt.timedelta(days=1)).isoformat())
    if not facets:
        pass
    elif query.study is not None:
        add("s.study_id = ?", query.study)
    elif studies is True:
        add("s.study_id IS NOT NULL")
    elif studies is False or (studies is None and not query.include_studies and query.study is None):
        add("s.study_id IS NULL")
    return (" WHERE " + " AND ".join(conds)) if conds else "", args


def order_by(query: SessionQuery, dead_owners: tuple[str, ...]) -> tuple[str, list[Any]]:
    """``ORDER BY`` for the query's sort (ties and equal values in id order; no value last)."""
    direction = "DESC" if query.descending else "ASC"
    args: list[Any] = []
    key = query.sort
    if key is SortKey.ID:
        return f" ORDER BY s.id {direction}", args
    expression = {SortKey.MANEUVER: MANEUVER_SQL, SortKey.PLANT: PLANT_SQL, SortKey.VEHICLE: FLOWN_SQL,
                  SortKey.FEEDBACK: FEEDBACK_SQL, SortKey.RULE: RULE_SQL, SortKey.TRIALS: "s.n_measured",
                  SortKey.ERROR: "s.last_position_error_m", SortKey.STUDY: "s.study_id", SortKey.SEED: "s.seed",
                  SortKey.STARTED: "s.started_at"}.get(key)
    if expression is None:  # status
        expression, args = state_sql(dead_owners)
    return f" ORDER BY ({expression}) IS NULL, ({expression}) {direction}, s.id {direction}", args + args
