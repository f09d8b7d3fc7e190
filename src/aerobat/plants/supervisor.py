"""The supervisor of Fig. 8, written once: a trial's phases and how its outcome is measured.

Every plant flies a trial the same way (Sect. 8, Fig. 8): take off and settle at the start,
hover, trigger the program, fly it open loop, recover and return to the start, land. The
maneuver's start state, its final state and the measured trajectory come from the
motion-capture samples alone, whatever the plant. What differs is how a plant moves its
vehicle from one point to the next: the arena runs its compiled radio loop
(:func:`aerobat.plants.arena.kernel.supervise`), RotorPy steps its simulator, Betaflight
streams radio frames to the firmware (in lockstep, or over MSP on the wall clock for ``fc``).

A plant hands :func:`fly_phases` a :class:`Sortie`, one trial's vehicle: each of its methods
flies one phase and raises :class:`TrialStop` to end the trial early. :func:`fly_phases`
runs the phases in order, measures what was flown and returns a :class:`Flown`; the plant
turns it into its :class:`~aerobat.core.plant.Trial` with its own message and extras.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from aerobat.core.plant import Signals, Trial, TrialStatus
from aerobat.plants.mocap import estimate_final_state, measured_states
from aerobat.quadrotor.dynamics import N_STATE
from aerobat.quadrotor.program import CompiledProgram

__all__ = ["Flown", "Phase", "Sortie", "TrialStop", "fly_phases"]

START_WINDOW_S = 0.06
"""The start state is estimated from the motion-capture samples this long before the trigger [s]."""


class Phase(enum.Enum):
    """The phases of a supervised trial (Fig. 8), in the order they fly."""

    TAKE_OFF = "take-off"  # power on, arm where there is a firmware, climb and settle at the start
    HOVER = "hover"  # hold the start before the trigger
    TRIGGER = "trigger"  # upload where there is a link, send the trigger: the maneuver's start is known
    MANEUVER = "maneuver"  # the program, open loop
    RETURN = "return"  # recover and fly back to the start under closed-loop control
    LAND = "land"  # where the plant lands between trials


class TrialStop(Exception):
    """A phase ends the trial early with ``status``; the message says why.

    ``picked_up`` False: the vehicle is back at the start under control (a lost trigger flies
    back), so the plant does not put it back by hand (:meth:`Sortie.pick_up`).
    """

    def __init__(self, status: TrialStatus, message: str, *, picked_up: bool = True) -> None:
        super().__init__(message)
        self.status = status
        self.picked_up = picked_up


class Sortie(Protocol):
    """One trial's vehicle as the supervisor flies it: a method per phase, and what it measures.

    A phase raises :class:`TrialStop` to end the trial. The phases a plant does not have
    (RotorPy's hover, the arena's landing) return at once.
    """

    start_m: np.ndarray
    """The maneuver start in the motion-capture frame [m]."""

    def take_off(self) -> None:
        """Power on and arm where there is a firmware; climb and settle at the start."""

    def hover(self) -> None:
        """Hold the start before the trigger."""

    def trigger(self, compiled: CompiledProgram) -> float:
        """Hand the vehicle the program and start it; returns the maneuver's start time [s]."""

    def maneuver(self, compiled: CompiledProgram, start_time_s: float) -> None:
        """Fly the program to its end (and the estimation window just after it)."""

    def return_to_start(self) -> None:
        """Recover and fly back to the start."""

    def land(self) -> None:
        """Land between trials, where the plant does."""

    def mocap(self) -> np.ndarray:
        """The motion-capture rows recorded so far, (t, x, y, z, qw, qx, qy, qz) each."""

    def now_s(self) -> float:
        """The plant's clock now [s]."""

    def pick_up(self) -> None:
        """After a failure: put the vehicle back at the start, restarted (a person's job in a real lab)."""


_NO_STATE = np.full(N_STATE, np.nan)


@dataclass(frozen=True)
class Flown:
    """What the supervisor saw of one trial.

    Attributes
    ----------
    status : how it ended; ``OK`` only when every phase flew and the final state was measured.
    message : why it ended early ("" for ``OK``).
    phase : the phase it ended in (:attr:`Phase.LAND` when every phase flew).
    start_time_s : the maneuver's start on the plant's clock [s], None if it was never triggered.
    times_s, states : the measured trajectory from the start (:func:`~aerobat.plants.mocap.measured_states`);
        up to the failure for a trial that ended in or after the maneuver, empty before it.
    final_state, start_state : the measured states at the maneuver's end and start (NaN when unknown).
    """

    status: TrialStatus
    message: str
    phase: Phase
    start_time_s: float | None
    times_s: np.ndarray
    states: np.ndarray
    final_state: np.ndarray
    start_state: np.ndarray

    @property
    def ok(self) -> bool:
        return self.status is TrialStatus.OK

    def trial(self, ok_message: str, info: dict[str, Any] | None = None, signals: Signals | None = None) -> Trial:
        """The plant's :class:`~aerobat.core.plant.Trial`: ``ok_message`` when it flew, else why it did not."""
        return Trial(self.status, ok_message if self.ok else self.message, self.final_state, self.times_s,
                     self.states, self.start_state, {} if info is None else info, signals)


def fly_phases(sortie: Sortie, compiled: CompiledProgram) -> Flown:
    """Fly one supervised trial of ``compiled`` (Fig. 8) on ``sortie``.

    Only :class:`TrialStop` ends the trial here; anything else a phase raises (a firmware that
    stops answering, a safety stop on a real vehicle) is the plant's to handle.
    """
    start: float | None = None
    phase = Phase.TAKE_OFF
    try:
        sortie.take_off()
        phase = Phase.HOVER
        sortie.hover()
        phase = Phase.TRIGGER
        start = sortie.trigger(compiled)
        phase = Phase.MANEUVER
        sortie.maneuver(compiled, start)
        phase = Phase.RETURN
        sortie.return_to_start()
        # measured once back at the start: what comes later lies outside the windows
        rows = sortie.mocap()
        end = start + compiled.duration_s
        times, states = measured_states(rows, start, end, sortie.start_m)
        final = estimate_final_state(rows, start, end, sortie.start_m)
        start_state = estimate_final_state(rows, start - START_WINDOW_S, start, sortie.start_m)
        phase = Phase.LAND
        sortie.land()
    except TrialStop as stop:
        if start is None or stop.status is TrialStatus.NO_TRIGGER:  # nothing of the maneuver flew
            times, states = np.empty(0), np.empty((0, N_STATE))
        else:
            times, states = measured_states(sortie.mocap(), start, sortie.now_s(), sortie.start_m)
        if stop.picked_up:
            sortie.pick_up()
        return Flown(stop.status, str(stop), phase, start, times, states, _NO_STATE.copy(), _NO_STATE.copy())
    start_state = _NO_STATE.copy() if start_state is None else start_state
    if final is None or not (np.all(np.isfinite(final[:13])) and np.all(np.isfinite(final[17:]))):
        return Flown(TrialStatus.ABORTED, "too few motion-capture samples to estimate the final state", phase,
                     start, times, states, _NO_STATE.copy(), start_state)
    return Flown(TrialStatus.OK, "", phase, start, times, states, final, start_state)
