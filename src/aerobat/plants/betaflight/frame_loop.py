"""Radio frames and the supervisor around them in one compiled loop: Python once per chunk of frames.

A trial through the firmware is ~3,700 radio frames of ~32 gyro steps each. The steps of a frame
have run compiled since :mod:`.lockstep`; the frame around them — the radio's drop draw and
latency queue, the sensor and motion-capture noise, the RC packets, and the supervisor's ANGLE
pilot (estimate, sticks, channels, volume check, "settled?") — was Python, ≈ 75 µs a frame, as
long as the firmware's own work on the frame's steps. While Python worked the firmware waited, went
to sleep, and cost a wake-up at the next step. :func:`fly_frames` does all of it for a run of
frames, with the same arithmetic in the same order and the same draws from the same generator
(numba's ``np.random.Generator`` is NumPy's stream), so a seed repeats a flight bit for bit
whichever loop flies it.

A call flies one :class:`~aerobat.plants.fpv.frames.Mode` (steps only, given channels, or the ANGLE pilot's
frames, sticks from the motion-capture estimate: :func:`~aerobat.plants.fpv.pilot.angle_sticks`) with one
:class:`~aerobat.plants.fpv.frames.Radio`; after each frame an optional truth row, the optional flight-volume
check and an optional :class:`~aerobat.plants.fpv.frames.Until` stop condition.

A call returns ``(status, frames completed)``. Besides the statuses of :mod:`.lockstep`
(:data:`~.lockstep.NO_ANSWER`, :data:`~.lockstep.SEND_FAILED`, :data:`~.lockstep.NON_FINITE`:
the frame in progress stops at step ``st[S_STEP]``, and the caller finishes that step with the
process's watchdog and calls again with ``resume``), :data:`~aerobat.plants.fpv.frames.RC_FAILED` (the RC packet at the
queue's head could not be sent; the caller sends it, drops it from the queue and calls again),
and the codes of :mod:`aerobat.plants.fpv.frames` (a stop condition met, a crash, the axis in ``st[S_AXIS]``).
:class:`.flight.Flight` owns the arrays and drives the calls.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from numba.core import types

from aerobat.firmware.betaflight.packets import RC_STRUCT
from aerobat.plants.betaflight.frame_noise import ALL, begin_draws, draw_noise
from aerobat.plants.betaflight.lockstep import DONE, IO_MOCAP_USED, SEND_FAILED, run_steps
from aerobat.plants.betaflight.physics import C_CONTACT
from aerobat.plants.fpv.frames import (
    CRASH_FLOOR,
    CRASH_VOLUME,
    F_AIRBORNE_S,
    F_WORST_MEASURED_M,
    F_WORST_TRUE_M,
    K_EXCHANGE,
    K_LATENCY_STEPS,
    K_RC_FD,
    K_SHM,
    P_AHEAD_S,
    P_DURATION_S,
    P_FEEDBACK,
    P_FIRST_FRAME,
    P_LAW_LATENCY_S,
    P_PERIOD_S,
    P_REFERENCE_DT_S,
    P_SETTLE_HOLD,
    P_SETTLE_POSITION_M,
    P_SETTLE_TILT_RAD,
    P_SETTLE_VELOCITY_M_S,
    P_START_TIME_S,
    Q_DROP_PROBABILITY,
    Q_MOCAP_LATENCY_S,
    Q_STEP_S,
    QUEUE_FULL,
    RC_FAILED,
    S_AXIS,
    S_CALM,
    S_DROPPED,
    S_IN_FRAME,
    S_Q_COUNT,
    S_Q_HEAD,
    S_SENT,
    S_STEP,
    S_TICK,
    UNTIL_MET,
    X_SHM,
    Mode,
    Radio,
    Until,
)
from aerobat.plants.fpv.pilot import angle_sticks, program_sticks
from aerobat.plants.lab_kernels import estimate_pose, settled
from aerobat.quadrotor.feedback import apply_feedback, relay_deviation

__all__ = ["fly_frames"]

# the enums as compile-time integers
M_STREAM, M_ANGLE, M_PROGRAM = int(Mode.STREAM), int(Mode.ANGLE), int(Mode.PROGRAM)
D_NONE, D_RADIO = int(Radio.NONE), int(Radio.LOSSY)
U_ARMED, U_SETTLED, U_TRACK, U_ON_FLOOR = int(Until.ARMED), int(Until.SETTLED), int(Until.TRACK), int(Until.ON_FLOOR)

_RC_BYTES = RC_STRUCT.size  # a double (0.0), then 16 uint16 channels: 40 bytes
_send = types.ExternalFunction("send", types.intp(types.int32, types.uintp, types.uintp, types.int32))
_publish_rc = types.ExternalFunction("aerobat_shm_publish_rc", types.int64(types.uintp, types.uintp, types.int64))


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def _estimate(log, available, pos, vel, quat):  # pragma: no cover - compiled
    # a call of its own, compiled as the Python supervisor's estimate_pose was (fastmath)
    return estimate_pose(log, available, pos, vel, quat)


@nb.njit(cache=True, error_model="numpy")
def _estimate_now(log, count, time_s, latency_s, pos, vel, quat):  # pragma: no cover - compiled
    """The supervisor's estimate at ``time_s``: samples older than the latency (``Flight.estimate``)."""
    pos[:] = 0.0
    vel[:] = 0.0
    quat[0] = 1.0
    quat[1:] = 0.0
    rows = np.searchsorted(log[:count, 0], time_s - latency_s + 1e-12, side="right")
    return _estimate(log, rows, pos, vel, quat)


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def _relay(log, available, start_time, origin, ref, ref_dt, sample, out):  # pragma: no cover - compiled
    # calls of their own, compiled as the Python pilot's were (fastmath)
    return relay_deviation(log, available, start_time, origin, ref, ref_dt, sample, out)


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def _apply(cmd, state, gains, ref, tau, t, scratch):  # pragma: no cover - compiled
    apply_feedback(cmd, state, gains, ref, tau, t, scratch)


@nb.njit(cache=True, error_model="numpy")
def _feedback_law(cmd, log, count, now_s, tau, pilot, origin, gains, ref, onboard, scratch, relay,
                  quat):  # pragma: no cover - compiled
    """The pilot's feedback law on ``cmd`` in place: the arithmetic of frame_by_frame's, NumPy's order."""
    available = np.searchsorted(log[:count, 0], now_s - pilot[P_LAW_LATENCY_S] + 1e-12, side="right")
    if available == 0:
        return
    row = available - 1
    lead = now_s - log[row, 0] + pilot[P_AHEAD_S]
    v0 = cmd[1] * lead
    v1 = cmd[2] * lead
    v2 = cmd[3] * lead
    quat[0] = v0
    quat[1] = v1
    quat[2] = v2
    angle = math.sqrt(np.dot(quat[0:3], quat[0:3]))  # quaternion_from_rotation_vector
    if angle < 1e-15:
        d = math.sqrt(1.0 + 0.25 * angle * angle)
        w2, x2, y2, z2 = 1.0 / d, 0.5 * v0 / d, 0.5 * v1 / d, 0.5 * v2 / d
    else:
        c = math.cos(angle / 2)
        s = math.sin(angle / 2)
        w2, x2, y2, z2 = c, s * (v0 / angle), s * (v1 / angle), s * (v2 / angle)
    w1, x1, y1, z1 = log[row, 4], log[row, 5], log[row, 6], log[row, 7]  # quaternion_multiply
    quat[0] = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2
    quat[1] = w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2
    quat[2] = w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2
    quat[3] = w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2
    norm = math.sqrt(np.dot(quat, quat))
    for i in range(4):
        onboard[i] = quat[i] / norm
    if _relay(log, available, pilot[P_START_TIME_S], origin, ref, pilot[P_REFERENCE_DT_S], scratch, relay):
        for i in range(6):
            onboard[4 + i] = relay[i]
        onboard[10] = log[row, 0]
        onboard[11] = 1.0
    _apply(cmd, onboard, gains, ref, tau, now_s, scratch)


@nb.njit(cache=True, error_model="numpy")
def _norm3(v):  # pragma: no cover - compiled
    return math.sqrt(np.dot(v, v))


@nb.njit(cache=True, error_model="numpy")
def _stick_us(position):  # pragma: no cover - compiled
    """rc.stick_to_us: 1000–2000 us, rounded half to even like Python's round."""
    return np.int64(np.rint(1500.0 + 500.0 * min(max(position, -1.0), 1.0)))


@nb.njit(cache=True, error_model="numpy")
def _send_rc(cfg, queue_rc, head, rc_block, rc_words):  # pragma: no cover - compiled
    for c in range(16):
        rc_words[4 + c] = queue_rc[head, c]
    if cfg[K_EXCHANGE] == X_SHM:
        return cfg[K_SHM] != 0 and _publish_rc(cfg[K_SHM], rc_block.ctypes.data, _RC_BYTES) >= 0
    return _send(cfg[K_RC_FD], rc_block.ctypes.data, _RC_BYTES, 0) == _RC_BYTES


@nb.njit(cache=True, error_model="numpy")
def _steps(n, resume, rng, cfg, fcfg, st, x, block, motors, plant, aux, pending, counters, noise, mocap_noise, log,
           packet, scratch, queue_due, queue_rc, rc_block, rc_words):  # pragma: no cover - compiled
    """The frame in progress from step ``st[S_STEP]`` to ``n``: RC packets as they come due, exchange, physics.

    The frame's noise is drawn as the steps need it and while the firmware works (shared memory),
    or all at once before the first step (UDP); all of it before the frame ends.
    """
    tick0 = st[S_TICK]
    size = queue_due.shape[0]
    i = st[S_STEP]
    while i < n:
        if not resume:
            while st[S_Q_COUNT] > 0 and queue_due[st[S_Q_HEAD]] <= tick0 + i:  # RC frames reach the receiver first
                if not _send_rc(cfg, queue_rc, st[S_Q_HEAD], rc_block, rc_words):
                    st[S_STEP] = i
                    return RC_FAILED
                st[S_Q_HEAD] = (st[S_Q_HEAD] + 1) % size
                st[S_Q_COUNT] -= 1
        stop = min(n, queue_due[st[S_Q_HEAD]] - tick0) if st[S_Q_COUNT] > 0 else n
        if cfg[K_EXCHANGE] == X_SHM and cfg[K_SHM] == 0:
            status = SEND_FAILED  # the region is closed: the Python exchange raises
        else:
            status, i = run_steps(cfg, i, stop, resume, tick0, fcfg[Q_STEP_S], x, block, motors, plant, aux, pending,
                                  counters, noise, mocap_noise, log, st, packet, scratch, rng, fcfg)
        resume = 0
        if status != DONE:
            st[S_STEP] = i
            return status
    draw_noise(ALL, rng, cfg, fcfg, st, noise, mocap_noise)  # the next draws are the next frame's
    st[S_TICK] = tick0 + n
    st[S_IN_FRAME] = 0
    st[S_STEP] = 0
    return DONE


@nb.njit(cache=True, error_model="numpy")
def _begin_frame(n, drop, rng, cfg, fcfg, st, channel_row, noise, mocap_noise, queue_due,
                 queue_rc):  # pragma: no cover - compiled
    """The radio's draw and queue, then the frame's noise draws laid out (taken by the steps); False: queue full."""
    if drop != D_NONE:
        dropped = drop == D_RADIO and rng.random() < fcfg[Q_DROP_PROBABILITY]
        st[S_SENT] += 1
        if dropped:
            st[S_DROPPED] += 1
        else:
            size = queue_due.shape[0]
            if st[S_Q_COUNT] == size:
                return False
            slot = (st[S_Q_HEAD] + st[S_Q_COUNT]) % size
            queue_due[slot] = st[S_TICK] + cfg[K_LATENCY_STEPS]
            queue_rc[slot, :] = channel_row
            st[S_Q_COUNT] += 1
    begin_draws(n, cfg, fcfg, st, mocap_noise)  # the frame's noise: drawn by the steps (frame_noise)
    st[IO_MOCAP_USED] = 0
    st[S_STEP] = 0
    st[S_IN_FRAME] = 1
    return True


@nb.njit(cache=True, error_model="numpy")
def _outside(st, log, start, volume):  # pragma: no cover - compiled
    """CRASH_FLOOR, CRASH_VOLUME (axis in st) or DONE: the plant's flight-volume check after a frame."""
    if st[0] == 0:  # no motion-capture sample yet
        return DONE
    row = st[0] - 1
    for axis in range(3):
        rel = log[row, 1 + axis] - start[axis]
        if rel < volume[axis, 0] or rel > volume[axis, 1]:
            st[S_AXIS] = axis
            return CRASH_VOLUME
    return DONE


@nb.njit(cache=True, error_model="numpy")
def fly_frames(mode, frames, n, drop, resume, check, until, rng, cfg, fcfg, st, fst, x, block, motors, plant, aux,
               pending, counters, packet, scratch, noise, mocap_noise, log, queue_due, queue_rc, rc_block, rc_words,
               channels, pilot, target, integral, gains, limits, start, volume, record, est, commands, fb_gains,
               reference, onboard, fb_scratch, relay):  # pragma: no cover - compiled
    """Up to ``frames`` frames of ``n`` gyro steps; returns (status, frames completed).

    ``channels``: (k, 16) RC channels [us], one row per frame or one for all (:data:`M_ANGLE`:
    the row its sticks fill in). ``pilot``, ``target``, ``integral``, ``gains``, ``limits``: the
    ANGLE pilot's (:func:`~aerobat.plants.fpv.pilot.angle_sticks`; the integral is updated in place). ``start`` and
    ``volume`` (3, 2): the flight volume around the start [m]. ``record``: (frames, 1 + 21 [+ 19]) truth
    rows (time [s], state [, the motor packet: motors, set point, PID terms]) after each frame, or
    empty. ``est``: scratch (3 + 3 + 4 + 4).
    :data:`Mode.PROGRAM`: ``commands`` (frames, 4) a row per frame, as sticks through ``limits``;
    with ``pilot[P_FEEDBACK]`` the feedback law first (``fb_gains``, ``reference``, the onboard
    state ``onboard`` updated in place, scratch ``fb_scratch`` (10) and ``relay`` (6)).
    ``resume`` (0 or :data:`.lockstep.RESUME_STEP` / ``RESUME_STORE``): how much of the frame in
    progress's step ``st[S_STEP]`` is done (after the watchdog took its motor packet).
    """
    pos = est[0:3]
    vel = est[3:6]
    quat = est[6:10]
    sticks = est[10:14]
    row = channels[0].copy()
    step_s = fcfg[Q_STEP_S]
    for k in range(frames):
        if st[S_IN_FRAME] == 0:
            if mode == M_STREAM:
                row[:] = channels[k if channels.shape[0] > 1 else 0]
            elif mode == M_ANGLE or mode == M_PROGRAM:
                if mode == M_ANGLE:
                    _estimate_now(log, st[0], st[S_TICK] * step_s, fcfg[Q_MOCAP_LATENCY_S], pos, vel, quat)
                    angle_sticks(pos, vel, quat, target, integral, gains, limits, pilot[P_PERIOD_S], sticks)
                else:
                    cmd = est[14:18]
                    cmd[:] = commands[k]
                    tau = (pilot[P_FIRST_FRAME] + k) * pilot[P_PERIOD_S]
                    if pilot[P_FEEDBACK] != 0.0 and tau < pilot[P_DURATION_S]:
                        _feedback_law(cmd, log, st[0], st[S_TICK] * step_s, tau, pilot, start, fb_gains, reference,
                                      onboard, fb_scratch, relay, est[18:22])
                    program_sticks(cmd, limits, sticks)
                row[0] = _stick_us(sticks[0])
                row[1] = _stick_us(sticks[1])
                row[2] = np.int64(np.rint(min(max(sticks[3], 1000.0), 2000.0)))
                row[3] = _stick_us(sticks[2])
            if not _begin_frame(n, drop, rng, cfg, fcfg, st, row, noise, mocap_noise, queue_due, queue_rc):
                return QUEUE_FULL, k
        status = _steps(n, resume, rng, cfg, fcfg, st, x, block, motors, plant, aux, pending, counters, noise,
                        mocap_noise, log, packet, scratch, queue_due, queue_rc, rc_block, rc_words)
        resume = 0
        if status != DONE:
            return status, k
        now_s = st[S_TICK] * step_s
        if record.shape[0] > 0:
            record[k, 0] = now_s
            record[k, 1:1 + x.shape[0]] = x
            for j in range(record.shape[1] - 1 - x.shape[0]):  # the motor packet's floats, if asked for
                record[k, 1 + x.shape[0] + j] = motors[j]
        if check:
            if counters[C_CONTACT]:
                return CRASH_FLOOR, k + 1
            if _outside(st, log, start, volume) != DONE:
                return CRASH_VOLUME, k + 1
        if until == U_ARMED:
            if min(min(motors[0], motors[1]), min(motors[2], motors[3])) > 0.0:
                return UNTIL_MET, k + 1
        elif until == U_ON_FLOOR:
            if counters[C_CONTACT]:
                return UNTIL_MET, k + 1
        elif until == U_SETTLED or until == U_TRACK:
            _estimate_now(log, st[0], now_s, fcfg[Q_MOCAP_LATENCY_S], pos, vel, quat)
            if until == U_TRACK:
                fst[F_WORST_MEASURED_M] = max(fst[F_WORST_MEASURED_M], _norm3(pos - start))
                fst[F_WORST_TRUE_M] = max(fst[F_WORST_TRUE_M], _norm3(x[0:3] - start))
            else:
                if math.isnan(fst[F_AIRBORNE_S]) and not counters[C_CONTACT]:
                    fst[F_AIRBORNE_S] = now_s
                ok = settled(pos, vel, quat, start, pilot[P_SETTLE_POSITION_M], pilot[P_SETTLE_VELOCITY_M_S],
                             pilot[P_SETTLE_TILT_RAD])
                st[S_CALM] = st[S_CALM] + 1 if ok else 0
                if st[S_CALM] >= pilot[P_SETTLE_HOLD]:
                    return UNTIL_MET, k + 1
    return DONE, frames
