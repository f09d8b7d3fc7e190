"""Finding sessions in SQL (``Store.query_sessions``) gives what filtering every session in Python gives."""

from __future__ import annotations

import datetime as dt
import itertools
import sys
from pathlib import Path

import pytest

from aerobat.errors import ConfigError
from aerobat.store import Store
from aerobat.store.query import FACETS, SessionQuery, SortKey

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from browse_fixtures import build_store  # noqa: E402

TODAY = dt.datetime.now(dt.UTC).date()


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    path = tmp_path_factory.mktemp("query") / "store.sqlite"
    build_store(path, sessions=7, study_vehicles=12, failed_jobs=2, flown=False)
    with Store(path) as s:
        s.tag_session(2, "night")
        s.tag_session(2, "windy")
        s.tag_session(9, "night")
        s.tag_session(3, "50%_off")
        s.note_session(4, "Battery swapped after trial 2")
        s.note_session(12, "gusty; battery warm")
    with Store(path, create=False) as s:
        yield s


def _lower(text: str) -> str:
    return text.translate(str.maketrans("ABCDEFGHIJKLMNOPQRSTUVWXYZ", "abcdefghijklmnopqrstuvwxyz"))


def reference(store: Store, q: SessionQuery, *, skip: str = "", visibility: bool = True) -> list:
    """The sessions ``q`` finds, filtered in Python over every session (no SQL), id order."""
    rows = []
    for s in store.list_sessions():
        notes = [text for _, text in store.session(s.id).notes]
        values = {"maneuver": [s.maneuver_name], "plant": [s.plant_kind], "vehicle": [s.vehicle, s.plant_vehicle],
                  "feedback": [s.feedback], "rule": [s.rule], "status": [s.display_state]}
        ok = all(getattr(q, k) is None or k == skip or any(_lower(v) == _lower(getattr(q, k)) for v in vs)
                 for k, vs in values.items())
        ok &= q.tag is None or skip == "tag" or q.tag in s.tags
        if q.text is not None:
            hay = [s.maneuver_name, s.plant_kind, s.vehicle, s.plant_vehicle, s.feedback, s.rule, *s.tags, *notes]
            ok &= any(_lower(q.text) in _lower(h) for h in hay)
        ok &= q.since is None or s.started_at[:10] >= q.since
        ok &= q.until is None or s.started_at[:10] <= q.until
        if visibility and skip != "study":
            ok &= (s.study_id == q.study) if q.study is not None else (q.include_studies or s.study_id is None)
        if ok:
            rows.append(s)
    return rows


QUERIES = [
    SessionQuery(), SessionQuery(include_studies=True), SessionQuery(plant="rotorpy"), SessionQuery(plant="ARENA"),
    SessionQuery(feedback="tracking", include_studies=True), SessionQuery(feedback="none"),
    SessionQuery(rule="broyden"), SessionQuery(rule="paper", plant="arena", include_studies=True),
    SessionQuery(vehicle="hummingbird"), SessionQuery(vehicle="nobody"), SessionQuery(status="completed"),
    SessionQuery(status="killed"), SessionQuery(study=1), SessionQuery(study=1, plant="rotorpy"),
    SessionQuery(tag="night"), SessionQuery(tag="night", include_studies=True), SessionQuery(tag="50%_off"),
    SessionQuery(text="broyden", include_studies=True), SessionQuery(text="ROTOR"), SessionQuery(text="battery"),
    SessionQuery(text="wind"), SessionQuery(text="%"), SessionQuery(text="_"), SessionQuery(text="50%_"),
    SessionQuery(text="schedule"), SessionQuery(text="tracking", include_studies=True),
    SessionQuery(since=TODAY.isoformat()), SessionQuery(until=(TODAY - dt.timedelta(days=1)).isoformat()),
    SessionQuery(since=(TODAY + dt.timedelta(days=1)).isoformat(), include_studies=True),
    SessionQuery(until=TODAY.isoformat(), text="night", include_studies=True),
]


@pytest.mark.parametrize("query", QUERIES, ids=[repr({k: v for k, v in vars(q).items() if v not in (None, False, 0)
                                                      and k != "sort"}) for q in QUERIES])
def test_filters_match_a_filter_over_every_session(store, query):
    page = store.query_sessions(query, counts=True)
    expected = reference(store, query)
    assert [s.id for s in page.rows] == [s.id for s in expected]
    assert page.matched == len(expected) and page.total == 7 + 10
    hidden = [] if query.include_studies or query.study is not None else [
        s for s in reference(store, query, visibility=False) if s.study_id is not None]
    assert page.hidden == len(hidden)
    assert page == store.query_sessions(query, counts=True)  # the same question, the same answer
    plain = store.query_sessions(query)
    assert (plain.rows, plain.matched, plain.hidden) == (page.rows, page.matched, page.hidden)
    for facet in FACETS:  # each value's count: what choosing it (the other filters kept) would show
        for value, n in page.counts[facet]:
            chosen = SessionQuery(**{**{k: getattr(query, k) for k in vars(query)}, facet: int(value)
                                     if facet == "study" else value})
            assert n == len(reference(store, chosen)) > 0, (facet, value)
        if facet != "study":
            values = {str(v) for s in reference(store, query, skip=facet) for v in (
                s.tags if facet == "tag" else [s.vehicle, s.plant_vehicle] if facet == "vehicle" else
                [{"maneuver": s.maneuver_name, "plant": s.plant_kind, "feedback": s.feedback, "rule": s.rule,
                  "status": s.display_state}[facet]])}
            assert {v for v, _ in page.counts[facet]} == values, facet


def _key(s, key: SortKey):
    return {SortKey.ID: s.id, SortKey.MANEUVER: s.maneuver_name, SortKey.PLANT: s.plant_kind,
            SortKey.VEHICLE: s.plant_vehicle, SortKey.FEEDBACK: s.feedback, SortKey.RULE: s.rule,
            SortKey.STATUS: s.display_state, SortKey.TRIALS: s.n_measured, SortKey.ERROR: s.last_position_error_m,
            SortKey.STUDY: s.study_id, SortKey.SEED: s.seed, SortKey.STARTED: s.started_at}[key]


@pytest.mark.parametrize(("key", "descending"), list(itertools.product(SortKey, (False, True))))
def test_pages_in_every_order_cover_every_session_once(store, key, descending):
    every = reference(store, SessionQuery(include_studies=True))
    present = [s for s in every if _key(s, key) is not None]
    ordered = sorted(present, key=lambda s: (_key(s, key), s.id), reverse=descending) + sorted(
        (s for s in every if _key(s, key) is None), key=lambda s: s.id, reverse=descending)
    pages = [store.query_sessions(SessionQuery(include_studies=True, sort=key, descending=descending, limit=4,
                                               offset=offset)) for offset in range(0, 20, 4)]
    assert [s.id for p in pages for s in p.rows] == [s.id for s in ordered]
    assert [p.page for p in pages] == [1, 2, 3, 4, 5] and pages[0].pages == 5


def test_find_sessions_keeps_its_meaning(store):
    assert [s.id for s in store.find_sessions()] == list(range(1, 8))
    assert [s.id for s in store.find_sessions(limit=3)] == [5, 6, 7]
    assert [s.id for s in store.find_sessions(include_studies=True, limit=2)] == [16, 17]
    assert [s.id for s in store.find_sessions(study="last", plant="arena")] == [
        s.id for s in store.list_sessions() if s.study_id == 1 and s.plant_kind == "arena"]


@pytest.mark.parametrize(("fields", "message"), [
    ({"plant": ""}, "plant '': expected 1 to 200 printable characters"),
    ({"text": "a\nb"}, "printable"),
    ({"since": "2026-02-30"}, "since '2026-02-30': expected a day, YYYY-MM-DD"),
    ({"status": "asleep"}, "status 'asleep': allowed"),
    ({"sort": "colour"}, "sort = 'colour': allowed 'id', 'maneuver'"),
    ({"limit": 0}, "limit"), ({"offset": -1}, "offset"), ({"study": 0}, "study"),
])
def test_a_bad_query_is_one_clear_line(fields, message):
    with pytest.raises(ConfigError, match=message.replace("(", r"\(")):
        SessionQuery(**fields)
