"""The supervisor of Fig. 8, written once (aerobat.plants.supervisor): phases, stops and measurement.

A scripted sortie moves a point vehicle at a known constant velocity through motion-capture
samples at 200 Hz; the supervisor's measurements of it are checked against the script, and each
way a trial can end early is checked for what is measured and whether the vehicle is picked up.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from aerobat.core.plant import TrialStatus
from aerobat.plants.supervisor import Phase, TrialStop, fly_phases
from aerobat.quadrotor.program import Program, Switch

_RATE_HZ = 200.0
_VELOCITY = np.array([0.5, -0.25, 1.0])  # m/s during the maneuver
_PROGRAM = Program(switches=(Switch(time_s=0.0, channel="collective", value=12.0),), duration_s=0.4).compile()


class _ScriptedSortie:
    """Hovers at the start, moves at ``_VELOCITY`` during the maneuver, stops when asked."""

    def __init__(self, stop_in: Phase | None = None, status: TrialStatus = TrialStatus.CRASHED,
                 picked_up: bool = True, samples: bool = True) -> None:
        self.start_m = np.array([1.0, 2.0, 3.0])
        self.stop_in, self.status, self.picked_up, self.samples = stop_in, status, picked_up, samples
        self.t = 0.0
        self.pos = self.start_m.copy()
        self.vel = np.zeros(3)
        self.rows: list[list[float]] = []
        self.calls: list[str] = []

    def _fly(self, seconds: float, phase: Phase) -> None:
        for _ in range(round(seconds * _RATE_HZ)):
            self.t += 1.0 / _RATE_HZ
            self.pos = self.pos + self.vel / _RATE_HZ
            if self.samples:
                self.rows.append([self.t, *self.pos, 1.0, 0.0, 0.0, 0.0])
        if phase is self.stop_in:
            raise TrialStop(self.status, f"stopped in {phase.value}", picked_up=self.picked_up)

    def take_off(self) -> None:
        self.calls.append("take_off")
        self._fly(0.5, Phase.TAKE_OFF)

    def hover(self) -> None:
        self.calls.append("hover")
        self._fly(0.2, Phase.HOVER)

    def trigger(self, compiled) -> float:
        self.calls.append("trigger")
        self._fly(0.05, Phase.TRIGGER)
        return self.t

    def maneuver(self, compiled, start_time_s: float) -> None:
        self.calls.append("maneuver")
        self.vel = _VELOCITY.copy()
        self._fly(compiled.duration_s + 0.015, Phase.MANEUVER)  # on through the estimation window
        self.vel = np.zeros(3)

    def return_to_start(self) -> None:
        self.calls.append("return_to_start")
        self._fly(0.3, Phase.RETURN)

    def land(self) -> None:
        self.calls.append("land")
        self._fly(0.2, Phase.LAND)

    def mocap(self) -> np.ndarray:
        return np.array(self.rows).reshape(-1, 8)

    def now_s(self) -> float:
        return self.t

    def pick_up(self) -> None:
        self.calls.append("pick_up")


def test_a_whole_trial_flies_every_phase_in_order_and_measures_the_maneuver_from_motion_capture():
    sortie = _ScriptedSortie()
    flown = fly_phases(sortie, _PROGRAM)
    assert flown.ok and flown.phase is Phase.LAND and flown.message == ""
    assert sortie.calls == ["take_off", "hover", "trigger", "maneuver", "return_to_start", "land"]
    assert flown.start_time_s == pytest.approx(0.75)
    # the final state: the displacement of 0.4 s at the scripted velocity, and that velocity
    np.testing.assert_allclose(flown.final_state[0:3], 0.4 * _VELOCITY, atol=1e-9)
    np.testing.assert_allclose(flown.final_state[3:6], _VELOCITY, atol=1e-9)
    # the start state's window looks 10 ms past the trigger, where the vehicle already moves: mm, not exact
    np.testing.assert_allclose(flown.start_state[0:3], 0.0, atol=5e-3)
    assert flown.times_s[0] == pytest.approx(0.0, abs=1e-9) and flown.times_s[-1] == pytest.approx(0.4)
    trial = flown.trial("flown", {"k": 1})
    assert trial.ok and trial.message == "flown" and trial.info == {"k": 1}


@pytest.mark.parametrize("phase", [Phase.TAKE_OFF, Phase.HOVER, Phase.TRIGGER])
def test_a_trial_stopped_before_the_maneuver_started_measures_nothing_and_is_picked_up(phase):
    sortie = _ScriptedSortie(stop_in=phase)
    flown = fly_phases(sortie, _PROGRAM)
    assert flown.status is TrialStatus.CRASHED and flown.phase is phase
    assert flown.message == f"stopped in {phase.value}" and flown.start_time_s is None
    assert flown.times_s.shape == (0,) and flown.states.shape[0] == 0
    assert np.isnan(flown.final_state).all() and np.isnan(flown.start_state).all()
    assert sortie.calls[-1] == "pick_up"
    assert flown.trial("never said").message == f"stopped in {phase.value}"


@pytest.mark.parametrize("phase", [Phase.MANEUVER, Phase.RETURN, Phase.LAND])
def test_a_trial_stopped_after_the_trigger_keeps_what_was_flown_from_the_start_to_the_stop(phase):
    sortie = _ScriptedSortie(stop_in=phase)
    flown = fly_phases(sortie, _PROGRAM)
    assert flown.status is TrialStatus.CRASHED and flown.phase is phase
    assert flown.start_time_s == pytest.approx(0.75)
    assert flown.times_s[-1] == pytest.approx(sortie.t - 0.75)  # up to the stop
    np.testing.assert_allclose(flown.states[-1, 0:3], sortie.pos - sortie.start_m, atol=1e-12)
    assert np.isnan(flown.final_state).all()
    assert sortie.calls[-1] == "pick_up"


def test_a_lost_trigger_measures_nothing_and_a_vehicle_flown_back_is_not_picked_up():
    sortie = _ScriptedSortie(stop_in=Phase.MANEUVER, status=TrialStatus.NO_TRIGGER, picked_up=False)
    flown = fly_phases(sortie, _PROGRAM)
    assert flown.status is TrialStatus.NO_TRIGGER and flown.times_s.shape == (0,)
    assert "pick_up" not in sortie.calls


def test_without_motion_capture_samples_the_trial_is_aborted_not_ok():
    sortie = _ScriptedSortie(samples=False)
    flown = fly_phases(sortie, _PROGRAM)
    assert flown.status is TrialStatus.ABORTED and flown.phase is Phase.LAND
    assert flown.message == "too few motion-capture samples to estimate the final state"
    assert flown.trial("flown").message == flown.message


def test_an_error_that_is_not_a_trial_stop_is_the_plants_to_handle():
    class Lost(_ScriptedSortie):
        def hover(self) -> None:
            raise ConnectionError("the firmware stopped answering")

    with pytest.raises(ConnectionError):
        fly_phases(Lost(), _PROGRAM)


_PLANTS = Path(__file__).resolve().parents[2] / "src" / "aerobat" / "plants"


def _called(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    return {node.func.id if isinstance(node.func, ast.Name) else node.func.attr for node in ast.walk(tree)
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name | ast.Attribute)}


@pytest.mark.parametrize("module", ["arena/arena.py", "rotorpy/plant.py", "fpv/phases.py"])
def test_the_arena_rotorpy_and_the_betaflight_pilot_fly_through_the_one_supervisor(module):
    assert "fly_phases" in _called(_PLANTS / module)


def test_both_betaflight_plants_fly_the_one_pilot_and_no_plant_measures_a_trial_itself():
    from aerobat.plants.betaflight.plant import BetaflightPlant
    from aerobat.plants.fc.plant import FlightControllerPlant
    from aerobat.plants.fpv.radio_plant import RadioPlant

    assert issubclass(BetaflightPlant, RadioPlant) and issubclass(FlightControllerPlant, RadioPlant)
    assert not issubclass(FlightControllerPlant, BetaflightPlant)
    for package in ("arena", "rotorpy", "betaflight", "fc", "fpv"):
        for path in sorted((_PLANTS / package).glob("*.py")):
            assert not _called(path) & {"estimate_final_state", "measured_states"}, path
