"""Browsing the store (issue 25, item 5): filters, tags, notes, compare, delete, and replay's notes."""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import math
from pathlib import Path

import pytest

from aerobat.cli import main
from aerobat.core.design import design
from aerobat.errors import ConfigError
from aerobat.experiments import start_session
from aerobat.plants import PlantChoice
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel
from aerobat.quadrotor.vehicle import hummingbird
from aerobat.store import Store, checksums

CONFIG = hummingbird()
FLIP = MultiFlip(vehicle=CONFIG.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
DESIGN = design(FLIP, NominalModel(CONFIG))


def call(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


@pytest.fixture()
def db(tmp_path) -> Path:
    """Sessions 1 (nominal, open loop), 2 (arena, tracking feedback) and 3 (nominal, learned for study 1)."""
    path = tmp_path / "s.sqlite"
    with Store(path) as store:
        for plant in (PlantChoice("nominal"), PlantChoice("arena", seed=2, feedback="tracking")):
            assert start_session(store, FLIP, model=CONFIG, plant=plant, iterations=2,
                                 design_result=DESIGN).run().completed
        study = store.create_study("rules", {"what": "test"})
        assert start_session(store, FLIP, model=CONFIG, plant=PlantChoice("nominal"), iterations=1,
                             design_result=DESIGN, study_id=study).run().completed
    return path


def ids(rows) -> list[int]:
    return [r.id for r in rows]


def test_find_sessions_filters_and_hides_study_sessions(db):
    with Store(db, create=False) as store:
        assert ids(store.find_sessions()) == [1, 2]  # study sessions hidden
        assert ids(store.find_sessions(include_studies=True)) == [1, 2, 3]
        assert ids(store.find_sessions(study=1)) == [3]
        assert ids(store.find_sessions(plant="nominal", include_studies=True)) == [1, 3]
        assert ids(store.find_sessions(feedback="tracking")) == [2]
        assert ids(store.find_sessions(feedback="none")) == [1]
        assert ids(store.find_sessions(vehicle=CONFIG.name)) == [1, 2]
        assert ids(store.find_sessions(vehicle="nobody")) == []
        assert ids(store.find_sessions(maneuver=store.session(1).maneuver_name, status="completed")) == [1, 2]
        assert ids(store.find_sessions(limit=1)) == [2]
        summary = store.find_sessions()[1]
        assert summary.feedback == "tracking" and summary.vehicle == CONFIG.name
        with pytest.raises(ConfigError, match="status 'done'"):
            store.find_sessions(status="done")


def test_the_sessions_command_filters_and_shows_vehicle_and_feedback(db):
    code, out, _ = call(["sessions", "--db", str(db)])
    assert code == 0
    lines = out.splitlines()
    assert "vehicle" in lines[0] and "feedback" in lines[0]
    assert [line.split()[0] for line in lines[2:4]] == ["1", "2"] and "tracking" in lines[3]
    assert lines[-1] == "1 study sessions hidden: --all shows them"
    code, out, _ = call(["sessions", "--all", "--json", "--db", str(db)])
    assert [r["id"] for r in json.loads(out)] == [1, 2, 3] and json.loads(out)[2]["study"] == 1
    code, out, _ = call(["sessions", "--feedback", "tracking", "--json", "--db", str(db)])
    assert [(r["id"], r["feedback"], r["plant"]) for r in json.loads(out)] == [(2, "tracking", "arena")]
    code, out, _ = call(["sessions", "--plant", "rotorpy", "--db", str(db)])
    assert code == 0 and out.startswith("no sessions") and "match" in out
    code, _, err = call(["sessions", "--status", "nope", "--db", str(db)])
    assert code == 2 and "--status" in err


def test_tags_and_notes_are_stored_listed_and_shown(db):
    assert call(["tag", "1", "baseline", "--db", str(db)])[0] == 0
    assert call(["tag", "2", "baseline", "--db", str(db)])[0] == 0
    code, out, _ = call(["tag", "2", "baseline", "--remove", "--json", "--db", str(db)])
    assert code == 0 and json.loads(out) == {"session": 2, "tags": []}
    code, _, err = call(["tag", "1", "two words", "--db", str(db)])
    assert code == 2 and "no spaces" in err
    code, out, _ = call(["note", "1", "default gains, first try", "--db", str(db)])
    assert code == 0
    code, out, _ = call(["sessions", "--tag", "baseline", "--json", "--db", str(db)])
    assert [(r["id"], r["tags"]) for r in json.loads(out)] == [(1, ["baseline"])]
    code, out, _ = call(["show", "1", "--db", str(db)])
    assert "tags:       baseline" in out and "note:       default gains, first try" in out
    with Store(db, create=False) as store:
        rec = store.session(1)
        assert rec.tags == ("baseline",) and rec.notes[0][1] == "default gains, first try"
        store.verify_session(1)  # the edits kept the checksums


def test_compare_two_sessions(db):
    with Store(db, create=False) as store:
        comparison = store.compare_sessions(1, 2)
        first_2 = store.iterations(2)[0]
        mask = [k == "position" for k in store.maneuver(store.session(2).maneuver_id).error_kinds]
    assert {"plant", "feedback", "seed"} <= set(comparison.differences)
    assert "maneuver" not in comparison.differences
    rows = {name: (a, b) for name, a, b in comparison.rows}
    assert rows["feedback"] == ("none", "tracking") and rows["plant"] == ("nominal", "arena")
    expected = math.sqrt(sum(float(e) ** 2 for e, m in zip(first_2.error, mask, strict=True) if m))
    assert float(rows["first position error [m]"][1]) == pytest.approx(expected, abs=5e-5)
    assert len(comparison.parameters) == len(FLIP.parameters)
    code, out, _ = call(["compare", "1", "2", "--db", str(db)])
    assert code == 0 and "differs" in out and "b − a" in out
    code, out, _ = call(["compare", "1", "2", "--json", "--db", str(db)])
    assert "feedback" in json.loads(out)["differences"]


def test_delete_is_explicit_and_loses_nothing_else(db):
    with Store(db, create=False) as store:
        kept = [it.params.tolist() for it in store.iterations(1)]
    before = hashlib.sha256(db.read_bytes()).hexdigest()
    code, _, err = call(["delete", "2", "--db", str(db)])
    assert code == 2 and "pass --yes" in err and "session 2" in err
    assert hashlib.sha256(db.read_bytes()).hexdigest() == before
    code, _, err = call(["delete", "3", "--yes", "--db", str(db)])
    assert code == 2 and "belongs to study 1" in err
    code, out, _ = call(["delete", "2", "--yes", "--json", "--db", str(db)])
    assert code == 0 and json.loads(out) == {"session": 2, "deleted_iterations": 2}
    with Store(db, create=False) as store:
        assert ids(store.find_sessions(include_studies=True)) == [1, 3]
        assert [it.params.tolist() for it in store.iterations(1)] == kept
        store.verify_session(1)
        store.verify_session(3)
        assert store.integrity_check() == []
        assert len(store.study_sessions(1)) == 1
    code, _, err = call(["show", "2", "--db", str(db)])
    assert code == 2 and "no session 2" in err


def test_delete_refuses_the_source_of_a_warm_start(db):
    with Store(db) as store:
        start_session(store, FLIP, model=CONFIG, plant=PlantChoice("nominal"), iterations=1, design_result=DESIGN,
                      start_params=store.session(1).current_params, warm_start_from=1)
        with pytest.raises(ConfigError, match="warm start of session"):
            store.delete_session(1)
        assert store.session(1).n_records == 2


def test_replay_says_what_it_cannot_draw(db, tmp_path):
    with Store(db) as store:  # as a study stores its sessions: no trajectories
        for it in store.iterations(3):
            store._db.execute("UPDATE iterations SET trajectory = NULL WHERE session_id = 3 AND idx = ?",
                              (it.index,))
            checksums.update(store._db, db, "iterations", {"session_id": 3, "idx": it.index},
                             {"traj_rows": 0, "traj_cols": 0, "traj_codec": None, "traj_checksum": None})
    code, out, err = call(["replay", "last", "--db", str(db), "--out", str(tmp_path / "r")])
    assert code == 0, err
    assert "last is session 3" in out and "no measured trajectories" in out and "model's flight only" in out
    code, out, err = call(["replay", "1", "--db", str(db), "--out", str(tmp_path / "r1")])
    assert code == 0 and "note:" not in out


def test_replay_of_an_identification_shows_its_flights(tmp_path):
    db = tmp_path / "s.sqlite"
    code, _, err = call(["identify", "--plant", "nominal", "--no-flips", "--output", str(tmp_path / "v.toml"),
                         "--db", str(db)])
    assert code == 0, err
    code, out, err = call(["replay", "last", "--db", str(db), "--out", str(tmp_path / "r"), "--json"])
    assert code == 0, err
    report = json.loads(out)
    assert Path(report["replay"]).stat().st_size > 10_000
    assert any("is an identification" in note for note in report["notes"])
