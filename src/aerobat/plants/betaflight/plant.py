"""``--plant betaflight``: the arena's physical world with Betaflight 4.6 as the onboard loop.

One :meth:`BetaflightPlant.fly` is one iteration of the paper's Fig. 8, flown the way an FPV
pilot flies (``docs/plants.md``, Betaflight):

1. **Power on** on the floor below the start: a fresh SITL process (lockstep, its own ports)
   boots from the configured eeprom; ARM off, ANGLE on, throttle low while Betaflight
   calibrates its gyro.
2. **Arm** through AUX1; the firmware answers with idle motor commands.
3. **Take off, settle, hover** in ANGLE mode: the offboard position loop on motion capture sends
   angle sticks and throttle over the radio (250 Hz, lossy) until the vehicle has stayed at the
   start for the hold time and then hovered for ``hover_s``.
4. **Trigger**: AUX2 switches to ACRO (air mode is on whenever armed) and the program streams
   as stick positions (body rates through the linear rate curve, collective through the inverted
   throttle→thrust model), one frame per radio period.
5. **Measure**: after the program (and 15 ms of its hover command) ANGLE mode and the position
   loop take over and fly back; the final state at the maneuver's end is estimated from
   motion-capture samples alone (:mod:`aerobat.plants.mocap`).
6. **Land and disarm** on the floor; the firmware process ends with the trial.

Every trial starts a fresh firmware: the plant's state between trials is its random generator,
the trial count and the battery (drift), so a saved state repeats the next trial bit for bit.
A firmware that dies or stops answering loses the trial (``TrialStatus.LOST``, with the reason);
the next trial starts a new one, and learning flies the lost parameters again.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from aerobat.config import check_type
from aerobat.core.plant import Signals, Trial, TrialStatus
from aerobat.firmware.betaflight.errors import FirmwareNotResponding
from aerobat.firmware.betaflight.packets import MOTOR_LOG_ORDER
from aerobat.firmware.betaflight.rc import RC_MIN_US, stick_to_us
from aerobat.firmware.betaflight.settings import BetaflightSettings, load_settings
from aerobat.plants.betaflight.flight import N_PACKET, Flight, NonFinite
from aerobat.plants.betaflight.physics import airframe_plant
from aerobat.plants.fpv.frames import AnglePilot, FeedbackLaw, FramesEnd, FramesRun, Mode, ProgramPilot, Until
from aerobat.plants.fpv.params import BetaflightParams
from aerobat.plants.fpv.pilot import L_CLIMB, StickMap
from aerobat.plants.plant_state import StateLayout
from aerobat.plants.supervisor import Phase, TrialStop, fly_phases
from aerobat.quadrotor.dynamics import N_STATE
from aerobat.quadrotor.feedback import (
    Feedback,
    FeedbackScheme,
    as_feedback,
    feedback_vector,
    onboard_state,
    reference_from_trajectory,
)
from aerobat.quadrotor.firmware.sticks import frames_of
from aerobat.quadrotor.program import CompiledProgram, Program
from aerobat.quadrotor.simulate import simulate
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["SIGNAL_NAMES", "BetaflightPlant"]

_AXES = ("roll", "pitch", "yaw")
SIGNAL_NAMES = (*(f"motor{m}" for m in range(1, 5)), *(f"rate_{a}_deg_s" for a in _AXES),
                *(f"setpoint_{a}_deg_s" for a in _AXES), *(f"{t}_{a}" for a in _AXES for t in "pidf"))
"""What a trial's :class:`~aerobat.core.plant.Signals` hold, a row per radio frame of the maneuver:
Betaflight's motor commands M1..M4 (0 stopped, 1 full), the true body rates in the firmware's
axes (the simulated gyro before its noise and filters) [deg/s], the rate set point [deg/s] and
the P, I, D, F terms of each axis in blackbox units (as Blackbox Explorer shows ``axisP[0]``…)."""

_LAYOUT = StateLayout("betaflight", counters=("trials_flown",), fractions=("capacity",))

_MARGIN_S = 0.015  # program's hover command after its end (the estimate looks 10 ms past it)
_LANDING_SPEED_M_S = 1.0


class BetaflightPlant:
    """The 5-inch racer in a motion-capture arena, flown by Betaflight 4.6 (SITL, lockstep).

    Parameters
    ----------
    config : the *nominal* vehicle (the design model), used for g; the true vehicle is
        ``params.airframe``, whose published mass and thrust curve the pilot's collective →
        throttle model inverts (``params.pilot.vehicle_mass_kg``).
    params : the plant's settings (:class:`~.params.BetaflightParams`).
    seed : seeds the plant's generator (noise, wind, radio losses, motor spread per trial).
    binary, eeprom : the SITL binary and configured eeprom (default: built and configured on
        first use, cached: :func:`aerobat.firmware.betaflight.build.ensure_sitl`,
        :func:`aerobat.firmware.betaflight.configure.ensure_eeprom`).
    settings : the firmware's settings (default: the packaged ``settings.toml``).
    feedback : what the offboard pilot mixes into the program's sticks (:mod:`aerobat.quadrotor.feedback`;
        default the best scheme measured, ``tracking``; ``"none"`` streams the program as it is).
        Betaflight runs no program, so the law runs in the pilot, at the radio's rate, on motion capture: the
        attitude is the latest motion-capture sample carried forward by the commanded rates over its age and the
        radio's latency (the pilot sees no gyro).
    design_model : the vehicle the programs were designed on, if not ``config`` (a vehicle identified from
        this plant): the feedback tracks that vehicle's flight of each program.
    """

    name = "betaflight"

    def __init__(self, config: VehicleConfig, params: BetaflightParams | None = None, *, seed: int = 0,
                 binary: Path | None = None, eeprom: Path | None = None,
                 settings: BetaflightSettings | None = None,
                 feedback: Feedback | FeedbackScheme | str | None = None,
                 design_model: VehicleConfig | None = None) -> None:
        from aerobat.firmware.betaflight.build import ensure_sitl
        from aerobat.firmware.betaflight.configure import ensure_eeprom

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
        if settings is None:  # settings given are taken as they are (the fc plant's are the real board's)
            self.settings = self.settings.with_props(self.params.airframe.props_out)
        self.binary = Path(binary) if binary is not None else ensure_sitl()
        self.eeprom = Path(eeprom) if eeprom is not None else ensure_eeprom(self.binary, settings=self.settings)
        self.start_m = np.zeros(3)
        self.gravity = config.vehicle.gravity_m_s2
        pilot = self.params.pilot
        # the pilot knows the vehicle it flies as published: its mass and thrust curve
        self.sticks = StickMap.from_settings(self.settings, self.params.airframe, pilot.vehicle_mass_kg)
        self.limits = self.sticks.limits(max_tilt_rad=math.radians(pilot.max_tilt_deg),
                                         max_climb_m_s=pilot.max_climb_m_s, gravity_m_s2=self.gravity)
        self.gains = np.array([pilot.position_gain_per_s2, pilot.velocity_gain_per_s, pilot.integral_gain_per_s3,
                               pilot.yaw_gain_per_s])
        self.last_truth: tuple[np.ndarray, np.ndarray] = (np.empty(0), np.empty((0, N_STATE)))
        self.flight: Flight | None = None  # the flight in progress (for fault injection and diagnosis)
        self._integral = np.zeros(3)
        self.feedback = as_feedback(feedback)
        self._fb_vector = feedback_vector(self.feedback)

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
    def _trial_plant(self, rng: np.random.Generator) -> np.ndarray:
        """The true vehicle for one trial: motor spread, battery, per-trial jitter, wind and gust."""
        p = self.params
        gains = np.array(p.airframe.thrust_gains, dtype=float) * self.capacity
        extra: dict[str, Any] = {}
        d = p.disturbances
        if d.enabled:
            gains = gains * (1.0 + d.thrust_gain_jitter * rng.standard_normal()
                             + d.motor_gain_jitter * rng.standard_normal(4))
            extra = {"wind_m_s": tuple(float(v) for v in d.wind_std_m_s * rng.standard_normal(3)),
                     "gust_amplitude_m_s": tuple(float(v) for v in d.gust_amplitude_std_m_s * rng.standard_normal(3)),
                     "gust_frequency_hz": d.gust_frequency_hz,
                     "gust_phase_rad": float(rng.uniform(0.0, 2.0 * math.pi))}
        return airframe_plant(p, thrust_gains=(float(gains[0]), float(gains[1]), float(gains[2]), float(gains[3])),
                              **extra)

    def fly(self, program: Program | CompiledProgram) -> Trial:
        """One supervised trial (Fig. 8) through the firmware; a failure is a trial status, never an exception."""
        wall = time.perf_counter()
        compiled = program.compile() if isinstance(program, Program) else program
        rng = np.random.default_rng(self.rng.integers(2**63))  # one child stream per trial, whatever happens
        plant = self._trial_plant(rng)
        self.trials_flown += 1
        info: dict[str, Any] = {"firmware": f"Betaflight 4.6.0 SITL lockstep, settings revision "
                                            f"{self.settings.revision} ({self.settings.sha256[:12]})"
                                            + (f", tune {self.params.tune.source}" if self.params.tune else "")}
        flight = None
        try:
            flight = self.open_flight(rng, plant)
            self.flight = flight
            return self._fly(flight, compiled, info, wall)
        except FirmwareNotResponding as error:
            info.update(self._timing(flight, wall))
            reason = str(error).splitlines()[0]
            return self._failed(TrialStatus.LOST, f"firmware lost: {reason}; the next trial starts a new one", info)
        except NonFinite as error:
            info.update(self._timing(flight, wall))
            return self._failed(TrialStatus.ABORTED, str(error), info)
        finally:
            self.flight = None
            if flight is not None:
                flight.close()
            if self.params.drift.enabled:
                self.capacity *= 1.0 - self.params.drift.thrust_loss_per_trial

    def open_flight(self, rng: np.random.Generator | None = None, plant: np.ndarray | None = None) -> Flight:
        """A fresh firmware and the vehicle on the floor below the start, powered on (not a trial).

        ``rng`` defaults to a child of the plant's generator, ``plant`` to this trial's true vehicle.
        The caller closes it (a context manager). :meth:`fly` runs the phases below on one.
        """
        rng = rng if rng is not None else np.random.default_rng(self.rng.integers(2**63))
        plant = plant if plant is not None else self._trial_plant(rng)
        self._integral = np.zeros(3)
        return Flight(self.binary, self.eeprom, self.params, plant, self.start_m, rng, self.gravity)

    def _timing(self, flight: Flight | None, wall: float) -> dict[str, Any]:
        elapsed = time.perf_counter() - wall
        simulated = flight.time_s if flight is not None else 0.0
        cpu = flight.firmware_cpu_time_s() if flight is not None else None
        spun, driver_spun = flight.spun_s() if flight is not None else (0.0, 0.0)
        choices = flight.spin_choices() if flight is not None else None
        # the driver's measured spin policy (shm_exchange.c, choose_spin): the waits that slept at once
        policy = {} if choices is None else {"driver_sleeping_share": choices.sleeping_share,
                                             "driver_spin_switches": choices.switches,
                                             "driver_spin_probes": choices.probes}
        return {"wall_s": elapsed, "simulated_s": simulated,
                "steps": flight.tick if flight is not None else 0,
                "real_time_factor": simulated / elapsed if elapsed > 0 else math.nan,
                # the driver's overhead: wall time per second of the firmware's own CPU time
                "firmware_cpu_s": cpu if cpu is not None else math.nan,
                "wall_per_firmware_cpu": elapsed / cpu if cpu else math.nan,
                # over shared memory the waits spin first: CPU time spent waiting, not working (wall
                # time spinning: under load it includes preemption)
                "firmware_spin_s": spun, "driver_spin_s": driver_spun,
                # Python's turns: calls into the compiled frame loop (the firmware may nap in each)
                "compiled_calls": flight.compiled_calls - 1 if flight is not None else 0, **policy}

    @staticmethod
    def _failed(status: TrialStatus, message: str, info: dict[str, Any],
                times: np.ndarray | None = None, states: np.ndarray | None = None,
                signals: Signals | None = None) -> Trial:
        nan_state = np.full(N_STATE, np.nan)
        return Trial(status, message, nan_state, np.empty(0) if times is None else times,
                     np.empty((0, N_STATE)) if states is None else states, nan_state.copy(), info, signals)

    def _fly(self, flight: Flight, compiled: CompiledProgram, info: dict[str, Any], wall: float) -> Trial:
        """The supervisor's phases (:func:`~aerobat.plants.supervisor.fly_phases`) on ``flight``."""
        sortie = _Sortie(self, flight, info)
        flown = fly_phases(sortie, compiled)
        self._keep_truth(sortie.truth, flown.start_time_s)
        signals = self._signals(sortie.truth, flown.start_time_s)
        if flown.phase is Phase.LAND:
            info["frames_sent"], info["frames_dropped"] = flight.frames_sent, flight.frames_dropped
        info.update(self._timing(flight, wall))
        return flown.trial(f"maneuver flown through Betaflight ({info['steps']} lockstep steps, "
                           f"{info.get('frames_dropped')}/{info.get('frames_sent')} radio frames lost)", info, signals)

    def _keep_truth(self, truth: list[np.ndarray], start_time: float | None) -> None:
        if truth and start_time is not None:
            rows = np.array(truth)
            self.last_truth = (rows[:, 0] - start_time, rows[:, 1:1 + N_STATE])
        else:
            self.last_truth = (np.empty(0), np.empty((0, N_STATE)))

    @staticmethod
    def _signals(truth: list[np.ndarray], start_time: float | None) -> Signals | None:
        """The firmware's motor packet after each maneuver frame, with the true body rates, as :class:`Signals`."""
        if not truth or start_time is None or len(truth[0]) == 1 + N_STATE:
            return None
        rows = np.array(truth)
        packet = rows[:, 1 + N_STATE:]
        columns = [packet[:, list(MOTOR_LOG_ORDER)], np.degrees(rows[:, 11:14]), packet[:, 4:7], packet[:, 7:19]]
        return Signals(rows[:, 0] - start_time, SIGNAL_NAMES, np.column_stack(columns))

    # ------------------------------------------------------------- channels
    def channels(self, sticks: np.ndarray, *, arm: bool, angle: bool) -> tuple[int, ...]:
        """RC channels (AETR1234, us) for (roll, pitch, yaw) sticks and a throttle pulse, with the mode switches."""
        aux = self.settings.aux_us(ARM=arm, ANGLE=angle)
        return (stick_to_us(float(sticks[0])), stick_to_us(float(sticks[1])),
                int(round(min(max(float(sticks[3]), RC_MIN_US), 2000.0))), stick_to_us(float(sticks[2])),
                *aux, *([RC_MIN_US] * (12 - len(aux))))

    # --------------------------------------------------------------- phases
    def power_on_and_arm(self, flight: Flight) -> float:
        """Calibrate on the floor, then arm through AUX1; returns the time the firmware armed."""
        idle = np.array([0.0, 0.0, 0.0, float(RC_MIN_US)])
        flight.run_frames(Mode.STREAM, flight.frames_for(self.params.pilot.calibration_s),
                          channels_us=self._rows(self.channels(idle, arm=False, angle=True)))
        armed = flight.run_frames(Mode.STREAM, flight.frames_for(1.0),
                                  channels_us=self._rows(self.channels(idle, arm=True, angle=True)), until=Until.ARMED)
        if armed.end is FramesEnd.MET:
            return flight.time_s
        raise TrialStop(TrialStatus.ABORTED, "the firmware did not arm within 1 s of the ARM switch")

    @staticmethod
    def _rows(*channels: tuple[int, ...]) -> np.ndarray:
        return np.array(channels, dtype=np.int64)

    def _estimate(self, flight: Flight) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        pos, vel, quat = np.zeros(3), np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
        flight.estimate(pos, vel, quat)
        return pos, vel, quat

    def fly_to(self, flight: Flight, target: np.ndarray, seconds: float, *, check: bool, until: Until = Until.NONE,
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

    def _raise_crash(self, flight: Flight, run: FramesRun) -> None:
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

    def settle(self, flight: Flight) -> tuple[float | None, float]:
        """Take off and fly to the start until within tolerance for the hold time."""
        pilot = self.params.pilot
        self._integral = np.zeros(3)
        run = self.fly_to(flight, self.start_m, pilot.settle_timeout_s, check=False, until=Until.SETTLED)
        if run.end is not FramesEnd.MET:
            raise TrialStop(TrialStatus.ABORTED, f"did not settle at the start within {pilot.settle_timeout_s:g} s")
        return run.airborne_s, flight.time_s

    def hover(self, flight: Flight, seconds: float) -> dict[str, float]:
        """Hover at the start; the largest position error seen (measured and true) [m]."""
        worst = {"seconds": seconds, "max_error_measured_m": 0.0, "max_error_true_m": 0.0}
        if seconds > 0:
            run = self.fly_to(flight, self.start_m, seconds, check=True, until=Until.TRACK)
            worst["max_error_measured_m"], worst["max_error_true_m"] = run.worst_estimated_m, run.worst_true_m
        return worst

    @staticmethod
    def trigger_time(flight: Flight) -> float:
        """When a program streamed from now starts: its first frame reaches the receiver [s]."""
        return flight.time_s + flight.latency_steps * flight.step_s

    def maneuver(self, flight: Flight, compiled: CompiledProgram, truth: list[np.ndarray], start_time: float) -> None:
        """Stream the program in ACRO from ``start_time`` (:meth:`trigger_time`): the truth, then the
        firmware's motor packet, are appended to ``truth`` a row per frame."""
        period = 1.0 / self.params.radio.rate_hz
        n = flight.frames_for(compiled.duration_s + _MARGIN_S)
        # each frame carries the program's mean over its period: the switch times survive the radio
        commands = frames_of(compiled, period, n)
        program = ProgramPilot(commands, self.limits, self.channels(np.zeros(4), arm=True, angle=False), period,
                               self._feedback_law(compiled, start_time) if self.feedback.enabled else None)
        # the truth, then the firmware's motor packet (where the flight has it)
        record = np.empty((n, 1 + N_STATE + (N_PACKET if flight.records_packet else 0)))
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

    def land_and_disarm(self, flight: Flight) -> tuple[bool, bool]:
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
    """One Betaflight trial as the supervisor flies it (:class:`~aerobat.plants.supervisor.Sortie`): the
    pilot's phases on ``flight`` (lockstep, or the wall clock for ``fc``), writing what they saw into ``info``."""

    def __init__(self, plant: BetaflightPlant, flight: Flight, info: dict[str, Any]) -> None:
        self.plant = plant
        self.flight = flight
        self.info = info
        self.start_m = plant.start_m
        self.truth: list[np.ndarray] = []
        self._dropped = 0  # radio frames lost before the maneuver

    def take_off(self) -> None:
        self.info["armed_at_s"] = self.plant.power_on_and_arm(self.flight)
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
