"""Runs of radio frames: what a run flies (:class:`Mode`, :class:`Radio`, :class:`AnglePilot`), when it stops
(:class:`Until`), how it ended (:class:`FramesRun`), and the compiled loop's codes and slots.

The pilot (:class:`~aerobat.plants.fpv.phases.RadioPilot`) flies its phases as runs of frames through any
flight with a ``run_frames`` method: :class:`~aerobat.plants.betaflight.flight.Flight` runs them compiled
(:mod:`aerobat.plants.betaflight.frame_loop`), a flight on the wall clock frame by frame
(:mod:`.frame_by_frame`). A module
of its own so that both can name these without loading the compiled loop, whose import builds
and loads the shared-memory exchange's C helper.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum, IntEnum

import numpy as np

__all__ = ["AnglePilot", "CRASH_FLOOR", "CRASH_VOLUME", "F_AIRBORNE_S", "F_WORST_MEASURED_M", "F_WORST_TRUE_M",
           "FeedbackLaw", "FramesEnd", "FramesRun", "HELD_ROW", "K_EVERY", "K_EXCHANGE", "K_LATENCY_STEPS",
           "K_MOTOR_FD", "K_RC_FD", "K_SENSOR_NOISE", "K_SHM", "K_SPIN_NS", "K_STATE_FD", "K_WAIT_NS", "Mode",
           "N_CFG", "N_FCFG", "N_FST", "N_PILOT", "N_ST", "P_AHEAD_S", "P_DURATION_S", "P_FEEDBACK", "P_FIRST_FRAME",
           "P_LAW_LATENCY_S", "P_PERIOD_S", "P_REFERENCE_DT_S", "P_SETTLE_HOLD", "P_SETTLE_POSITION_M",
           "P_SETTLE_TILT_RAD", "P_SETTLE_VELOCITY_M_S", "P_START_TIME_S", "ProgramPilot", "QUEUE_FULL",
           "Q_ATTITUDE_NOISE_RAD", "Q_DROP_PROBABILITY", "Q_MOCAP_LATENCY_S", "Q_POSITION_NOISE_M", "Q_STEP_S",
           "RC_FAILED", "Radio", "S_AXIS", "S_CALM", "S_DRAWN", "S_DRAW_STEPS", "S_DRAW_TOTAL", "S_DROPPED",
           "S_HELD", "S_IN_FRAME", "S_Q_COUNT", "S_Q_HEAD", "S_SENT", "S_STEP", "S_TICK", "UNTIL_MET", "Until",
           "X_SHM", "X_UDP"]

# statuses beyond lockstep's DONE, NO_ANSWER, SEND_FAILED, NON_FINITE (0-3)
RC_FAILED = 4
"""The RC packet at the queue's head could not be sent (nothing of the step has happened)."""
UNTIL_MET = 5
"""The stop condition held after the last frame completed."""
CRASH_FLOOR = 6
"""The vehicle touched the floor while the volume was checked."""
CRASH_VOLUME = 7
"""The last motion-capture sample left the flight volume (axis in ``st[S_AXIS]``)."""
QUEUE_FULL = 8
"""The radio's latency queue overflowed (a sizing bug, never a flight's doing)."""


class Mode(IntEnum):
    """What a run of frames flies."""

    STEPS = 0
    """Gyro steps with no radio frame (the firmware hears its receiver another way)."""
    STREAM = 1
    """Frames whose RC channels are given: one row per frame, or one row for all."""
    ANGLE = 2
    """The supervisor's ANGLE-mode frames toward a target, sticks from the motion-capture estimate."""
    PROGRAM = 3
    """A maneuver's commands as ACRO sticks, a row per frame, with the pilot's feedback law if any."""


class Radio(IntEnum):
    """What the radio does with a frame."""

    NONE = 0
    """No frame is sent (steps only)."""
    LOSSLESS = 1
    """The frame always arrives, after the link latency."""
    LOSSY = 2
    """The frame is lost with the radio's drop probability (one draw per frame)."""


class Until(IntEnum):
    """A run's stop condition, checked after each frame."""

    NONE = 0
    ARMED = 1
    """Every motor command above zero: the firmware armed."""
    SETTLED = 2
    """The estimate within the settle tolerances for the hold's frames in a row (records the lift-off)."""
    TRACK = 3
    """Never met: records the largest distance from the start, estimated and true."""
    ON_FLOOR = 4
    """The vehicle rests on the floor."""


X_UDP, X_SHM = 0, 1  # cfg[K_EXCHANGE]: the lockstep exchange

# st (int64): the first N_IO slots are lockstep's io (log rows, mocap noise used, exchanges, resume)
S_TICK = 4  # gyro steps since power-on at the start of the frame in progress (between frames: now)
S_Q_HEAD = 5  # the radio's latency queue: ring head and length
S_Q_COUNT = 6
S_SENT = 7  # radio frames sent and dropped
S_DROPPED = 8
S_STEP = 9  # the step of the frame in progress a call stopped at
S_IN_FRAME = 10  # 1 while a frame's draws are done and its steps are not
S_CALM = 11  # consecutive frames within the settle tolerances
S_AXIS = 12  # the axis that left the volume (CRASH_VOLUME)
S_DRAWN = 13  # the frame in progress's noise draws done so far (frame_noise.draw_noise), of
S_DRAW_TOTAL = 14  # all of them (sensor noise, then motion-capture noise)
S_DRAW_STEPS = 15  # the frame in progress's steps (the draws' layout)
S_HELD = 16  # 1 + the tick of a motion-capture sample waiting for its noise (its state in scratch[HELD_ROW]), or 0
N_ST = 17
HELD_ROW = 6  # scratch's row (after the physics' six) that holds a sample's state until its noise is drawn

# cfg (int64): the flight's constants (K_SHM: the region's address, 0 when closed or over UDP)
K_EXCHANGE, K_STATE_FD, K_MOTOR_FD, K_RC_FD, K_SHM, K_SPIN_NS, K_WAIT_NS, K_EVERY, K_LATENCY_STEPS, \
    K_SENSOR_NOISE = range(10)
N_CFG = 10
# fcfg (float64)
Q_STEP_S, Q_DROP_PROBABILITY, Q_POSITION_NOISE_M, Q_ATTITUDE_NOISE_RAD, Q_MOCAP_LATENCY_S = range(5)
N_FCFG = 5
# pilot (float64): the supervisor's frame period and settle tolerances
P_PERIOD_S, P_SETTLE_POSITION_M, P_SETTLE_VELOCITY_M_S, P_SETTLE_TILT_RAD, P_SETTLE_HOLD = range(5)
# … and the program pilot's: its duration, the maneuver's start, the look-ahead, the reference's step,
# whether the feedback law runs, the run's first frame's index in the program, the law's capture latency
P_DURATION_S, P_START_TIME_S, P_AHEAD_S, P_REFERENCE_DT_S, P_FEEDBACK, P_FIRST_FRAME, P_LAW_LATENCY_S = range(5, 12)
N_PILOT = 12
# fst (float64): what the stop conditions saw
F_AIRBORNE_S, F_WORST_MEASURED_M, F_WORST_TRUE_M = range(3)
N_FST = 3


class FramesEnd(Enum):
    """How a run of frames (:meth:`~aerobat.plants.betaflight.flight.Flight.run_frames`) ended."""

    DONE = "done"
    """Every frame was flown (a stop condition, if any, never held)."""
    MET = "met"
    """The stop condition held after the last frame flown."""
    FLOOR = "floor"
    """The volume was checked and the vehicle touched the floor."""
    VOLUME = "volume"
    """The volume was checked and the last motion-capture sample was outside it."""


@dataclass(frozen=True)
class FramesRun:
    """The outcome of :meth:`~aerobat.plants.betaflight.flight.Flight.run_frames`."""

    end: FramesEnd
    frames: int
    """Frames flown."""
    axis: int | None = None
    """The axis (0 x, 1 y, 2 z) that left the volume (``VOLUME``)."""
    airborne_s: float | None = None
    """:attr:`Until.SETTLED`: when the vehicle first left the floor during the run [s since power-on]."""
    worst_estimated_m: float = 0.0
    """:attr:`Until.TRACK`: the largest estimated distance from the start after a frame [m]."""
    worst_true_m: float = 0.0
    """:attr:`Until.TRACK`: the largest true distance from the start after a frame [m]."""


@dataclass(frozen=True)
class AnglePilot:
    """The supervisor's ANGLE pilot for :attr:`Mode.ANGLE` (:func:`.pilot.angle_sticks`).

    ``integral`` (3) is the pilot's integral state, updated in place; ``gains`` (k_p, k_d, k_i,
    k_yaw) and ``limits`` as :func:`.pilot.angle_sticks` takes them; ``channels`` the 16 RC
    channels [us] its sticks fill in (the mode switches); the settle tolerances are read by
    :attr:`Until.SETTLED`.
    """

    target_m: np.ndarray
    integral: np.ndarray
    gains: np.ndarray
    limits: np.ndarray
    channels_us: tuple[int, ...]
    period_s: float
    settle_position_m: float = 0.0
    settle_velocity_m_s: float = 0.0
    settle_tilt_rad: float = 0.0
    settle_hold_frames: int = 1


@dataclass(frozen=True)
class FeedbackLaw:
    """The offboard pilot's feedback law during a maneuver (:mod:`aerobat.quadrotor.feedback`).

    Before each of the program's frames (until its ``duration_s``) the pilot takes the latest
    motion-capture sample older than the capture's latency ``mocap_latency_s``, carries its attitude forward by the
    commanded rates to when the frame acts (``ahead_s``: the radio's latency), relays the position
    deviation from the ``reference`` (samples every ``reference_dt_s``, from the maneuver's start
    ``start_time_s``) and corrects the command (:func:`~aerobat.quadrotor.feedback.apply_feedback`
    with ``gains``). ``state`` is the onboard estimate, updated in place.
    """

    gains: np.ndarray
    reference: np.ndarray
    reference_dt_s: float
    state: np.ndarray
    duration_s: float
    start_time_s: float
    ahead_s: float
    mocap_latency_s: float


@dataclass(frozen=True)
class ProgramPilot:
    """A maneuver streamed as ACRO sticks for :attr:`Mode.PROGRAM` (:func:`.pilot.program_sticks`).

    ``commands`` (frames, 4): collective [m/s²] and body rates p, q, r [rad/s] FLU, a row per frame;
    ``limits`` the stick map's; ``channels_us`` the 16 RC channels [us] the sticks fill in (the mode
    switches); ``law`` the pilot's feedback (None: open loop).
    """

    commands: np.ndarray
    limits: np.ndarray
    channels_us: tuple[int, ...]
    period_s: float
    law: FeedbackLaw | None = None
