"""Durable sessions as a library call (aerobat.experiments.sessions): stored, resumed exactly, every rule."""

from __future__ import annotations

import math

import numpy as np
import pytest

from aerobat.core.design import design
from aerobat.core.learning import Learner
from aerobat.core.rules import RuleChoice
from aerobat.errors import ConfigError, DesignFailed
from aerobat.experiments import resume_session, start_session
from aerobat.plants import PlantChoice
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel
from aerobat.quadrotor.vehicle import VehicleParams, hummingbird
from aerobat.store import Store, checksums

CONFIG = hummingbird()
FLIP = MultiFlip(vehicle=CONFIG.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
DESIGN = design(FLIP, NominalModel(CONFIG))


def _records(store: Store, session_id: int) -> list[tuple]:
    return [(it.index, it.status, it.params.tobytes(), it.next_params.tobytes(), it.error.tobytes(), it.gamma,
             it.scale) for it in store.iterations(session_id)]


@pytest.mark.parametrize("rule", ["paper", "tsvd", "damped", "kalman", "broyden", "tsvd+isc", "kalman+isc"])
def test_a_resumed_session_repeats_an_uninterrupted_one_bit_for_bit(tmp_path, rule):
    choice = RuleChoice.parse(rule)
    plant = PlantChoice("arena", seed=5)
    with Store(tmp_path / "a.sqlite") as store:
        whole = start_session(store, FLIP, model=CONFIG, plant=plant, rule=choice, iterations=6,
                              design_result=DESIGN)
        assert whole.run().completed
        part = start_session(store, FLIP, model=CONFIG, plant=plant, rule=choice, iterations=6,
                             design_result=DESIGN)
        stops = iter([False, False, False, True])  # stop after the third trial, as Ctrl-C does
        outcome = part.run(should_stop=lambda: next(stops, True))
        assert outcome.status.value == "interrupted" and outcome.measured == 3
    with Store(tmp_path / "a.sqlite") as store:  # another process, later
        resumed = resume_session(store, part.id)
        assert resumed.exact and resumed.measured == 3
        assert resumed.run().completed
        assert _records(store, part.id) == _records(store, whole.id)
        assert np.array_equal(store.session(part.id).current_params, store.session(whole.id).current_params)


def test_each_iteration_stores_the_step_actually_applied_in_one_commit(tmp_path, monkeypatch):
    """Defect 3: next_params was rebuilt from the un-held step and patched in a second transaction,
    so a kill between the two commits resumed from the wrong parameters."""
    lower = FLIP.parameters[2].lower
    start = DESIGN.p_nominal.copy()
    start[2] = lower  # the coast duration starts at its bound: corrections push it out and it is held
    commits: list[str] = []
    write = Store._write

    def counting(self, action, fn, **kwargs):
        commits.append(action)
        return write(self, action, fn, **kwargs)

    with Store(tmp_path / "a.sqlite") as store:
        run = start_session(store, FLIP, model=CONFIG, plant=PlantChoice("arena", seed=2), iterations=5,
                            design_result=DESIGN, start_params=start)
        monkeypatch.setattr(Store, "_write", counting)
        run.run()
        monkeypatch.setattr(Store, "_write", write)
        n = store.session(run.id).n_records
        assert len(commits) == n + 1, commits  # one per iteration, and closing the session
        records = store.iterations(run.id)
        held = [it for it in records if "held at a bound" in it.message]
        for before, after in zip(records, records[1:], strict=False):
            assert np.array_equal(after.params, before.next_params)  # what was stored is what flew next
        last = store.last_iteration(run.id)
        assert last is not None and last.learner_state is not None
        assert np.array_equal(np.array(last.learner_state["params"]), last.next_params)
    assert held, "the test needs a held parameter: the stored step must be the held one"
    for it in held:
        assert it.next_params[2] == it.params[2]


def test_learner_step_is_what_was_applied():
    learner = Learner(FLIP, DESIGN)
    from aerobat.plants import Arena

    plant = Arena(CONFIG, seed=1)
    for _ in range(3):
        before = learner.ask()
        record = learner.tell(plant.fly(learner.program()))
        assert np.array_equal(record.params, before)
        assert np.array_equal(record.next_params, learner.ask())


def test_a_design_that_does_not_converge_is_refused_unless_forced(tmp_path):
    weak = VehicleParams(collective_reduced_max_m_s2=11.0)
    config = hummingbird()
    import dataclasses

    config = dataclasses.replace(config, vehicle=weak)
    flip = MultiFlip(vehicle=weak, flips=3, dims=2)
    with Store(tmp_path / "a.sqlite") as store:
        with pytest.raises(DesignFailed, match="force"):
            start_session(store, flip, model=config, plant=PlantChoice("nominal"), iterations=2)
        assert store.list_sessions() == []


def test_resume_refuses_a_completed_session_and_accepts_a_higher_target(tmp_path):
    with Store(tmp_path / "a.sqlite") as store:
        run = start_session(store, FLIP, model=CONFIG, plant=PlantChoice("nominal"), iterations=2,
                            design_result=DESIGN)
        assert run.run().completed
        with pytest.raises(ConfigError, match="already has 2 of 2"):
            resume_session(store, run.id)
        more = resume_session(store, "last", iterations=4)
        assert more.run().measured == 4


def test_a_stored_session_loads_back_and_its_json_round_trips(tmp_path):
    import json

    from aerobat.experiments.reports import load_session, session_from_json, session_json

    with Store(tmp_path / "a.sqlite") as store:
        run = start_session(store, FLIP, model=CONFIG, plant=PlantChoice("arena", seed=2),
                            rule=RuleChoice.parse("paper"), iterations=3, design_result=DESIGN)
        assert run.run().completed
        loaded = load_session(store, run.id)
        data = json.loads(json.dumps(session_json(store, run.id, full=True)))
        assert np.array_equal(loaded.final_params, store.session(run.id).current_params)
    assert loaded.status.value == "completed" and len(loaded.iterations) == 3
    again = session_from_json(data)
    assert again.status == loaded.status
    for a, b in zip(again.iterations, loaded.iterations, strict=True):
        assert np.array_equal(a.params, b.params) and np.array_equal(a.next_params, b.next_params)
        assert np.allclose(a.error, b.error, equal_nan=True)
    with pytest.raises(ConfigError, match="session JSON"):
        session_from_json({"maneuver": data["maneuver"]})


def test_a_session_recorded_before_the_reciprocal_kernels_resumes_and_says_it_is_not_bit_for_bit(tmp_path):
    import sqlite3

    path = tmp_path / "a.sqlite"
    with Store(path) as store:
        run = start_session(store, FLIP, model=CONFIG, plant=PlantChoice("arena", seed=5), iterations=4,
                            design_result=DESIGN)
        stops = iter([False, True])
        assert run.run(should_stop=lambda: next(stops, True)).measured == 1
        current = resume_session(store, run.id)
        assert current.exact and current.inexact_because == ""  # recorded by this aerobat
    with sqlite3.connect(path) as conn:  # as aerobat 0.2.0 (divisions in the kernels) wrote it
        checksums.update(conn, path, "sessions", {"id": run.id}, {"aerobat_version": "0.2.0"})
    with Store(path) as store:
        old = resume_session(store, run.id, take_over=True)
        assert not old.exact and "aerobat 0.2.0" in old.inexact_because and "not bit for bit" in old.inexact_because
        assert old.run().completed  # it continues all the same
