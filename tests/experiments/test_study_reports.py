"""Study reports from the library: one call runs a study and returns its rows, CSV and figures.

The same report is built again from the store alone (``study_report``), and the command line's
files are the library's (``aerobat study feedback`` writes what ``feedback_study(...).to_csv()``
gives, wall times apart).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math

import numpy as np
import pytest

from aerobat import MultiFlip, NominalModel, PlantChoice, Store, design, hummingbird
from aerobat.errors import ConfigError
from aerobat.experiments.execution import LocalExecutor
from aerobat.experiments.studies import (
    EnvelopeReport,
    FeedbackReport,
    RobustnessReport,
    RulesReport,
    StudyReport,
    envelope_study,
    feedback_study,
    robustness_study,
    rules_study,
    study_report,
)
from aerobat.quadrotor.feedback import FeedbackScheme

WALL_COLUMNS = {"wall_ms_per_trial", "wall_s"}


@pytest.fixture(scope="module")
def pool():
    executor = LocalExecutor(2)
    yield executor
    executor.close()


@pytest.fixture(scope="module")
def flip():
    config = hummingbird()
    maneuver = MultiFlip(vehicle=config.vehicle, flips=1, max_rate_rad_s=math.radians(1200), dims=2)
    nominal = design(maneuver, NominalModel(config))
    assert nominal.converged
    return config, maneuver, nominal


def _table(text: str) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(text)))


def _without_wall(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    return [{k: v for k, v in row.items() if k not in WALL_COLUMNS} for row in rows]


def test_feedback_study_in_one_call_and_again_from_the_store(tmp_path, pool, flip):
    config, maneuver, nominal = flip
    with Store(tmp_path / "s.sqlite") as store:
        report = feedback_study(store, maneuver, nominal, config, schemes=[FeedbackScheme.NONE, "attitude"],
                                scenarios=["default", "lossy-link"], seeds=1, trials=3,
                                plant=PlantChoice("arena", seed=4), executor=pool)
        stored = study_report(store, report.study_id)
    assert isinstance(report, FeedbackReport) and isinstance(report, StudyReport)
    assert report.outcome.ran == 4 and report.outcome.skipped == 0 and not report.outcome.failed
    assert [(r.scenario, r.scheme) for r in report.rows] == [
        ("default", "none"), ("default", "attitude"), ("lossy-link", "none"), ("lossy-link", "attitude")]
    for row in report.rows:
        assert row.runs == 1 and row.failures == 0 and row.job_errors == ()
        assert 0.0 < row.last10_mean_m < 5.0 and row.last10_mean_m == row.last10_worst_seed_m
        assert row.last10_angle_deg and all(a >= 0 for a in row.last10_angle_deg)
    table = _table(report.to_csv())
    assert list(table[0]) == [f.name for f in dataclasses.fields(type(report.rows[0]))]
    assert len(report.curves["default"]["none"][0]) == 3  # one position error per trial
    # built from the store alone: the same rows, none of them run now
    assert stored.rows == report.rows and stored.to_csv() == report.to_csv()
    assert stored.outcome.ran == 0 and stored.outcome.skipped == 4
    written = report.write(tmp_path / "out")
    assert [p.name for p in written] == ["feedback.csv", "feedback.png"] and all(p.stat().st_size for p in written)
    assert (tmp_path / "out" / "feedback.csv").read_bytes().decode() == report.to_csv()


def test_the_command_line_writes_the_library_report(tmp_path, pool, flip):
    from aerobat.cli import main

    config, maneuver, nominal = flip
    with Store(tmp_path / "lib.sqlite") as store:
        report = feedback_study(store, maneuver, nominal, config, schemes=["none"], scenarios=["default"], seeds=2,
                                trials=3, plant=PlantChoice("arena"), executor=pool)
    code = main(["study", "feedback", "flip", "--flips", "1", "--dims", "2", "--max-rate-deg-s", "1200",
                 "--schemes", "none", "--scenarios", "default", "--seeds", "2", "--trials", "3", "--workers", "2",
                 "--db", str(tmp_path / "cli.sqlite"), "--out", str(tmp_path / "cli")])
    assert code == 0
    cli_rows = _table((tmp_path / "cli" / "feedback.csv").read_text())
    assert _without_wall(cli_rows) == _without_wall(_table(report.to_csv()))
    with Store(tmp_path / "cli.sqlite") as cli_store, Store(tmp_path / "lib.sqlite") as lib_store:
        assert cli_store.study(1).spec == lib_store.study(1).spec  # resumable from either side


def test_rules_study_rows_and_stored_report(tmp_path, pool, flip):
    config, maneuver, nominal = flip
    with Store(tmp_path / "s.sqlite") as store:
        report = rules_study(store, maneuver, nominal, config, methods=["paper", "tsvd"], seeds=2, trials=4,
                             plant=PlantChoice("arena", seed=2), executor=pool)
        stored = study_report(store, "last")
    assert isinstance(report, RulesReport)
    assert [r.method for r in report.rows] == ["paper", "tsvd"]
    assert all(r.runs == 2 and r.failures == 0 for r in report.rows)
    assert [len(c) for c in report.curves["paper"]] == [4, 4]
    assert stored.rows == report.rows
    assert [row["method"] for row in _table(report.to_csv())] == ["paper", "tsvd"]


def test_rules_study_refuses_an_unknown_method_before_a_job_runs(tmp_path, flip):
    config, maneuver, nominal = flip
    with Store(tmp_path / "s.sqlite") as store:
        with pytest.raises(ConfigError, match="nosuchrule"):
            rules_study(store, maneuver, nominal, config, methods=["nosuchrule"], seeds=1, trials=2,
                        plant=PlantChoice("arena"))
        assert store.list_studies() == []


def test_robustness_study_json_and_stored_report(tmp_path, pool, flip):
    config, maneuver, nominal = flip
    with Store(tmp_path / "s.sqlite") as store:
        report = robustness_study(store, maneuver, nominal, config, vehicles=3, iterations=4, seed=7, executor=pool)
        stored = study_report(store, report.study_id)
    assert isinstance(report, RobustnessReport)
    assert report.ran == 3 and report.skipped == 0 and report.failed == ()
    assert len(report.rows) == 3 and {r.key for r in report.rows} == set(report.outcome.results)
    for row in report.rows:
        assert math.isfinite(row.final_error_m) and set(row.properties) == set(report.properties)
    summary = report.to_json()
    assert summary["vehicles"] == 3 and summary["learned"] == 3 and summary["ran"] == 3
    again = stored.to_json()
    assert {**again, "ran": 3, "skipped": 0} == summary
    table = _table(report.to_csv())
    assert list(table[0])[:4] == ["key", "success", "trials_to_tolerance", "final_error_m"]


def test_envelope_study_grid_and_refused_ranges(tmp_path, pool):
    config = hummingbird()
    with Store(tmp_path / "s.sqlite") as store:
        report = envelope_study(store, config, flips=[1, 2], rates_deg_s=[900.0, 1800.0], dims=2, executor=pool)
        stored = study_report(store, report.study_id)
        with pytest.raises(ConfigError, match=r"^flips\[0\] = 0 is out of range: allowed 1 … 10$"):
            envelope_study(store, config, flips=[0], rates_deg_s=[900.0])
        with pytest.raises(ConfigError, match=r"^rates_deg_s\[0\] = 6000 is out of range: allowed "
                                              r"\[28.6479, 5729.58\] \(deg/s\)$"):
            envelope_study(store, config, flips=[1], rates_deg_s=[6000.0])
    assert isinstance(report, EnvelopeReport)
    assert report.feasible.shape == (2, 2) and np.all(report.feasible == 1.0)
    assert [(c.flips, c.max_rate_deg_s) for c in report.rows] == [(1, 900.0), (1, 1800.0), (2, 900.0), (2, 1800.0)]
    assert all(c.duration_s is not None and c.duration_s > 0 for c in report.rows)
    assert stored.to_json() == report.to_json()
    np.testing.assert_array_equal(stored.feasible, report.feasible)
