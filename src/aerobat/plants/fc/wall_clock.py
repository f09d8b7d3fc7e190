"""A flight on the wall clock: what the Fig. 8 supervisor drives when the flight controller is real.

:class:`WallClockFlight` offers the supervisor (the phases of
:class:`~aerobat.plants.betaflight.plant.BetaflightPlant`: arm, settle, hover, stream the program,
return, land) the same few operations as the lockstep :class:`~aerobat.plants.betaflight.flight.Flight`,
but against time that does not wait: :meth:`~WallClockFlight.frame` sends one RC frame as
``MSP_SET_RAW_RC`` at its deadline on the monotonic clock, then takes in the motion-capture poses and
the flight controller's answers that arrived, and asks the :class:`~.safety.SafetyMonitor` whether to
stop. A stop raises :class:`SafetyStop`; the plant then disarms (or, with the link gone, leaves the
vehicle to the firmware's RX-loss failsafe).

What the lockstep flight knows and a real one does not: the true state. ``x`` here is the best the
ground knows — the motion-capture estimate, with the true position when the source is the rehearsal's
simulated one. Every frame's deadline and the moment it was sent are kept, so the trial reports its
frame jitter and the deadlines it missed.
"""

from __future__ import annotations

import collections
import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from aerobat.firmware.betaflight.errors import LinkClosed, LinkTimeout
from aerobat.firmware.betaflight.msp import MSP_BATTERY_STATE, MSP_SET_RAW_RC, Battery, MspClient
from aerobat.plants.fpv.frame_by_frame import run_frames_by_frame
from aerobat.plants.fpv.frames import FramesRun, Mode
from aerobat.plants.lab_kernels import MOCAP_COLUMNS, estimate_pose
from aerobat.plants.world_params import Volume
from aerobat.quadrotor.dynamics import N_STATE

from .pose_source import Pose, PoseSource
from .safety import SafetyMonitor, StopReason

__all__ = ["SafetyStop", "WallClockFlight"]

_LATE_FRAME_FRACTION = 0.5  # a frame sent more than half a period after its deadline missed it
_CENTRE_US = 1500
_RESOLUTION_S = 1e-3  # the step the supervisor's latency arithmetic counts in (latency_steps × step_s)


class SafetyStop(Exception):
    """The safety monitor stopped the flight: ``reason`` (a :class:`~.safety.StopReason`) and what it saw."""

    def __init__(self, reason: StopReason, detail: str) -> None:
        super().__init__(f"{reason.value}: {reason.meaning} ({detail})")
        self.reason = reason
        self.detail = detail


class WallClockFlight:
    """One flight of a real (or rehearsed) flight controller, frame by frame on the wall clock.

    Parameters
    ----------
    msp : the flight controller's MSP client (on a :class:`~aerobat.firmware.betaflight.serial_link.SerialTransport`).
    poses : the vehicle's motion capture.
    monitor : the safety monitor (its limits, its kill).
    rate_hz : RC frames per second.
    time_zero_s : ``time.monotonic()`` at the flight's time zero (the rehearsal's world start).
    start_m : the maneuver start in the motion-capture frame.
    floor_z_m : the floor's height, for ``on_floor`` when the source knows no truth.
    command_latency_s : from sending a frame to the firmware acting on it (the supervisor dates the
        maneuver's start with it).
    battery_period_s : how often the battery is asked for (MSP_BATTERY_STATE) during the flight.
    rotation_stick_us : a roll, pitch or yaw stick this far from the centre asks for a rotation (in ACRO,
        the rehearsal's set-point threshold): the frames that first do are noted (``deflections_s``).
    volume : the flight volume around the start, for the supervisor's checks (:meth:`run_frames`).
    """

    packet_columns = 0  # no motor packet: a board sends none
    """Rows of ``record`` hold the truth only: the board's set point and PID terms never reach the link, and
    its motors only when asked (an MSP request per frame would take the link's time from the frames)."""

    def __init__(self, msp: MspClient, poses: PoseSource, monitor: SafetyMonitor, *, rate_hz: float,
                 time_zero_s: float, start_m: np.ndarray, floor_z_m: float, command_latency_s: float,
                 battery_period_s: float = 1.0, rotation_stick_us: float = 100.0,
                 volume: Volume | None = None) -> None:
        self.msp = msp
        self.poses = poses
        self.monitor = monitor
        self.period_s = 1.0 / rate_hz
        self.rate_hz = rate_hz
        self.time_zero_s = time_zero_s
        self.start_m = np.asarray(start_m, dtype=float)
        self.volume = volume
        self.floor_z_m = floor_z_m
        self.step_s = _RESOLUTION_S
        self.latency_steps = round(command_latency_s / _RESOLUTION_S)
        self.log = np.empty((4096, MOCAP_COLUMNS))
        self.log_count = 0
        self.frames_sent = 0
        self.frames_dropped = 0  # a real link loses frames unseen: counted by the flight controller, not here
        self.frames_late = 0
        self.deadlines: list[tuple[float, float]] = []  # (deadline, sent) in flight time [s]
        self.answers = 0
        self._posted: collections.deque[float] = collections.deque()  # frames not yet acknowledged
        self._acks_dropped = msp.discarded[MSP_SET_RAW_RC]  # acknowledgements a request read and dropped
        self._answered_at_s = msp.answered_at_s  # the link's last sign of life before this flight
        self.acks: list[tuple[float, float]] = []  # (frame sent, its acknowledgement) in flight time [s]
        self.rotation_stick_us = rotation_stick_us
        self.deflections_s: list[float] = []  # frames whose roll, pitch or yaw stick left the centre [s]
        self._deflected = False
        self.battery: Battery | None = None
        self.battery_period_s = battery_period_s
        self.battery_stops = True  # off while the pre-flight checks the battery itself
        self._battery_due_s = -math.inf
        self._next_s: float | None = None
        self._true_position: tuple[float, float, float] | None = None
        self._on_floor: bool | None = None
        self.x = np.zeros(N_STATE)
        self.x[6] = 1.0
        self.tick = 0
        # the compiled estimate loads now, not inside the first frame's deadline (≈0.5 s from its cache),
        # and the safety clocks start after it
        estimate_pose(self.log, 0, np.zeros(3), np.zeros(3), np.zeros(4))
        monitor.start(time.monotonic())

    # ------------------------------------------------------------------ time
    @property
    def time_s(self) -> float:
        """Seconds since the flight's time zero, on the monotonic clock."""
        return time.monotonic() - self.time_zero_s

    def frames_for(self, seconds: float) -> int:
        """Radio frames in ``seconds`` (at least one)."""
        return max(1, math.ceil(seconds * self.rate_hz - 1e-9))

    # ------------------------------------------------------------------ frames
    def frame(self, channels_us: Sequence[int], *, lossless: bool = False) -> None:
        """Send one RC frame at its deadline, take in what arrived, and check safety (raises :class:`SafetyStop`)."""
        del lossless  # a real link is never lossless: it loses what it loses
        now = self.time_s
        if self._next_s is None:
            self._next_s = now
        elif now < self._next_s:
            time.sleep(self._next_s - now)
        deadline = self._next_s
        try:
            self.msp.post_raw_rc(channels_us)
        except (LinkClosed, LinkTimeout) as error:
            self._stop(StopReason.LINK_LOST, str(error))
        sent = self.time_s
        self._posted.append(sent)
        self.deadlines.append((deadline, sent))
        deflected = max(abs(int(channels_us[i]) - _CENTRE_US) for i in (0, 1, 3)) > self.rotation_stick_us
        if deflected and not self._deflected:
            self.deflections_s.append(sent)
        self._deflected = deflected
        if sent - deadline > _LATE_FRAME_FRACTION * self.period_s:
            self.frames_late += 1
        # the schedule holds (no drift); a frame that is a whole period late starts a new schedule
        self._next_s = deadline + self.period_s if sent - deadline < self.period_s else sent + self.period_s
        self.frames_sent += 1
        self.tick += 1
        self._take_in()

    def run_frames(self, mode: Mode, frames: int, **run: Any) -> FramesRun:
        """The supervisor's runs of frames, one :meth:`frame` per radio period (:func:`.run_frames_by_frame`)."""
        return run_frames_by_frame(self, self.volume, mode, frames, **run)

    def watch(self, seconds: float) -> None:
        """Send nothing for ``seconds``, taking in poses (after a link loss: the vehicle is the firmware's)."""
        end_s = time.monotonic() + seconds
        while (remaining_s := end_s - time.monotonic()) > 0:
            for pose in self.poses.wait(remaining_s):
                self._log(pose)
        self._update_x()

    def _log(self, pose: Pose) -> None:
        if self.log_count == self.log.shape[0]:
            grown = np.empty((2 * self.log.shape[0], MOCAP_COLUMNS))
            grown[: self.log_count] = self.log[: self.log_count]
            self.log = grown
        row = self.log[self.log_count]
        row[0] = pose.measured_s - self.time_zero_s
        row[1:4] = pose.position_m
        row[4:8] = pose.quaternion_wxyz
        self.log_count += 1
        self.monitor.pose(pose.position_m, pose.received_s)
        self._true_position, self._on_floor = pose.true_position_m, pose.on_floor

    def _take_in(self) -> None:
        wall = time.monotonic()
        try:
            if wall >= self._battery_due_s:  # the battery, asked now and read from a later frame's answers
                self.msp.post(MSP_BATTERY_STATE)
                self._battery_due_s = wall + self.battery_period_s
            answers = self.msp.collect(0.0)
        except (LinkClosed, LinkTimeout) as error:
            self._stop(StopReason.LINK_LOST, str(error))
        self.answers += len(answers)
        if self.msp.answered_at_s > self._answered_at_s:  # any new answer is a sign of life, a request's included
            self._answered_at_s = self.msp.answered_at_s
            self.monitor.link_answered(self._answered_at_s)
        # acknowledgements a request (status, motors, battery) read in between answered the oldest frames:
        # those frames' times are unknown, and the next acknowledgement is a later frame's
        dropped = self.msp.discarded[MSP_SET_RAW_RC]
        for _ in range(min(dropped - self._acks_dropped, len(self._posted))):
            self._posted.popleft()
        self._acks_dropped = dropped
        for command, payload in answers:
            if command == MSP_SET_RAW_RC and self._posted:  # answered in order: the oldest frame's
                self.acks.append((self._posted.popleft(), wall - self.time_zero_s))
            elif command == MSP_BATTERY_STATE and payload:
                self.battery = Battery.decode(payload)
                if self.battery_stops:
                    self.monitor.battery(self.battery)
        for pose in self.poses.wait(0.0):
            self._log(pose)
        self._update_x()
        reason = self.monitor.check(wall)
        if reason is not None:
            raise SafetyStop(reason, self.monitor.detail)

    def _stop(self, reason: StopReason, detail: str) -> None:
        if reason is StopReason.LINK_LOST:
            self.monitor.link_answered(-math.inf)
        raise SafetyStop(reason, detail)

    def _update_x(self) -> None:
        pos, vel, quat = np.zeros(3), np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
        if estimate_pose(self.log, self.log_count, pos, vel, quat):
            self.x[0:3] = pos if self._true_position is None else self._true_position
            self.x[3:6] = vel
            self.x[6:10] = quat

    # ------------------------------------------------------------------ measurement
    def estimate(self, pos: np.ndarray, vel: np.ndarray, quat: np.ndarray) -> bool:
        """The supervisor's estimate now: the fit over every pose received (each already its latency old)."""
        return bool(estimate_pose(self.log, self.log_count, pos, vel, quat))

    def mocap(self) -> np.ndarray:
        """The motion-capture log so far: rows (t, x, y, z, qw, qx, qy, qz), t in flight time."""
        return self.log[: self.log_count]

    @property
    def on_floor(self) -> bool:
        """On the floor: the simulated source's truth, else within 5 cm of the floor and slower than 0.2 m/s."""
        if self._on_floor is not None:
            return self._on_floor
        return bool(self.log_count and self.x[2] - self.floor_z_m < 0.05 and np.linalg.norm(self.x[3:6]) < 0.2)

    def motor_commands(self) -> tuple[float, float, float, float]:
        """The flight controller's motor outputs (MSP_MOTOR), 0 stopped … 1 full (armed idle is a few per cent)."""
        try:
            outputs = self.msp.motor_outputs()[:4]
        except (LinkClosed, LinkTimeout) as error:
            self._stop(StopReason.LINK_LOST, str(error))
        self.monitor.link_answered(time.monotonic())
        m = [max(0.0, (v - 1000) / 1000.0) for v in outputs]
        return (m[0], m[1], m[2], m[3])

    def firmware_cpu_time_s(self) -> float | None:
        """Unknown for a flight controller of its own."""
        return None

    def jitter(self, start_s: float = -math.inf, end_s: float = math.inf) -> dict[str, Any]:
        """Frame timing between ``start_s`` and ``end_s`` [flight time]: lateness after the deadline and intervals.

        Keys: ``frames``, ``late_frames`` (sent more than half a period late), ``lateness_median_ms``,
        ``lateness_max_ms``, ``interval_std_ms`` (the spread of the time between frames), ``acknowledged``
        and ``ack_round_trip_median_ms``/``_max_ms``: from sending a frame to reading the firmware's
        acknowledgement, an upper bound of the command-to-firmware latency (the firmware takes the frame
        when it parses it, then answers at once).
        """
        rows = np.array([(d, s) for d, s in self.deadlines if start_s <= d <= end_s]).reshape(-1, 2)
        acks = np.array([(s, a) for s, a in self.acks if start_s <= s <= end_s]).reshape(-1, 2)
        rtt = acks[:, 1] - acks[:, 0]
        lateness = rows[:, 1] - rows[:, 0]
        intervals = np.diff(rows[:, 1])

        def ms(values: np.ndarray, how: Any) -> float | None:  # None, not NaN, for none: the info is JSON
            return float(how(values) * 1e3) if values.size else None

        return {"frames": int(rows.shape[0]),
                "late_frames": int(np.sum(lateness > _LATE_FRAME_FRACTION * self.period_s)),
                "lateness_median_ms": ms(lateness, np.median), "lateness_max_ms": ms(lateness, np.max),
                "interval_std_ms": ms(intervals, np.std), "acknowledged": int(acks.shape[0]),
                "ack_round_trip_median_ms": ms(rtt, np.median), "ack_round_trip_max_ms": ms(rtt, np.max)}

    def close(self) -> None:
        """Nothing to release: the plant owns the link and the source."""
