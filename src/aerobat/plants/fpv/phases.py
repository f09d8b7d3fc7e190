"""The offboard pilot of a Betaflight quad: the trial's phases flown by radio frames, on any flight.

:class:`RadioPilot` flies the supervisor's phases (:func:`aerobat.plants.supervisor.fly_phases`) the
way a pilot flies an FPV quad: calibrate and arm through the AUX switch, take off and settle in
ANGLE mode on a position loop over motion capture, hover, stream the program's rates in ACRO, return
and land. It takes frames from a :class:`RadioFlight`: the lockstep SITL's
(:class:`aerobat.plants.betaflight.flight.Flight`) or a board's on the wall clock
(:class:`aerobat.plants.fc.wall_clock.WallClockFlight`). Both Betaflight plants own one; neither
imports the other.
"""

from __future__ import annotations

import math
from typing import Any, Protocol

import numpy as np

from aerobat.core.plant import Signals, Trial, TrialStatus
from aerobat.firmware.betaflight.packets import MOTOR_LOG_ORDER
from aerobat.firmware.betaflight.rc import RC_MIN_US, stick_to_us
from aerobat.firmware.betaflight.settings import BetaflightSettings
from aerobat.plants.fpv.frames import AnglePilot, FeedbackLaw, FramesEnd, FramesRun, Mode, ProgramPilot, Until
from aerobat.plants.fpv.params import BetaflightParams
from aerobat.plants.fpv.pilot import L_CLIMB, StickMap
from aerobat.plants.supervisor import Flown, TrialStop, fly_phases
from aerobat.quadrotor.dynamics import N_STATE
from aerobat.quadrotor.feedback import Feedback, feedback_vector, onboard_state, reference_from_trajectory
from aerobat.quadrotor.firmware.sticks import frames_of
from aerobat.quadrotor.program import CompiledProgram
from aerobat.quadrotor.simulate import simulate
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["SIGNAL_NAMES", "RadioFlight", "RadioPilot", "failed_trial", "signals_of"]

_AXES = ("roll", "pitch", "yaw")
SIGNAL_NAMES = (*(f"motor{m}" for m in range(1, 5)), *(f"rate_{a}_deg_s" for a in _AXES),
                *(f"setpoint_{a}_deg_s" for a in _AXES), *(f"{t}_{a}" for a in _AXES for t in "pidf"))
"""What a trial's :class:`~aerobat.core.plant.Signals` hold, a row per radio frame of the maneuver:
Betaflight's motor commands M1..M4 (0 stopped, 1 full), the true body rates in the firmware's
axes (the simulated gyro before its noise and filters) [deg/s], the rate set point [deg/s] and
the P, I, D, F terms of each axis in blackbox units (as Blackbox Explorer shows ``axisP[0]``…)."""


_MARGIN_S = 0.015  # program's hover command after its end (the estimate looks 10 ms past it)
_LANDING_SPEED_M_S = 1.0



class RadioFlight(Protocol):
    """What the pilot needs of a flight: frames in, motion capture out, the clock."""

    @property
    def x(self) -> np.ndarray: ...  # the state as the world knows it (a board's: the latest pose)

    @property
    def step_s(self) -> float: ...

    @property
    def latency_steps(self) -> int: ...

    @property
    def frames_sent(self) -> int: ...

    @property
    def frames_dropped(self) -> int: ...

    @property
    def packet_columns(self) -> int: ...  # the firmware's motor packet's floats a record row ends with (0: none)

    @property
    def time_s(self) -> float: ...

    def frames_for(self, seconds: float) -> int: ...

    def run_frames(self, mode: Mode, frames: int, *, channels_us: np.ndarray | None = None,
                   pilot: AnglePilot | ProgramPilot | None = None, check: bool = False, until: Until = Until.NONE,
                   record: np.ndarray | None = None) -> FramesRun: ...

    def estimate(self, pos: np.ndarray, vel: np.ndarray, quat: np.ndarray) -> bool: ...

    def mocap(self) -> np.ndarray: ...

    def motor_commands(self) -> tuple[float, float, float, float]: ...


_REARM_OFF_S = 0.3
"""How long the pilot turns the ARM switch off before trying again when the firmware did not arm [s]."""


def failed_trial(status: TrialStatus, message: str, info: dict[str, Any]) -> Trial:
    """A trial that ended before anything was measured (a firmware that did not start, a refused pre-flight)."""
    nan_state = np.full(N_STATE, np.nan)
    return Trial(status, message, nan_state, np.empty(0), np.empty((0, N_STATE)), nan_state.copy(), info)


def signals_of(truth: list[np.ndarray], start_time: float | None) -> Signals | None:
    """The firmware's motor packet after each maneuver frame, with the true body rates, as :class:`Signals`."""
    if not truth or start_time is None or len(truth[0]) == 1 + N_STATE:
        return None
    rows = np.array(truth)
    packet = rows[:, 1 + N_STATE:]
    columns = [packet[:, list(MOTOR_LOG_ORDER)], np.degrees(rows[:, 11:14]), packet[:, 4:7], packet[:, 7:19]]
    return Signals(rows[:, 0] - start_time, SIGNAL_NAMES, np.column_stack(columns))


class RadioPilot:
    """The offboard pilot: a position loop on motion capture giving ANGLE-mode sticks, and the program in ACRO.

    Parameters
    ----------
    params : the plant's settings; the pilot, radio and volume are used here.
    settings : the firmware's settings (the AUX switches, the rates the sticks map to).
    gravity_m_s2 : g of the nominal vehicle.
    start_m : the maneuver start in the motion-capture frame [m].
    feedback : the pilot-side feedback (``none``: open loop).
    design_model : the vehicle the programs were designed on: the feedback tracks its flight of each.
    """

    def __init__(self, params: BetaflightParams, settings: BetaflightSettings, *, gravity_m_s2: float,
                 start_m: np.ndarray, feedback: Feedback, design_model: VehicleConfig) -> None:
        self.params = params
        self.settings = settings
        self.start_m = start_m
        self.design_model = design_model
        self.feedback = feedback
        self._fb_vector = feedback_vector(feedback)
        pilot = params.pilot
        # the pilot knows the vehicle it flies as published: its mass and thrust curve
        self.sticks = StickMap.from_settings(settings, params.airframe, pilot.vehicle_mass_kg)
        self.limits = self.sticks.limits(max_tilt_rad=math.radians(pilot.max_tilt_deg),
                                         max_climb_m_s=pilot.max_climb_m_s, gravity_m_s2=gravity_m_s2)
        self.gains = np.array([pilot.position_gain_per_s2, pilot.velocity_gain_per_s, pilot.integral_gain_per_s3,
                               pilot.yaw_gain_per_s])
        self._integral = np.zeros(3)
        self.arm_attempts = 0
        """How many times the last :meth:`power_on_and_arm` turned the ARM switch on (1: at once)."""

    def fly(self, flight: RadioFlight, compiled: CompiledProgram,
            info: dict[str, Any]) -> tuple[Flown, list[np.ndarray]]:
        """The supervisor's phases on ``flight``; what each phase saw goes into ``info``. Returns what the
        supervisor measured and the truth (a row per maneuver frame: time, state, the firmware's packet)."""
        self._integral = np.zeros(3)
        sortie = _Sortie(self, flight, info)
        return fly_phases(sortie, compiled), sortie.truth

    # ------------------------------------------------------------- channels
    def channels(self, sticks: np.ndarray, *, arm: bool, angle: bool) -> tuple[int, ...]:
        """RC channels (AETR1234, us) for (roll, pitch, yaw) sticks and a throttle pulse, with the mode switches."""
        aux = self.settings.aux_us(ARM=arm, ANGLE=angle)
        return (stick_to_us(float(sticks[0])), stick_to_us(float(sticks[1])),
                int(round(min(max(float(sticks[3]), RC_MIN_US), 2000.0))), stick_to_us(float(sticks[2])),
                *aux, *([RC_MIN_US] * (12 - len(aux))))

    # --------------------------------------------------------------- phases
    def power_on_and_arm(self, flight: RadioFlight) -> float:
        """Calibrate on the floor, then arm through AUX1; returns the time the firmware armed.

        As a pilot would, a switch that did not arm within 1 s is turned off for :data:`_REARM_OFF_S` and on
        again, once: Betaflight refuses an ARM switch that was on while arming was blocked (a gap in the
        radio link, say) until the switch is cycled. A lockstep flight arms at the first try.
        """
        idle = np.array([0.0, 0.0, 0.0, float(RC_MIN_US)])
        disarmed = self._rows(self.channels(idle, arm=False, angle=True))
        flight.run_frames(Mode.STREAM, flight.frames_for(self.params.pilot.calibration_s), channels_us=disarmed)
        for attempt in range(2):
            if attempt:
                flight.run_frames(Mode.STREAM, flight.frames_for(_REARM_OFF_S), channels_us=disarmed)
            armed = flight.run_frames(Mode.STREAM, flight.frames_for(1.0),
                                      channels_us=self._rows(self.channels(idle, arm=True, angle=True)),
                                      until=Until.ARMED)
            if armed.end is FramesEnd.MET:
                self.arm_attempts = attempt + 1
                return flight.time_s
        raise TrialStop(TrialStatus.ABORTED, "the firmware did not arm within 1 s of the ARM switch, twice (the "
                                             f"switch cycled off for {_REARM_OFF_S:g} s in between)")

    @staticmethod
    def _rows(*channels: tuple[int, ...]) -> np.ndarray:
        return np.array(channels, dtype=np.int64)

    def _estimate(self, flight: RadioFlight) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        pos, vel, quat = np.zeros(3), np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
        flight.estimate(pos, vel, quat)
        return pos, vel, quat

    def fly_to(self, flight: RadioFlight, target: np.ndarray, seconds: float, *, check: bool, until: Until = Until.NONE,
               limits: np.ndarray | None = None) -> FramesRun:
        """ANGLE-mode frames toward ``target`` for ``seconds`` or until ``until``; a crash raises :class:`TrialStop`."""
        pilot = self.params.pilot
        angle = AnglePilot(np.asarray(target, dtype=float), self._integral, self.gains,
                           self.limits if limits is None else limits,
                           self.channels(np.zeros(4), arm=True, angle=True), 1.0 / self.params.radio.rate_hz,
                           pilot.settle_position_m, pilot.settle_velocity_m_s, pilot.settle_tilt_rad,
                           max(1, flight.frames_for(pilot.settle_hold_s)))
        run = flight.run_frames(Mode.ANGLE, flight.frames_for(seconds), pilot=angle, check=check, until=until)
        self._raise_crash(flight, run)
        return run

    def _raise_crash(self, flight: RadioFlight, run: FramesRun) -> None:
        if run.end is FramesEnd.FLOOR:
            raise TrialStop(TrialStatus.CRASHED, f"hit the floor at t = {flight.time_s:.3f} s")
        if run.end is FramesEnd.VOLUME:
            assert run.axis is not None
            row = flight.mocap()[-1]
            lo, hi = (self.params.volume.x_m, self.params.volume.y_m, self.params.volume.z_m)[run.axis]
            name = "xyz"[run.axis]
            rel = row[1 + run.axis] - self.start_m[run.axis]
            raise TrialStop(TrialStatus.CRASHED, f"left the flight volume at t = {row[0]:.3f} s: {name} = "
                                                 f"{rel:+.3f} m beyond the {name} limits [{lo:g}, {hi:g}] m")

    def settle(self, flight: RadioFlight) -> tuple[float | None, float]:
        """Take off and fly to the start until within tolerance for the hold time."""
        pilot = self.params.pilot
        self._integral = np.zeros(3)
        run = self.fly_to(flight, self.start_m, pilot.settle_timeout_s, check=False, until=Until.SETTLED)
        if run.end is not FramesEnd.MET:
            raise TrialStop(TrialStatus.ABORTED, f"did not settle at the start within {pilot.settle_timeout_s:g} s: "
                                                 f"{self._settle_miss(flight)}")
        return run.airborne_s, flight.time_s

    def _settle_miss(self, flight: RadioFlight) -> str:
        """Where the estimate was when the settle gave up, beside the tolerances it had to meet."""
        pilot = self.params.pilot
        pos, vel, quat = self._estimate(flight)
        off_cm = (pos - self.start_m) * 100.0
        tilt_rad = math.acos(max(-1.0, min(1.0, 1.0 - 2.0 * (quat[1] ** 2 + quat[2] ** 2))))
        return (f"at the end {np.linalg.norm(off_cm):.1f} cm from it (x {off_cm[0]:+.1f}, y {off_cm[1]:+.1f}, "
                f"z {off_cm[2]:+.1f} cm), {np.linalg.norm(vel) * 100.0:.1f} cm/s, tilted "
                f"{math.degrees(tilt_rad):.2f}°, {flight.mocap().shape[0]} motion-capture samples (must hold "
                f"{pilot.settle_position_m * 100:g} cm, {pilot.settle_velocity_m_s * 100:g} cm/s and "
                f"{math.degrees(pilot.settle_tilt_rad):.2f}° for {pilot.settle_hold_s:g} s)")

    def hover(self, flight: RadioFlight, seconds: float) -> dict[str, float]:
        """Hover at the start; the largest position error seen (measured and true) [m]."""
        worst = {"seconds": seconds, "max_error_measured_m": 0.0, "max_error_true_m": 0.0}
        if seconds > 0:
            run = self.fly_to(flight, self.start_m, seconds, check=True, until=Until.TRACK)
            worst["max_error_measured_m"], worst["max_error_true_m"] = run.worst_estimated_m, run.worst_true_m
        return worst

    @staticmethod
    def trigger_time(flight: RadioFlight) -> float:
        """When a program streamed from now starts: its first frame reaches the receiver [s]."""
        return flight.time_s + flight.latency_steps * flight.step_s

    def maneuver(self, flight: RadioFlight, compiled: CompiledProgram, truth: list[np.ndarray],
                 start_time: float) -> None:
        """Stream the program in ACRO from ``start_time`` (:meth:`trigger_time`): the truth, then the
        firmware's motor packet, are appended to ``truth`` a row per frame."""
        period = 1.0 / self.params.radio.rate_hz
        n = flight.frames_for(compiled.duration_s + _MARGIN_S)
        # each frame carries the program's mean over its period: the switch times survive the radio
        commands = frames_of(compiled, period, n)
        program = ProgramPilot(commands, self.limits, self.channels(np.zeros(4), arm=True, angle=False), period,
                               self._feedback_law(compiled, start_time) if self.feedback.enabled else None)
        # the truth, then the firmware's motor packet (where the flight has it)
        record = np.empty((n, 1 + N_STATE + flight.packet_columns))
        run = flight.run_frames(Mode.PROGRAM, n, pilot=program, check=True, record=record)
        truth.extend(record[:run.frames])
        self._raise_crash(flight, run)
        self._integral[0:2] = 0.0  # the hover throttle's integral (the pilot's mass error) carries into the return

    def _feedback_law(self, compiled: CompiledProgram, start_time: float) -> FeedbackLaw:
        """The feedback law as the offboard pilot runs it, around the nominal trajectory of ``compiled``."""
        nominal = simulate(compiled, self.design_model, record=True)
        reference = reference_from_trajectory(nominal.times_s, nominal.states, self.feedback.gains.reference_rate_hz)
        state, _ = onboard_state()
        return FeedbackLaw(self._fb_vector, reference.samples, reference.dt_s, state, compiled.duration_s, start_time,
                           self.params.radio.latency_s, self.params.motion_capture.latency_s)

    def land_and_disarm(self, flight: RadioFlight) -> tuple[bool, bool]:
        """Descend onto the floor, throttle down and disarm; (landed, disarmed)."""
        pilot = self.params.pilot
        below = self.start_m + np.array([0.0, 0.0, self.params.volume.z_m[0] - 0.3])
        gentle = self.limits.copy()
        gentle[L_CLIMB] = min(gentle[L_CLIMB], _LANDING_SPEED_M_S)
        landed = self.fly_to(flight, below, pilot.landing_timeout_s, check=False, until=Until.ON_FLOOR,
                             limits=gentle).end is FramesEnd.MET
        low = np.array([0.0, 0.0, 0.0, float(RC_MIN_US)])
        flight.run_frames(Mode.STREAM, flight.frames_for(0.1), channels_us=self._rows(self.channels(low, arm=True,
                                                                                                    angle=True)))
        flight.run_frames(Mode.STREAM, flight.frames_for(0.1), channels_us=self._rows(self.channels(low, arm=False,
                                                                                                    angle=True)))
        return landed, max(flight.motor_commands()) == 0.0


class _Sortie:
    """One trial as the pilot flies it (:class:`~aerobat.plants.supervisor.Sortie`): the
    pilot's phases on ``flight`` (lockstep, or the wall clock for ``fc``), writing what they saw into ``info``."""

    def __init__(self, plant: RadioPilot, flight: RadioFlight, info: dict[str, Any]) -> None:
        self.plant = plant
        self.flight = flight
        self.info = info
        self.start_m = plant.start_m
        self.truth: list[np.ndarray] = []
        self._dropped = 0  # radio frames lost before the maneuver

    def take_off(self) -> None:
        self.info["armed_at_s"] = self.plant.power_on_and_arm(self.flight)
        if self.plant.arm_attempts > 1:  # the switch was cycled: a trial that armed at once says nothing
            self.info["arm_attempts"] = self.plant.arm_attempts
        self.info["airborne_at_s"], self.info["settled_at_s"] = self.plant.settle(self.flight)

    def hover(self) -> None:
        self.info["hover"] = self.plant.hover(self.flight, self.plant.params.pilot.hover_s)

    def trigger(self, compiled: CompiledProgram) -> float:
        """The program streams from the next frame: no upload, no trigger packet."""
        self._dropped = self.flight.frames_dropped
        return self.plant.trigger_time(self.flight)

    def maneuver(self, compiled: CompiledProgram, start_time_s: float) -> None:
        self.plant.maneuver(self.flight, compiled, self.truth, start_time_s)
        self.info["start_time_s"] = start_time_s
        self.info["maneuver_frames_dropped"] = self.flight.frames_dropped - self._dropped

    def return_to_start(self) -> None:
        self.plant.fly_to(self.flight, self.start_m, self.plant.params.pilot.return_time_s, check=True)
        self.info["returned_error_m"] = float(np.linalg.norm(self.flight.x[0:3] - self.start_m))

    def land(self) -> None:
        self.info["landed"], self.info["disarmed"] = self.plant.land_and_disarm(self.flight)

    def mocap(self) -> np.ndarray:
        return self.flight.mocap()

    def now_s(self) -> float:
        return self.flight.time_s

    def pick_up(self) -> None:
        """Every trial starts a new firmware on the floor: nothing to put back."""
