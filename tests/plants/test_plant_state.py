"""The lab plants' shared state between trials (aerobat.plants.plant_state)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aerobat.plants.plant_state import FORMAT, StateLayout

LAYOUT = StateLayout("demo", counters=("trials_flown", "tick"), fractions=("capacity",))
SIZES = {"x": 3, "vehicle.q": 4}


def _encoded(rng: np.random.Generator) -> dict:
    arrays = {"x": np.array([1.0, 2.0, 3.0]), "vehicle.q": np.array([1.0, 0.0, 0.0, 0.0])}
    return LAYOUT.encode(rng, {"trials_flown": 4, "tick": 17}, {"capacity": 0.5}, arrays)


def test_round_trip_through_json_restores_the_generator_and_values() -> None:
    rng = np.random.default_rng(7)
    rng.standard_normal(5)
    state = json.loads(json.dumps(_encoded(rng)))
    assert state["format"] == FORMAT and state["vehicle"] == {"q": [1.0, 0.0, 0.0, 0.0]}
    expected = rng.standard_normal(3)
    fresh = np.random.default_rng(0)
    read = LAYOUT.decode(state, fresh, SIZES)
    assert fresh.standard_normal(1) == np.random.default_rng(0).standard_normal(1)  # decode changes nothing
    fresh.bit_generator.state = read.rng
    np.testing.assert_array_equal(fresh.standard_normal(3), expected)
    assert read.counters == {"trials_flown": 4, "tick": 17} and read.fractions == {"capacity": 0.5}
    np.testing.assert_array_equal(read.arrays["vehicle.q"], [1.0, 0.0, 0.0, 0.0])


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda s: [1, 2], "demo state: expected a table, got list"),
        (lambda s: {k: v for k, v in s.items() if k != "tick"}, "demo state: missing field(s) tick"),
        (lambda s: {k: v for k, v in s.items() if k != "vehicle"}, "demo state: missing field(s) vehicle"),
        (lambda s: {**s, "format": 2}, "demo state.format = 2: this aerobat reads format 1"),
        (lambda s: {**s, "rng": {"bit_generator": "MT19937"}}, "demo state.rng: expected a PCG64 generator state"),
        (lambda s: {**s, "tick": -1}, "demo state.tick = -1: expected an integer >= 0"),
        (lambda s: {**s, "trials_flown": True}, "demo state.trials_flown = True: expected an integer >= 0"),
        (lambda s: {**s, "capacity": 1.5}, "demo state.capacity = 1.5: expected a number in (0, 1]"),
        (lambda s: {**s, "x": [1.0]}, "demo state.x: expected 3 numbers, got 1"),
        (lambda s: {**s, "x": ["a", 1, 2]}, "demo state.x: expected a list of numbers"),
        (lambda s: {**s, "x": [1.0, float("nan"), 2.0]}, "demo state.x: expected finite numbers"),
        (lambda s: {**s, "vehicle": 3}, "demo state.vehicle: expected a table"),
    ],
)
def test_a_damaged_state_names_its_field(change, message: str) -> None:
    rng = np.random.default_rng(1)
    before = rng.bit_generator.state
    with pytest.raises(ValueError) as caught:
        LAYOUT.decode(change(_encoded(rng)), rng, SIZES)
    assert str(caught.value) == message
    assert rng.bit_generator.state == before


def test_an_array_stored_one_shorter_is_padded_and_non_finite_allowed_when_declared() -> None:
    rng = np.random.default_rng(1)
    lenient = StateLayout("demo", counters=("trials_flown", "tick"), fractions=("capacity",), finite=False)
    state = {**_encoded(rng), "x": [1.0, float("inf")]}
    read = lenient.decode(state, rng, SIZES, padding={"x": 0.0})
    np.testing.assert_array_equal(read.arrays["x"], [1.0, np.inf, 0.0])


def test_every_stateful_lab_plant_uses_the_shared_layout() -> None:
    """get_state/set_state is written once: each plant module declares a StateLayout."""
    from aerobat.plants.arena import arena
    from aerobat.plants.betaflight import plant as betaflight
    from aerobat.plants.rotorpy import plant as rotorpy

    for module in (arena, betaflight, rotorpy):
        assert isinstance(module._LAYOUT, StateLayout), module.__name__
        source = open(module.__file__).read()
        assert '"format": 1' not in source and "bit_generator.state = {" not in source, module.__name__
