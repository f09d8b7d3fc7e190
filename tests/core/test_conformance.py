"""The conformance kit (aerobat.core.testing) over every registered maneuver, plant and update rule.

A new maneuver kind, plant or rule without an example here fails the first test of its group,
so nothing registered goes unchecked.
"""

from __future__ import annotations

import importlib
import math
from pathlib import Path

import numpy as np
import pytest

from aerobat.core.design import design
from aerobat.core.registry import from_spec, registered_kinds
from aerobat.core.rules import RULES, IscModel, make_rule
from aerobat.core.testing import ToyManeuver, ToyModel, ToyPlant, check_maneuver, check_plant, check_rule
from aerobat.firmware.betaflight.errors import FirmwareUnavailable
from aerobat.plants import BUILT_IN, PLANTS, PlantChoice
from aerobat.quadrotor.maneuvers import MultiFlip, load_maneuver_file, translation_maneuver
from aerobat.quadrotor.simulate import NominalModel
from aerobat.quadrotor.vehicle import hummingbird

CONFIG = hummingbird()
FLIP = MultiFlip(vehicle=CONFIG.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "maneuvers"
MANEUVERS = {
    "flip": lambda: MultiFlip(vehicle=CONFIG.vehicle, flips=3, dims=3),
    "staged": lambda: load_maneuver_file(EXAMPLES / "flip_sideways.toml", CONFIG.vehicle),
    "translation": lambda: translation_maneuver(CONFIG, (2.0, 1.0)),
    "toy": ToyManeuver,
}


def test_every_maneuver_kind_has_an_example():
    known = set(registered_kinds()) - {"test_hop"}  # the test plugin package's own kind (test_maneuver_files.py)
    assert known <= set(MANEUVERS), known - set(MANEUVERS)


@pytest.mark.parametrize("kind", sorted(MANEUVERS))
def test_maneuver_conforms(kind):
    maneuver = MANEUVERS[kind]()
    model = ToyModel() if kind == "toy" else NominalModel(CONFIG)
    result = check_maneuver(maneuver, model=model, rebuild=from_spec)
    assert result is not None and result.converged


def test_every_plant_has_a_check():
    # the built-in plants (a plant a test module registers, tests/plants/test_a_plant_defined_in_a_test.py,
    # runs the kit in its own file)
    built_in = {importlib.import_module(module).SPEC.name for module in BUILT_IN}
    assert built_in == {"nominal", "arena", "rotorpy", "betaflight", "fc"} and built_in <= set(PLANTS.names())


@pytest.mark.parametrize("kind", ["nominal", "arena", "rotorpy", "betaflight",
                                  pytest.param("fc", marks=pytest.mark.xdist_group("real_time"))])  # fc: rehearsal
def test_plant_conforms(kind):
    choice = PlantChoice(kind, seed=4)
    try:
        choice.spec.check_available()
        plant = choice.build(CONFIG)
    except (ImportError, FirmwareUnavailable) as exc:
        pytest.skip(str(exc))
    p0 = design(FLIP, NominalModel(CONFIG)).p_nominal
    trial = check_plant(plant, FLIP, params=p0)
    assert trial.ok, trial.message


TOY = ToyManeuver()
TOY_DESIGN = design(TOY, ToyModel())
TOY_ISC = IscModel(np.array([[1.0, 0.0], [0.0, 1.0]]), lambda trial, params: np.asarray(trial.start_state))


def test_every_rule_is_checked():
    assert set(RULES.names()) == {"paper", "tsvd", "damped", "kalman", "broyden"}


@pytest.mark.parametrize("label", [*sorted(RULES.names()), *(f"{name}+isc" for name in sorted(RULES.names()))])
def test_rule_conforms_and_resumes_exactly_from_its_state(label):
    options = {"isc": TOY_ISC} if label.endswith("+isc") else {}
    check_rule(lambda: make_rule(label, TOY_DESIGN, **options), TOY, ToyPlant(seed=7, noise_m=0.01), TOY_DESIGN,
               trials=8)


def test_the_kit_catches_a_broken_maneuver():
    class Broken(ToyManeuver):
        def guess(self) -> np.ndarray:
            return np.array([2.0, 0.5])  # one parameter short

    with pytest.raises(AssertionError, match="guess"):
        check_maneuver(Broken())


def test_the_kit_catches_a_rule_that_forgets_its_state():
    from aerobat.core.rules import KalmanRule

    class Forgetful(KalmanRule):
        def load_state(self, state):  # loads nothing: a resumed run starts from scratch
            return None

    with pytest.raises(AssertionError, match="resumed"):
        check_rule(lambda: Forgetful(TOY_DESIGN), TOY, ToyPlant(seed=2, noise_m=0.01), TOY_DESIGN, trials=8)


def test_a_plant_declares_whether_its_trials_repeat_on_the_protocol():
    """``repeatable`` is declared on a protocol (issue 43), not read by name: a plant without it repeats exactly."""
    from aerobat.core.plant import MaybeRepeatablePlant, repeats_exactly
    from aerobat.plants.fc.plant import FlightControllerPlant

    class Simulated:
        name = "simulated"

        def fly(self, program):
            raise AssertionError("not flown")

    class OnTheWallClock(Simulated):
        repeatable = False

    assert repeats_exactly(Simulated()) and not isinstance(Simulated(), MaybeRepeatablePlant)
    assert not repeats_exactly(OnTheWallClock()) and isinstance(OnTheWallClock(), MaybeRepeatablePlant)
    assert FlightControllerPlant.repeatable is False
