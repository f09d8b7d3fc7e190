"""The built-in jobs' typed specifications (issue 43): one definition of each job's table, read back by field."""

from __future__ import annotations

import json

import pytest

from aerobat.errors import ConfigError
from aerobat.experiments.job_specs import BenchmarkJob, DesignJob, LearnJob, RuleRunJob


def test_a_spec_goes_through_json_and_back_equal():
    spec = RuleRunJob(maneuver={"kind": "flip"}, design={"p_nominal": [1.0]}, model={"name": "x"},
                      plant={"kind": "arena", "seed": 3}, method="paper", trials=8, scenario="default",
                      scheme="none")
    table = json.loads(json.dumps(spec.to_table()))
    assert list(table) == ["maneuver", "design", "model", "plant", "method", "trials", "tolerance_m", "scenario",
                           "scheme"]  # the order stored studies have
    assert RuleRunJob.from_table(table) == spec
    # a rules study's run has no scenario: the key is left out, not written as null
    assert "scenario" not in RuleRunJob(**{**spec.__dict__, "scenario": None, "scheme": None}).to_table()
    assert LearnJob.from_table({"maneuver": {}, "design": {}, "model": {}, "plant": {}}).iterations == 30
    assert DesignJob.from_table({"maneuver": {}, "model": {}}).continuation is False
    assert BenchmarkJob.from_table({"y_m": 1, "z_m": 2.5}).limits == {}


@pytest.mark.parametrize("table, message", [
    ({"design": {}, "model": {}, "plant": {}}, "learn job without its 'maneuver'"),
    ({"maneuver": {}, "design": {}, "model": {}, "plant": {}, "iterations": "30"}, r"spec.iterations: expected int"),
    ({"maneuver": {}, "design": {}, "model": {}, "plant": {}, "iterations": True}, r"expected int, got bool"),
    ({"maneuver": [], "design": {}, "model": {}, "plant": {}}, r"job spec.maneuver: expected dict"),
    ("not a table", "expected a table"),
])
def test_a_bad_table_is_refused_naming_the_field(table, message):
    with pytest.raises(ConfigError, match=message):
        LearnJob.from_table(table)


def test_a_benchmark_target_must_be_finite():
    with pytest.raises(ConfigError, match="must be finite"):
        BenchmarkJob(y_m=float("nan"), z_m=1.0)
