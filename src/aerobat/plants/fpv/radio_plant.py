"""What both plants flown by radio share: the vehicle, the firmware's settings, the pilot, the trial-to-trial state.

:class:`RadioPlant` is the base of the lockstep plant (:class:`aerobat.plants.betaflight.plant.BetaflightPlant`)
and of the flight controller on the wall clock (:class:`aerobat.plants.fc.plant.FlightControllerPlant`).
Each opens its own kind of flight and says how it kept time; the phases are the
:class:`~aerobat.plants.fpv.phases.RadioPilot`'s, measured by the one supervisor.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from aerobat.config import check_type
from aerobat.core.plant import Trial
from aerobat.firmware.betaflight.settings import BetaflightSettings, load_settings
from aerobat.plants.fpv.params import BetaflightParams
from aerobat.plants.fpv.phases import RadioFlight, RadioPilot, signals_of
from aerobat.plants.plant_state import StateLayout
from aerobat.plants.supervisor import Phase
from aerobat.quadrotor.dynamics import N_STATE
from aerobat.quadrotor.feedback import Feedback, FeedbackScheme, as_feedback
from aerobat.quadrotor.program import CompiledProgram
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["RadioPlant"]

# stored sessions of both plants hold this format (it was the Betaflight plant's before fc had its own class)
_LAYOUT = StateLayout("betaflight", counters=("trials_flown",), fractions=("capacity",))


class RadioPlant:
    """A plant whose vehicle a :class:`~aerobat.plants.fpv.phases.RadioPilot` flies through Betaflight.

    Parameters
    ----------
    config : the *nominal* vehicle (the design model), used for g.
    params : the plant's settings (:class:`~aerobat.plants.fpv.params.BetaflightParams`).
    seed : seeds the plant's generator.
    settings : the firmware's settings; None: the packaged ``settings.toml`` with the airframe's
        propeller direction. Settings given are taken as they are (a real board's are its own).
        Either way a tune in ``params`` is applied unless the settings carry one.
    feedback : what the offboard pilot mixes into the program's sticks (:mod:`aerobat.quadrotor.feedback`).
    design_model : the vehicle the programs were designed on, if not ``config``: the feedback tracks its flight.
    """

    def __init__(self, config: VehicleConfig, params: BetaflightParams | None, *, seed: int,
                 settings: BetaflightSettings | None, feedback: Feedback | FeedbackScheme | str | None,
                 design_model: VehicleConfig | None) -> None:
        self.config = config
        self.design_model = config if design_model is None else check_type(
            "design_model", design_model, VehicleConfig, "a VehicleConfig or None")
        self.params = params or BetaflightParams()
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.trials_flown = 0
        self.capacity = 1.0
        self.settings = settings or load_settings()
        self.tune_report = None
        if self.params.tune is not None and self.settings.tune is None:
            from aerobat.firmware.betaflight.translate import translate

            self.tune_report = translate(self.params.tune)
            self.settings = self.settings.with_tune(self.tune_report)
        if settings is None:
            self.settings = self.settings.with_props(self.params.airframe.props_out)
        self.gravity = config.vehicle.gravity_m_s2
        self.last_truth: tuple[np.ndarray, np.ndarray] = (np.empty(0), np.empty((0, N_STATE)))
        self.flight: Any = None  # the flight in progress (for fault injection, diagnosis, the operator's kill)
        self.feedback = as_feedback(feedback)
        self.pilot = RadioPilot(self.params, self.settings, gravity_m_s2=self.gravity, start_m=np.zeros(3),
                                feedback=self.feedback, design_model=self.design_model)

    @property
    def start_m(self) -> np.ndarray:
        """The maneuver start in the motion-capture frame [m] (the pilot's)."""
        return self.pilot.start_m

    @start_m.setter
    def start_m(self, value: np.ndarray) -> None:
        self.pilot.start_m = np.array(value, dtype=float)

    # ---------------------------------------------------------------- state
    def get_state(self) -> dict[str, Any]:
        """What changes from trial to trial: ``format``, ``rng``, ``trials_flown``, ``capacity`` (JSON-ready)."""
        return _LAYOUT.encode(self.rng, {"trials_flown": self.trials_flown}, {"capacity": self.capacity}, {})

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`get_state` (of a plant built with the same arguments).

        Raises
        ------
        ValueError
            A field is missing or of the wrong type, or the generator kind differs.
        """
        read = _LAYOUT.decode(state, self.rng, {})
        self.rng.bit_generator.state = read.rng
        self.trials_flown = read.counters["trials_flown"]
        self.capacity = read.fractions["capacity"]

    def reset_drift(self) -> None:
        """A fresh battery: thrust capacity back to 100 %."""
        self.capacity = 1.0

    # ---------------------------------------------------------------- trial
    def _timing(self, flight: Any, wall: float) -> dict[str, Any]:
        """How the flight kept time (the plant's own fields)."""
        raise NotImplementedError

    def _ok_message(self, info: dict[str, Any]) -> str:
        """What an ``ok`` trial says, from its ``info``."""
        raise NotImplementedError

    def _fly(self, flight: RadioFlight, compiled: CompiledProgram, info: dict[str, Any], wall: float) -> Trial:
        """The pilot's phases (:meth:`~aerobat.plants.fpv.phases.RadioPilot.fly`) on ``flight``, as a trial."""
        flown, truth = self.pilot.fly(flight, compiled, info)
        start = flown.start_time_s
        if truth and start is not None:
            rows = np.array(truth)
            self.last_truth = (rows[:, 0] - start, rows[:, 1:1 + N_STATE])
        else:
            self.last_truth = (np.empty(0), np.empty((0, N_STATE)))
        if flown.phase is Phase.LAND:
            info["frames_sent"], info["frames_dropped"] = flight.frames_sent, flight.frames_dropped
        info.update(self._timing(flight, wall))
        return flown.trial(self._ok_message(info) if flown.ok else "", info, signals_of(truth, start))
