"""The library's entry points refuse what they cannot use with aerobat's errors (issue 31: H4, S3, I7)."""

from __future__ import annotations

import numpy as np
import pytest

from aerobat.errors import ConfigError
from aerobat.store import Store


class _CountingPlant:
    """A plant that must not be flown: the test fails (instead of running for ever) if it is."""

    name = "counting"

    def __init__(self) -> None:
        self.flights = 0

    def fly(self, program):
        self.flights += 1
        raise AssertionError("learn flew a trial before refusing its arguments")


@pytest.fixture(scope="module")
def small_flip():
    from aerobat import MultiFlip, NominalModel, design, hummingbird

    config = hummingbird()
    flip = MultiFlip(vehicle=config.vehicle, flips=1, dims=2)
    return flip, design(flip, NominalModel(config))


@pytest.mark.parametrize("options, fragment", [
    ({"iterations": 2**40}, "iterations = 1099511627776 is out of range: allowed 1 … 10000"),
    ({"iterations": 10_001}, "iterations = 10001 is out of range: allowed 1 … 10000"),
    ({"iterations": 0}, "iterations = 0 is out of range: allowed 1 … 10000"),
    ({"iterations": 5, "max_attempts": 2**40}, "max_attempts = 1099511627776 is out of range: allowed 1 … 30010"),
])
def test_learn_refuses_a_count_it_cannot_hold_before_flying(small_flip, options, fragment):
    """H4: every record is kept for the returned session; 2**40 iterations grew memory until MemoryError."""
    from aerobat import learn

    flip, nominal = small_flip
    plant = _CountingPlant()
    with pytest.raises(ConfigError) as info:
        learn(flip, nominal, plant, **options)
    assert str(info.value) == fragment
    assert plant.flights == 0


def test_learn_still_takes_its_largest_count(small_flip):
    from aerobat import NominalPlant, hummingbird, learn

    flip, nominal = small_flip
    stops = []
    session = learn(flip, nominal, NominalPlant(hummingbird()), iterations=10_000,
                    should_stop=lambda: stops.append(1) or len(stops) > 3)
    assert session.status.value == "interrupted" and len(session.iterations) == 3


@pytest.mark.parametrize("kind", [None, float("nan"), object(), 3, "", "9lives", "a b", "x" * 65, "ok\n"])
def test_run_study_refuses_a_kind_that_is_not_a_name_and_stores_nothing(tmp_path, kind):
    """S3: run_study(store, None, {}, []) stored a study of kind 'None' ('nan', an object's repr)."""
    from aerobat import run_study

    with Store(tmp_path / "s.sqlite") as store:
        with pytest.raises(ConfigError, match=r"^study kind = .*: expected a name of 1 … 64 letters"):
            run_study(store, kind, {}, [], workers=1)
        assert store.list_studies() == []


@pytest.mark.parametrize("spec, jobs, fragment", [
    ([("a", 1)], [], "study envelope spec: expected a mapping of the study's options (a dict), got list"),
    (5, [], "study envelope spec: expected a mapping of the study's options (a dict), got int 5"),
    (None, [], "study envelope spec: expected a mapping"),
    ({(1, 2): 3}, [], "study envelope spec: not JSON-ready"),
    ({"vehicle": object()}, [], "study envelope spec: not JSON-ready (numbers, strings, lists and dicts): object"),
    ({}, "ab", "study envelope jobs: expected a sequence of Job, got str 'ab'"),
    ({}, None, "study envelope jobs: expected a sequence of Job, got NoneType None"),
    ({}, [1], "study envelope jobs: expected Job items, got int 1"),
])
def test_run_study_refuses_what_is_not_a_study_with_aerobats_error(tmp_path, spec, jobs, fragment):
    """I7: a non-mapping spec raised TypeError or AttributeError from inside."""
    from aerobat import run_study

    with Store(tmp_path / "s.sqlite") as store:
        with pytest.raises(ConfigError) as info:
            run_study(store, "envelope", spec, jobs, workers=1)
        assert str(info.value).startswith(fragment), str(info.value)
        assert store.list_studies() == []


def test_run_study_keeps_a_numpy_spec_and_the_callbacks_are_checked(tmp_path):
    from aerobat import run_study

    with Store(tmp_path / "s.sqlite") as store:
        outcome = run_study(store, "envelope", {"rates": np.linspace(1.0, 2.0, 3), "n": np.int64(2)}, [], workers=1)
        assert store.study(outcome.study_id).spec == {"rates": [1.0, 1.5, 2.0], "n": 2}
        for options, fragment in (({"progress": 5}, "progress = 5: expected a function"),
                                  ({"resume": True}, "resume = True: expected a study id"),
                                  ({"command": "aerobat study"}, "command = 'aerobat study': expected a sequence")):
            with pytest.raises(ConfigError, match=fragment):
                run_study(store, "envelope", {}, [], workers=1, **options)


@pytest.mark.parametrize("name", [np.array([1.0, 2.0]), np.array(["hummingbird"]), ["hummingbird"], None, b"fpv5"])
def test_preset_refuses_what_is_not_a_name(name):
    """I7: preset(np.array([1., 2.])) raised ValueError (an array compared element by element)."""
    from aerobat import preset

    with pytest.raises(ConfigError, match=r"^vehicle preset: expected a name, one of hummingbird, .*; got "):
        preset(name)
