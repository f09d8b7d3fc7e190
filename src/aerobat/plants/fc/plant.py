"""``FlightControllerPlant``: the Fig. 8 supervisor flying a Betaflight board on the wall clock.

The supervisor and the pilot are the ones the lockstep Betaflight plant flies with
(:func:`aerobat.plants.supervisor.fly_phases`, :class:`aerobat.plants.fpv.phases.RadioPilot`: power on
and arm, take off and settle, hover, stream the program as sticks in ACRO, measure, fly back, land and
disarm), with the same stick map; the two plants share them through :mod:`aerobat.plants.fpv` and
neither imports the other. What changes is the flight it drives: a :class:`~.wall_clock.WallClockFlight`,
whose frames go out as ``MSP_SET_RAW_RC`` over a
serial port at their deadlines and whose measurements are motion-capture poses as they arrive, with the
:class:`~.safety.SafetyMonitor` asked at every frame.

Two connections give it a flight controller (:class:`Connection`):

* :class:`BoardConnection` — a real board: ``/dev/ttyACM0`` and a motion-capture system
  (:class:`~.pose_source.MotionCaptureSource`).
* :class:`RehearsalConnection` — the real firmware in real time: a :class:`~.world.RealTimeWorld`
  (the SITL and aerobat's physics in a process of their own, paced to the wall clock), its UART as
  a serial device (:class:`~.pty_bridge.PtyBridge`), its motion capture over UDP
  (:class:`~.simulated_source.SimulatedSource`, 200 Hz with latency). A fresh world per trial.

Before each trial the plant streams disarmed frames and runs :func:`~.safety.preflight`; a take-off it
refuses is an aborted trial naming the problems. A safety stop during the flight disarms at once
(kill, geofence, motion-capture loss, low battery) or, with the link gone, leaves the vehicle to the
firmware's RX-loss failsafe; the trial ends ``crashed`` (geofence) or ``aborted`` (the others), which
ends a learning session: a real vehicle is not flown again until a person has looked.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import threading
import time
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from aerobat.core.plant import Trial, TrialStatus
from aerobat.errors import ConfigError
from aerobat.firmware.betaflight.errors import LinkClosed, LinkTimeout, MspError
from aerobat.firmware.betaflight.msp import Battery, FailsafeConfig, MspClient, MspModeRange, StatusEx
from aerobat.firmware.betaflight.rc import RC_MIN_US
from aerobat.firmware.betaflight.serial_link import SerialTransport
from aerobat.firmware.betaflight.settings import BetaflightSettings, load_settings
from aerobat.plants.fpv.params import BetaflightParams
from aerobat.plants.fpv.phases import failed_trial
from aerobat.plants.fpv.pilot import program_sticks
from aerobat.plants.fpv.priority import GROUND_FIFO_PRIORITY, real_time_threads
from aerobat.plants.fpv.radio_plant import RadioPlant
from aerobat.quadrotor.firmware.sticks import frames_of
from aerobat.quadrotor.program import CompiledProgram, Program
from aerobat.quadrotor.vehicle import VehicleConfig

from .pose_source import MotionCaptureSource, PoseSource
from .pty_bridge import PtyBridge
from .safety import (
    SafetyLimits,
    SafetyMonitor,
    StopReason,
    configuration_problems,
    failsafe_problems,
    preflight,
)
from .settings import FcSettings, LinkKind, fc_params
from .simulated_source import SimulatedSource
from .wall_clock import SafetyStop, WallClockFlight
from .world import SET_POINT_JUMP_DEG_S, RealTimeWorld, WorldReport

__all__ = ["MSP_RC_SETTINGS", "REHEARSAL_TIMEOUTS", "BoardConnection", "Connection", "FlightControllerPlant", "Link",
           "RehearsalConnection", "build_fc_plant"]

MSP_RC_SETTINGS = {"serial_update_rate_hz": "2000"}
"""Firmware settings RC over MSP needs: the serial task reads MSP at 100 Hz by default, which would
hold a frame up to 10 ms and merge frames sent faster; at 2000 Hz a frame waits at most 0.5 ms."""

REHEARSAL_TIMEOUTS: dict[str, Any] = {"mocap_timeout_s": 0.25, "link_timeout_s": 0.5}
"""A rehearsal's timeouts: its world can fall behind the wall clock on a loaded machine (it reports by
how much, :class:`~.world.WorldReport`), which delays its poses as a real system's never are."""

_STATUS_FOR = {StopReason.GEOFENCE: TrialStatus.CRASHED}
_PREFLIGHT_FRAMES_S = 0.5  # disarmed frames before the checks: the receiver sees a live link
_CALIBRATION_WAIT_S = 2.0  # beyond the pilot's calibration time, the longest the checks wait for the gyro
_SAFE_FRAMES_S = 0.3  # disarmed frames sent after a stop
_DISARM_ATTEMPTS = 3  # rounds of disarmed frames while the board still reports itself armed after a stop
_FAILSAFE_WAIT_S = 4.0  # after a link loss, how long the vehicle is watched coming down (failsafe DROP: ≈1.6 s)


@dataclass
class Link:
    """An open connection to a flight controller for one trial."""

    msp: MspClient
    poses: PoseSource
    time_zero_s: float
    world: RealTimeWorld | None = None
    bridge: PtyBridge | None = None


class Connection(Protocol):
    """How the plant reaches a flight controller: one :class:`Link` per trial, closed after it."""

    require_battery: bool

    def open(self, seed: int) -> contextlib.AbstractContextManager[Link]:
        """The link for one trial (``seed``: the trial's, for a simulated world)."""


@dataclass
class BoardConnection:
    """A real board on ``port`` and a motion-capture source (the caller opens and closes the source)."""

    port: str
    poses: PoseSource | None
    baudrate_bd: int = 115_200
    require_battery: bool = True

    def check(self) -> None:
        """Open the port once and close it (:class:`ConfigError` naming it if it cannot be opened)."""
        SerialTransport(self.port, self.baudrate_bd).close()

    @contextlib.contextmanager
    def open(self, seed: int) -> Iterator[Link]:
        del seed
        if self.poses is None:
            raise ConfigError("the board's motion capture is not connected (BoardConnection.poses is None)")
        with SerialTransport(self.port, self.baudrate_bd) as transport:
            yield Link(MspClient(transport, timeout_s=0.5), self.poses, time.monotonic())


@dataclass
class RehearsalConnection:
    """The real firmware and aerobat's physics on the wall clock, reached as a real board is.

    ``plant_args`` build the world (:class:`~aerobat.plants.betaflight.plant.BetaflightPlant`'s
    arguments); the seed of each trial is the plant's. The SITL has no battery sensor: the battery
    check is off here, and its trigger is tested against MSP answers from a pseudo-terminal.
    """

    plant_args: dict[str, Any]
    chunk_s: float = 1e-3
    require_battery: bool = False
    reports: list[WorldReport] = field(default_factory=list)
    current: Link | None = None
    """The link of the trial in progress (for drills: cut it, blind its motion capture)."""

    @contextlib.contextmanager
    def open(self, seed: int) -> Iterator[Link]:
        with SimulatedSource() as source:
            world = RealTimeWorld({**self.plant_args, "seed": seed}, source.port, chunk_s=self.chunk_s)
            try:
                try:
                    bridge = PtyBridge("127.0.0.1", world.uart1_port)
                except (TimeoutError, OSError, RuntimeError) as error:  # say what became of the world and firmware
                    raise RuntimeError(f"{error} ({world.describe()})") from error
                with bridge, SerialTransport(bridge.device) as transport:
                    t0 = world.start()
                    source.set_time_zero(t0)
                    self.current = Link(MspClient(transport, timeout_s=1.0), source, t0, world, bridge)
                    yield self.current
            finally:
                self.current = None
                report = world.stop()
                if report is not None:
                    self.reports.append(report)


def _ground_threads(link: Link) -> tuple[int | None, ...]:
    """The ground station's threads that keep the wall clock: this one (frames, supervisor), the pose
    receiver's and the serial bridge's, where they have their own."""
    return (threading.get_native_id(), getattr(link.poses, "thread_id", None),
            link.bridge.thread_id if link.bridge is not None else None)


class FlightControllerPlant(RadioPlant):
    """``--plant fc``: the Fig. 8 supervisor on the wall clock, with a Betaflight flight controller.

    Parameters
    ----------
    config : the nominal vehicle (the design model).
    connection : how to reach the flight controller (:class:`BoardConnection`, :class:`RehearsalConnection`).
    params : the Betaflight plant's settings; the pilot, radio rate and volume are used here (the
        airframe, sensors and disturbances only by a rehearsal's world). Default: :func:`~.settings.fc_params`
        (lockstep's, with more time to settle on the wall clock).
    limits : the safety limits (geofence in the motion-capture frame; default: :class:`~.safety.SafetyLimits`'s,
        for a rehearsal with the fence just outside the plant's flight volume).
    seed : seeds the trials' worlds in a rehearsal.
    settings : the firmware's settings (default: the packaged ones with :data:`MSP_RC_SETTINGS`).
    feedback : the pilot's feedback (default ``none``: open loop, as the paper flies).
    start_m : the maneuver start in the motion-capture frame (default: a rehearsal's origin; for a board,
        above the room's origin by the volume's floor distance, so that the floor is at z = 0).
    dry_run : everything but spinning motors: each trial connects, runs the pre-flight checks and streams
        the program's frames disarmed at the radio rate (their timing reported), then ends ``aborted``
        ("dry run"): nothing is measured.
    binary, eeprom : a rehearsal's firmware (built and configured on first use).
    design_model : the vehicle the programs were designed on, if not ``config``: the feedback tracks its flight.
    """

    name = "fc"
    repeatable = False  # on the wall clock: timing decides every trial (aerobat.core.plant.MaybeRepeatablePlant)

    def __init__(self, config: VehicleConfig, connection: Connection, params: BetaflightParams | None = None, *,
                 limits: SafetyLimits | None = None, seed: int = 0, settings: BetaflightSettings | None = None,
                 feedback: Any = "none", dry_run: bool = False, start_m: Any = None,
                 design_model: VehicleConfig | None = None, **firmware: Any) -> None:
        from aerobat.firmware.betaflight.build import ensure_sitl
        from aerobat.firmware.betaflight.configure import ensure_eeprom

        settings = settings or load_settings().with_values(MSP_RC_SETTINGS, "RC frames over MSP")
        super().__init__(config, params if params is not None else fc_params(), seed=seed, settings=settings,
                         feedback=feedback, design_model=design_model)
        # a rehearsal's firmware (a board runs its own: build_fc_plant passes no SITL)
        binary, eeprom = firmware.get("binary"), firmware.get("eeprom")
        self.binary = Path(binary) if binary is not None else ensure_sitl()
        self.eeprom = Path(eeprom) if eeprom is not None else ensure_eeprom(self.binary, settings=self.settings)
        self.connection = connection
        self.dry_run = dry_run
        if start_m is not None:
            self.start_m = np.array(start_m, dtype=float)
        elif not isinstance(connection, RehearsalConnection):  # a room: its floor at z = 0 below the start
            self.start_m = np.array([0.0, 0.0, -self.params.volume.z_m[0]])
        if limits is None:  # a rehearsal's room is the plant's volume; a real room's fence is the user's to give
            limits = SafetyLimits()
            if isinstance(connection, RehearsalConnection):
                limits = dataclasses.replace(limits.with_fence_around(self.start_m, self.params.volume),
                                             **REHEARSAL_TIMEOUTS)
        self.safety = limits
        self.kill_requested = False
        # compiled now, not inside a flight's frame deadline
        program_sticks(np.zeros(4), self.pilot.limits, np.zeros(4))
        if isinstance(connection, RehearsalConnection):
            connection.plant_args.update(config=config, params=self.params, binary=self.binary,
                                         eeprom=self.eeprom, settings=self.settings)

    def kill(self) -> None:
        """The operator's kill: the flight in progress disarms at its next frame (callable from any thread)."""
        self.kill_requested = True
        flight = self.flight
        if isinstance(flight, WallClockFlight):
            flight.monitor.kill()

    def fly(self, program: Program | CompiledProgram) -> Trial:
        """One supervised trial on the wall clock; a failure or a safety stop is a trial status, never an exception."""
        wall = time.perf_counter()
        compiled = program.compile() if isinstance(program, Program) else program
        seed = int(self.rng.integers(2**31))
        self.trials_flown += 1
        info: dict[str, Any] = {"firmware": "Betaflight over MSP on a serial port, wall clock"}
        rehearsal = isinstance(self.connection, RehearsalConnection)
        with contextlib.ExitStack() as stack:
            try:
                link = stack.enter_context(self.connection.open(seed))
            except (TimeoutError, RuntimeError, OSError, LinkTimeout, LinkClosed) as error:
                # a rehearsal's firmware that does not start is a lost trial (flown again); a board that
                # cannot be reached is a person's to look at
                return failed_trial(TrialStatus.LOST if rehearsal else TrialStatus.ABORTED,
                                    f"could not reach the flight controller: {error}", info)
            # the ground keeps its deadlines on a busy machine: its frames, poses and serial bytes ahead of
            # other work while the trial flies, where allowed (docs/real-vehicle.md, "Under load")
            info["ground_scheduling"] = stack.enter_context(
                real_time_threads(_ground_threads(link), GROUND_FIFO_PRIORITY))
            trial, flight = self._supervise(link, compiled, info, wall)
        report = link.world.report if link.world is not None else None
        if report is not None:
            trial.info["world"] = dataclasses.asdict(report)
            if report.error and trial.status is not TrialStatus.OK:  # the firmware died or hung in flight
                trial = failed_trial(TrialStatus.LOST, f"firmware lost: {report.error}; the next trial starts a "
                                                       f"new one", trial.info)
        start = trial.info.get("start_time_s")
        if start is not None:
            trial.info["maneuver_frames"] = flight.jitter(start, start + compiled.duration_s)
            if report is not None:
                trial.info["command_latency_s"] = _command_latency(flight, report.set_point_jumps_wall_s, start)
                trial.info["command_latency_world_s"] = _command_latency(flight, report.set_point_jumps_s, start)
        trial.info["frames"] = flight.jitter()
        return trial

    def _supervise(self, link: Link, compiled: CompiledProgram, info: dict[str, Any],
                   wall: float) -> tuple[Trial, WallClockFlight]:
        """Pre-flight, then the supervisor's phases; a safety stop makes the vehicle safe and ends the trial."""
        monitor = SafetyMonitor(self.safety, time.monotonic())
        if self.kill_requested:
            monitor.kill()
        floor = float(self.start_m[2] + self.params.volume.z_m[0])
        flight = WallClockFlight(link.msp, link.poses, monitor, rate_hz=self.params.radio.rate_hz,
                                 time_zero_s=link.time_zero_s, start_m=self.start_m, floor_z_m=floor,
                                 command_latency_s=self.params.radio.latency_s,
                                 rotation_stick_us=self._rotation_stick_us(), volume=self.params.volume)
        self.flight = flight
        try:
            problems = self._preflight(flight, link.msp)
            if problems:
                info["preflight"] = list(problems)
                return failed_trial(TrialStatus.ABORTED, "pre-flight refused: " + "; ".join(problems), info), flight
            if self.dry_run:
                return self._dry_run(flight, compiled, info), flight
            return self._fly(flight, compiled, info, wall), flight
        except SafetyStop as stop:
            info["safety_stop"] = stop.reason.value
            info["disarm_confirmed"] = confirmed = self._make_safe(flight, stop.reason)
            message = str(stop) if confirmed is not False else f"{stop}; THE BOARD STILL REPORTS ITSELF ARMED"
            return failed_trial(_STATUS_FOR.get(stop.reason, TrialStatus.ABORTED), message, info), flight
        except KeyboardInterrupt:  # Ctrl-C is the operator's kill: disarm, then let the session stop
            flight.monitor.kill()
            if self._make_safe(flight, StopReason.KILL) is False:
                warnings.warn("THE BOARD STILL REPORTS ITSELF ARMED after the kill", RuntimeWarning, stacklevel=2)
            raise
        finally:
            self.flight = None

    def _dry_run(self, flight: WallClockFlight, compiled: CompiledProgram, info: dict[str, Any]) -> Trial:
        """The program's frames at the radio rate with ARM off (ACRO, as the maneuver streams them)."""
        n = flight.frames_for(compiled.duration_s)
        commands = frames_of(compiled, 1.0 / self.params.radio.rate_hz, n)
        sticks = np.zeros(4)
        start = flight.time_s
        for k in range(n):
            program_sticks(commands[k], self.pilot.limits, sticks)
            flight.frame(self.pilot.channels(sticks, arm=False, angle=False))
        info["dry_run"] = flight.jitter(start)
        return failed_trial(TrialStatus.ABORTED, f"dry run: pre-flight passed; the program's {n} frames streamed "
                                                 f"disarmed; nothing flew, nothing measured", info)

    def _rotation_stick_us(self) -> float:
        """The stick deflection [µs] asking for :data:`~.world.SET_POINT_JUMP_DEG_S` on the most sensitive axis."""
        sticks = (abs(self.settings.stick_for_rate(axis, SET_POINT_JUMP_DEG_S)) for axis in ("roll", "pitch", "yaw"))
        return min(sticks) * 500.0

    def _preflight(self, flight: WallClockFlight, msp: MspClient) -> tuple[str, ...]:
        idle = self.pilot.channels(np.array([0.0, 0.0, 0.0, float(RC_MIN_US)]), arm=False, angle=True)
        status: StatusEx | None = None
        battery: Battery | None = None
        # disarmed frames until the receiver sees a live link and the gyro has calibrated (a board
        # just powered on calibrates for a second or two), then the checks
        deadline_s = flight.time_s + self.params.pilot.calibration_s + _CALIBRATION_WAIT_S
        flight.battery_stops = False  # a low battery on the ground is the pre-flight's to name, not a stop
        while True:
            for _ in range(flight.frames_for(_PREFLIGHT_FRAMES_S)):
                flight.frame(idle)
            try:
                status, battery = msp.status_ex(), msp.battery()
            except (LinkClosed, LinkTimeout, MspError):
                status = battery = None
            if status is None or not status.arming_disable_flags or flight.time_s > deadline_s:
                break
        features: int | None = None
        ranges: tuple[MspModeRange, ...] | None = None
        failsafe: FailsafeConfig | None = None
        with contextlib.suppress(LinkClosed, LinkTimeout, MspError):  # no answer: the check says so
            features, ranges = msp.features(), msp.mode_ranges()
        with contextlib.suppress(LinkClosed, LinkTimeout, MspError):
            failsafe = msp.failsafe()
        rows = flight.mocap()
        recent = rows[rows[:, 0] > flight.time_s - _PREFLIGHT_FRAMES_S] if rows.shape[0] else rows
        rate_hz = recent.shape[0] / _PREFLIGHT_FRAMES_S
        position = tuple(rows[-1, 1:4]) if rows.shape[0] else None
        floor = self.start_m + np.array([0.0, 0.0, self.params.volume.z_m[0]])
        check = preflight(self.safety, status=status, battery=battery, mocap_rate_hz=rate_hz,
                          position_m=position, start_m=floor)
        flight.battery_stops = True
        problems = (configuration_problems(features, ranges, self.settings.modes)
                    + failsafe_problems(failsafe, self.safety) + check.problems)
        if not self.connection.require_battery:
            problems = tuple(p for p in problems if not p.startswith("battery:"))
        return problems

    def _make_safe(self, flight: WallClockFlight, reason: StopReason) -> bool | None:
        """Disarm at once; with the link gone, send nothing and watch the firmware's RX-loss failsafe bring it down.

        Returns whether the board then reports itself disarmed (MSP_STATUS_EX; disarmed frames are sent
        again while it does not, :data:`_DISARM_ATTEMPTS` times), None when it cannot be asked (the link).
        """
        if reason is StopReason.LINK_LOST:
            deadline_s = flight.time_s + _FAILSAFE_WAIT_S
            while flight.time_s < deadline_s:
                with contextlib.suppress(SafetyStop):
                    flight.watch(0.05)
                if flight.on_floor and np.linalg.norm(flight.x[3:6]) < 0.05:
                    break
            return None
        low = self.pilot.channels(np.array([0.0, 0.0, 0.0, float(RC_MIN_US)]), arm=False, angle=True)
        for _attempt in range(_DISARM_ATTEMPTS):
            for _ in range(flight.frames_for(_SAFE_FRAMES_S)):
                with contextlib.suppress(SafetyStop):
                    flight.frame(low)
            try:  # the board says whether it disarmed; disarmed frames go on while it says it is armed
                armed = flight.msp.status_ex().armed
            except (LinkClosed, LinkTimeout, MspError):
                return None
            if not armed:
                return True
        return False

    def _ok_message(self, info: dict[str, Any]) -> str:
        return f"maneuver flown over MSP on the wall clock ({info['frames_sent']} radio frames)"

    def _timing(self, flight: Any, wall: float) -> dict[str, Any]:
        elapsed = time.perf_counter() - wall
        # the flight is the wall clock's: no simulated time of its own, no firmware CPU time to compare with
        return {"wall_s": elapsed, "flight_s": flight.time_s if flight is not None else 0.0,
                "steps": flight.tick if flight is not None else 0}  # radio frames: the wall clock has no steps


def build_fc_plant(config: VehicleConfig, settings: FcSettings, *, seed: int = 0,
                   feedback: Any = None, design_model: VehicleConfig | None = None) -> FlightControllerPlant:
    """The plant ``--plant fc --fc FILE`` flies: a rehearsal, or a board and the room's motion capture."""
    feedback = "none" if feedback is None else feedback
    if settings.link.kind is LinkKind.REHEARSAL:
        return FlightControllerPlant(config, RehearsalConnection({}), settings.betaflight, seed=seed,
                                     feedback=feedback, dry_run=settings.link.dry_run, design_model=design_model)
    connection = BoardConnection(settings.link.port, None, settings.link.baudrate_bd)
    connection.check()  # the port first: a missing board is refused before the motion capture is asked
    mocap = settings.mocap
    connection.poses = MotionCaptureSource(mocap.system, mocap.body, latency_s=mocap.latency_s,
                                           options={"hostname": mocap.hostname} if mocap.hostname else None)
    # a board runs its own firmware: no SITL is built or configured for it
    return FlightControllerPlant(config, connection, settings.betaflight, limits=settings.limits, seed=seed,
                                 feedback=feedback, dry_run=settings.link.dry_run, start_m=settings.start_m,
                                 design_model=design_model,
                                 binary=Path(os.devnull), eeprom=Path(os.devnull))


def _command_latency(flight: WallClockFlight, jumps_s: Sequence[float], start_s: float) -> float | None:
    """From sending the maneuver's first rotation frame to the firmware's rate set point jumping [s].

    The ground notes when a frame first deflects a roll, pitch or yaw stick (the program's first rate
    command: a step), the rehearsal's world when the firmware's rate set point rises above 200 °/s (to
    its 1 ms chunk), on the wall clock (``set_point_jumps_wall_s``: what a board on its own clock would
    show) or in the world's time (``set_point_jumps_s``: earlier by the world's lag then); None when
    either moment is unknown.
    """
    sent = [t for t in flight.deflections_s if t >= start_s - 0.1]
    jumps = [t for t in jumps_s if sent and t >= sent[0]]
    return jumps[0] - sent[0] if jumps else None
