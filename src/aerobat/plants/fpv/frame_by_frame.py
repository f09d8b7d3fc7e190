"""Runs of radio frames in Python, one ``frame()`` call each: for a flight on the wall clock.

A flight controller on a serial port (:mod:`aerobat.plants.fc`) flies one frame per radio period
of real time, with safety checks and MSP traffic in between; it cannot hand a run of frames to
compiled code. :func:`run_frames_by_frame` gives such a flight the same ``run_frames`` as the
compiled :class:`~aerobat.plants.betaflight.flight.Flight`: the same ANGLE pilot, checks and stop conditions, frame by
frame, through the flight's ``frame``, ``estimate``, ``mocap``, ``on_floor`` and ``x``. On a
lockstep :class:`~aerobat.plants.betaflight.flight.Flight` it flies what the compiled loop flies, bit for bit (a test
holds them to it).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from aerobat.firmware.betaflight.rc import RC_MIN_US, stick_to_us
from aerobat.plants.fpv.frames import (
    AnglePilot,
    FeedbackLaw,
    FramesEnd,
    FramesRun,
    Mode,
    ProgramPilot,
    Radio,
    Until,
)
from aerobat.plants.fpv.pilot import angle_sticks, program_sticks
from aerobat.plants.lab_kernels import settled
from aerobat.plants.world_params import Volume
from aerobat.quadrotor.dynamics import quaternion_from_rotation_vector, quaternion_multiply
from aerobat.quadrotor.feedback import apply_feedback, relay_deviation

__all__ = ["run_frames_by_frame"]


def _estimate(flight: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    pos, vel, quat = np.zeros(3), np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
    flight.estimate(pos, vel, quat)
    return pos, vel, quat


def _apply_law(flight: Any, law: FeedbackLaw, tau: float, command: np.ndarray, scratch: np.ndarray,
               relay: np.ndarray) -> np.ndarray:
    """The pilot's feedback law: ``command`` corrected from the latest motion capture (a copy)."""
    cmd = command.copy()
    rows = flight.mocap()
    available = int(np.searchsorted(rows[:, 0], flight.time_s - law.mocap_latency_s + 1e-12, side="right"))
    if available == 0:
        return cmd
    row = rows[available - 1]
    # the latest attitude, carried forward by the commanded rates to when this frame acts
    step = quaternion_from_rotation_vector(cmd[1:4] * (flight.time_s - row[0] + law.ahead_s))
    q = quaternion_multiply(row[4:8], step)
    state = law.state
    state[0:4] = q / np.linalg.norm(q)
    if relay_deviation(rows, available, law.start_time_s, flight.start_m, law.reference, law.reference_dt_s,
                       scratch, relay):
        state[4:10] = relay
        state[10] = row[0]
        state[11] = 1.0
    apply_feedback(cmd, state, law.gains, law.reference, tau, flight.time_s, scratch)
    return cmd


def _outside(flight: Any, volume: Volume) -> int | None:
    """The axis along which the last motion-capture sample is outside the volume around the start, if any."""
    rows = flight.mocap()
    if rows.shape[0] == 0:
        return None
    row = rows[-1]
    for axis, (lo, hi) in enumerate((volume.x_m, volume.y_m, volume.z_m)):
        rel = row[1 + axis] - flight.start_m[axis]
        if rel < lo or rel > hi:
            return axis
    return None


def run_frames_by_frame(flight: Any, volume: Volume | None, mode: Mode, frames: int, *, steps: int | None = None,
                        radio: Radio = Radio.LOSSY, channels_us: np.ndarray | None = None,
                        pilot: AnglePilot | ProgramPilot | None = None, check: bool = False,
                        until: Until = Until.NONE, record: np.ndarray | None = None) -> FramesRun:
    """:meth:`~aerobat.plants.betaflight.flight.Flight.run_frames` through ``flight.frame()``; ``volume``: the
    flight volume (for ``check``)."""
    if mode is Mode.STEPS or steps is not None:
        raise ValueError("a flight on the wall clock flies whole radio frames")
    if check and volume is None:
        raise ValueError("checking the flight volume needs the volume")
    if mode is Mode.ANGLE and not isinstance(pilot, AnglePilot):
        raise ValueError("Mode.ANGLE needs an AnglePilot")
    if mode is Mode.PROGRAM and not isinstance(pilot, ProgramPilot):
        raise ValueError("Mode.PROGRAM needs a ProgramPilot")
    sticks = np.zeros(4)
    scratch, relay = np.empty(10), np.empty(6)
    start = flight.start_m
    airborne: float | None = None
    worst_estimated = worst_true = 0.0
    calm = 0
    for k in range(frames):
        if isinstance(pilot, AnglePilot) and mode is Mode.ANGLE:
            pos, vel, quat = _estimate(flight)
            angle_sticks(pos, vel, quat, pilot.target_m, pilot.integral, pilot.gains, pilot.limits, pilot.period_s,
                         sticks)
        elif isinstance(pilot, ProgramPilot) and mode is Mode.PROGRAM:
            cmd = pilot.commands[k]
            tau = k * pilot.period_s
            if pilot.law is not None and tau < pilot.law.duration_s:
                cmd = _apply_law(flight, pilot.law, tau, cmd, scratch, relay)
            program_sticks(cmd, pilot.limits, sticks)
        if mode is Mode.ANGLE or mode is Mode.PROGRAM:
            assert pilot is not None
            channels: tuple[int, ...] = (stick_to_us(float(sticks[0])), stick_to_us(float(sticks[1])),
                                         int(round(min(max(float(sticks[3]), RC_MIN_US), 2000.0))),
                                         stick_to_us(float(sticks[2])), *pilot.channels_us[4:])
        else:
            assert channels_us is not None
            channels = tuple(int(c) for c in channels_us[k if len(channels_us) > 1 else 0])
        flight.frame(channels, lossless=radio is Radio.LOSSLESS)
        if record is not None:
            record[k, 0] = flight.time_s
            record[k, 1:1 + flight.x.size] = flight.x
            if record.shape[1] > 1 + flight.x.size:  # asked for the firmware's motor packet too
                record[k, 1 + flight.x.size:] = flight.motors[:record.shape[1] - 1 - flight.x.size]
        if check:
            if flight.on_floor:
                return FramesRun(FramesEnd.FLOOR, k + 1)
            axis = _outside(flight, volume)  # type: ignore[arg-type]
            if axis is not None:
                return FramesRun(FramesEnd.VOLUME, k + 1, axis)
        met = False
        if until is Until.ARMED:
            met = min(flight.motor_commands()) > 0.0
        elif until is Until.ON_FLOOR:
            met = flight.on_floor
        elif until is Until.TRACK:
            pos, _, _ = _estimate(flight)
            worst_estimated = max(worst_estimated, float(np.linalg.norm(pos - start)))
            worst_true = max(worst_true, float(np.linalg.norm(flight.x[0:3] - start)))
        elif until is Until.SETTLED:
            assert isinstance(pilot, AnglePilot)
            pos, vel, quat = _estimate(flight)
            if airborne is None and not flight.on_floor:
                airborne = flight.time_s
            ok = settled(pos, vel, quat, start, pilot.settle_position_m, pilot.settle_velocity_m_s,
                         pilot.settle_tilt_rad)
            calm = calm + 1 if ok else 0
            met = calm >= pilot.settle_hold_frames
        if met:
            return FramesRun(FramesEnd.MET, k + 1, None, airborne, worst_estimated, worst_true)
    return FramesRun(FramesEnd.DONE, frames, None, airborne, worst_estimated, worst_true)
