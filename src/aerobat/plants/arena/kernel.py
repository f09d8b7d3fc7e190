"""Compiled pieces of the arena: the vehicle's onboard loop and the supervisor's PD controller.

``advance`` runs the physical vehicle tick by tick at the onboard rate: the
command generator (when a maneuver is running) or the last radio command (when
not), the rate controller with gyro latency, scale error and bias, zero-order
hold of motor commands, RK4 of the true plant, and motion-capture sampling with
pre-drawn noise. No randomness inside: every noise sample comes from the
arena's seeded generator.

``supervise`` is the one entry point; every kernel it calls is ``inline="always"``, so it
is compiled as one unit. (Calling separately compiled numba functions made the result
depend on numba's cache: a freshly compiled ``supervise`` and one loaded from the cache
differed in the last bits, so the first run after a change and every later run of the same
seeded session disagreed by up to ~1e-9 m.)
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from aerobat.quadrotor.dynamics import controller_constants, plant_constants, thrust_commands
from aerobat.quadrotor.feedback import apply_feedback, onboard_propagate, onboard_receive, relay_deviation
from aerobat.quadrotor.playback import rk4_plant_step

__all__ = ["MOCAP_COLUMNS", "advance", "estimate_pose", "mocap_sample", "pd_command", "supervise"]

# mocap record columns: t, x, y, z, qw, qx, qy, qz
MOCAP_COLUMNS = 8


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def advance(x, gyro_prev, tick0, n_ticks, tick_s, plant, ctrl, sensor, latency, radio_cmd,
            bp, coeffs, nseg, man_start_tick, duration_s, mocap_every, mocap_noise, mocap_out,
            fb_gains, reference, onboard, history, scratch):  # pragma: no cover
    """Advance the true vehicle ``n_ticks`` onboard ticks from global tick ``tick0``.

    With a feedback scheme (``fb_gains[0] > 0``) the onboard attitude estimate integrates
    the gyro every tick and, while the program runs, :func:`~aerobat.quadrotor.feedback.apply_feedback`
    corrects its commands towards ``reference``.

    Returns (number of mocap rows written, 0 if finite else 1).
    """
    feedback = fb_gains[0] > 0.0
    n = x.shape[0]
    k1 = np.empty(n)
    k2 = np.empty(n)
    k3 = np.empty(n)
    k4 = np.empty(n)
    tmp = np.empty(n)
    cmd = np.empty(4)
    pc = plant_constants(plant)
    cc = controller_constants(ctrl)
    rows = 0
    seg = 0
    for i in range(n_ticks):
        tick = tick0 + i
        t = tick * tick_s
        if tick % mocap_every == 0 and rows < mocap_out.shape[0]:
            mocap_sample(x, t, mocap_noise[rows], mocap_out[rows])
            rows += 1
        running = False
        if man_start_tick >= 0 and tick >= man_start_tick:
            tau = (tick - man_start_tick) * tick_s
            if tau < duration_s - 1e-12:
                running = True
                while seg < nseg - 1 and bp[seg + 1] <= tau + 1e-12:
                    seg += 1
                for ch in range(4):
                    cmd[ch] = coeffs[seg, ch, 0] + (tau - bp[seg]) * (
                        coeffs[seg, ch, 1] + (tau - bp[seg]) * coeffs[seg, ch, 2])
        if not running:
            for ch in range(4):
                cmd[ch] = radio_cmd[ch]
        gp = (1.0 + sensor[0]) * x[10] + sensor[3]
        gq = (1.0 + sensor[1]) * x[11] + sensor[4]
        gr = (1.0 + sensor[2]) * x[12] + sensor[5]
        if feedback:
            if running:
                apply_feedback(cmd, onboard, fb_gains, reference, (tick - man_start_tick) * tick_s, t, scratch)
            if latency > 0:
                onboard_propagate(onboard, history, t, gyro_prev[0], gyro_prev[1], gyro_prev[2], tick_s)
            else:
                onboard_propagate(onboard, history, t, gp, gq, gr, tick_s)
        if latency > 0:
            ft = thrust_commands(cmd, gyro_prev[0], gyro_prev[1], gyro_prev[2], ctrl, cc)
        else:
            ft = thrust_commands(cmd, gp, gq, gr, ctrl, cc)
        gyro_prev[0] = gp
        gyro_prev[1] = gq
        gyro_prev[2] = gr
        rk4_plant_step(t, x, ft, plant, pc, tick_s, k1, k2, k3, k4, tmp)
        for j in range(n):
            if not math.isfinite(x[j]):
                return rows, 1
    return rows, 0


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def mocap_sample(x, t, noise, out):  # pragma: no cover - compiled
    out[0] = t
    out[1] = x[0] + noise[0]
    out[2] = x[1] + noise[1]
    out[3] = x[2] + noise[2]
    # attitude noise: q ⊗ exp(δ/2), δ small rotation vector in the body frame
    qw = x[6]
    qx = x[7]
    qy = x[8]
    qz = x[9]
    dx = 0.5 * noise[3]
    dy = 0.5 * noise[4]
    dz = 0.5 * noise[5]
    dw = math.sqrt(max(0.0, 1.0 - dx * dx - dy * dy - dz * dz))
    out[4] = qw * dw - qx * dx - qy * dy - qz * dz
    out[5] = qw * dx + qx * dw + qy * dz - qz * dy
    out[6] = qw * dy - qx * dz + qy * dw + qz * dx
    out[7] = qw * dz + qx * dy - qy * dx + qz * dw


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def pd_command(pos, vel, quat, target, integral, gains, limits, dt, out, settling=False):  # pragma: no cover
    """Cascaded PD(+I) hover controller: position → acceleration → attitude → body rates.

    gains = (k_p [1/s²], k_d [1/s], k_att [1/s], k_yaw [1/s], k_i [1/s³]);
    limits = (collective min, max [m/s²], max tilt acceleration [m/s²], max rate [rad/s], g).
    Writes (collective, p̂, q̂, r̂) into ``out``; updates ``integral`` (anti-windup clamp), within 0.1 m of
    the target, or within 0.3 m while ``settling`` and nearly still.
    """
    kp = gains[0]
    kd = gains[1]
    katt = gains[2]
    kyaw = gains[3]
    ki = gains[4]
    g = limits[4]
    a = np.empty(3)
    # settling and nearly still: a steady offset the P term cannot remove (a heavy vehicle sags
    # 10 cm, beyond the 0.1 m window, and would never settle) is trimmed too
    still = settling and vel[0] * vel[0] + vel[1] * vel[1] + vel[2] * vel[2] < 0.05 * 0.05
    for i in range(3):
        err = target[i] - pos[i]
        if abs(err) < 0.1 or (still and abs(err) < 0.3):  # conditional integration: trim only near the target
            integral[i] = min(max(integral[i] + err * dt, -1.0), 1.0)
        a[i] = kp * err - kd * vel[i] + ki * integral[i]
    horiz = math.sqrt(a[0] * a[0] + a[1] * a[1])
    if horiz > limits[2]:
        a[0] *= limits[2] / horiz
        a[1] *= limits[2] / horiz
    a[2] += g
    a[2] = max(a[2], 0.3 * g)
    norm = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    b3x = a[0] / norm
    b3y = a[1] / norm
    b3z = a[2] / norm
    # desired heading: body x along world x projected (yaw 0)
    b2x = b3y * 0.0 - b3z * 0.0
    b2y = b3z * 1.0 - b3x * 0.0
    b2z = b3x * 0.0 - b3y * 1.0
    n2 = math.sqrt(b2x * b2x + b2y * b2y + b2z * b2z)
    b2x /= n2
    b2y /= n2
    b2z /= n2
    b1x = b2y * b3z - b2z * b3y
    b1y = b2z * b3x - b2x * b3z
    b1z = b2x * b3y - b2y * b3x
    qw = quat[0]
    qx = quat[1]
    qy = quat[2]
    qz = quat[3]
    R = np.empty((3, 3))
    R[0, 0] = 1 - 2 * (qy * qy + qz * qz)
    R[0, 1] = 2 * (qx * qy - qw * qz)
    R[0, 2] = 2 * (qx * qz + qw * qy)
    R[1, 0] = 2 * (qx * qy + qw * qz)
    R[1, 1] = 1 - 2 * (qx * qx + qz * qz)
    R[1, 2] = 2 * (qy * qz - qw * qx)
    R[2, 0] = 2 * (qx * qz - qw * qy)
    R[2, 1] = 2 * (qy * qz + qw * qx)
    R[2, 2] = 1 - 2 * (qx * qx + qy * qy)
    Rd = np.empty((3, 3))
    Rd[0, 0] = b1x
    Rd[1, 0] = b1y
    Rd[2, 0] = b1z
    Rd[0, 1] = b2x
    Rd[1, 1] = b2y
    Rd[2, 1] = b2z
    Rd[0, 2] = b3x
    Rd[1, 2] = b3y
    Rd[2, 2] = b3z
    M = Rd.T @ R - R.T @ Rd
    ex = 0.5 * M[2, 1]
    ey = 0.5 * M[0, 2]
    ez = 0.5 * M[1, 0]
    collective = a[0] * R[0, 2] + a[1] * R[1, 2] + a[2] * R[2, 2]
    out[0] = min(max(collective, limits[0]), limits[1])
    out[1] = min(max(-katt * ex, -limits[3]), limits[3])
    out[2] = min(max(-katt * ey, -limits[3]), limits[3])
    out[3] = min(max(-kyaw * ez, -limits[3]), limits[3])


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def estimate_pose(log, available, est_pos, est_vel, est_quat):  # pragma: no cover - compiled
    """Supervisor's estimate from the first ``available`` mocap rows: last pose, line-fit velocity."""
    if available <= 0:
        return False
    first = max(0, available - 20)
    count = available - first
    last = available - 1
    for i in range(3):
        est_pos[i] = log[last, 1 + i]
        est_vel[i] = 0.0
    for i in range(4):
        est_quat[i] = log[last, 4 + i]
    if count >= 3:
        tm = 0.0
        for k in range(first, available):
            tm += log[k, 0]
        tm /= count
        den = 0.0
        for k in range(first, available):
            den += (log[k, 0] - tm) ** 2
        for i in range(3):
            pm = 0.0
            for k in range(first, available):
                pm += log[k, 1 + i]
            pm /= count
            num = 0.0
            for k in range(first, available):
                num += (log[k, 0] - tm) * (log[k, 1 + i] - pm)
            est_vel[i] = num / den
    return True


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def supervise(x, gyro_prev, tick0, end_tick, tick_s, plant, ctrl, sensor, latency, radio_cmd,
              bp, coeffs, nseg, man_start_tick, duration_s, mocap_every, mocap_delay_ticks, mocap_noise,
              log, log_count, period_s, link_delay_ticks, drops, drop_probability, closed_loop, target,
              integral, gains, limits, hover_cmd, volume, settle, fb_gains, reference, onboard, history,
              out):  # pragma: no cover - compiled
    """The supervisor's radio loop (70 Hz) around the vehicle's onboard loop, in one compiled call.

    Every radio period: estimate the state from the motion-capture samples available
    (``mocap_delay_ticks`` old), compute a PD command (or the open-loop placeholder),
    drop it with ``drops[j] < drop_probability``, deliver it after ``link_delay_ticks``,
    check the volume (relative to ``target``, which is always the start position). With
    ``settle = (hold_ticks, pos, vel, tilt)`` and hold_ticks > 0
    it returns as soon as the estimate has stayed within tolerance for hold_ticks.

    ``out`` receives (tick, log_count, noise_used, drops_used, status, bad_row) with status
    0 = ran to end_tick, 1 = non-finite state, 2 = left the volume (row bad_row), 3 = settled.

    With a feedback scheme every command packet also carries the latest motion-capture attitude
    and, once a maneuver was triggered, the deviation from ``reference``; the vehicle takes them
    in when the packet arrives.
    """
    feedback = fb_gains[0] > 0.0
    scratch = np.empty(10)
    relay = np.empty(6)
    relay_q = np.empty(4)
    relay_t = 0.0
    relay_ok = False
    relay_translation = False
    tick = tick0
    noise_used = 0
    drops_used = 0
    status = 0
    bad_row = -1
    cmd = np.empty(4)
    est_pos = np.empty(3)
    est_vel = np.empty(3)
    est_quat = np.empty(4)
    calm = 0
    available = 0
    while tick < end_tick:
        period_start = tick
        now = tick * tick_s
        next_send = (math.floor(now / period_s + 1e-9) + 1.0) * period_s
        send_tick = min(end_tick, int(math.ceil(next_send / tick_s - 1e-9)))
        avail_time = (tick - mocap_delay_ticks) * tick_s + 1e-12
        while available < log_count and log[available, 0] <= avail_time:
            available += 1
        have = estimate_pose(log, available, est_pos, est_vel, est_quat)
        if feedback:
            relay_ok = have
            if have:
                relay_t = log[available - 1, 0]
                for i in range(4):
                    relay_q[i] = log[available - 1, 4 + i]
                relay_translation = man_start_tick >= 0 and relay_deviation(
                    log, available, man_start_tick * tick_s, target, reference, fb_gains[12], scratch, relay)
        if closed_loop and have:
            pd_command(est_pos, est_vel, est_quat, target, integral, gains, limits, period_s, cmd, settle[0] > 0)
        else:
            for i in range(4):
                cmd[i] = hover_cmd[i]
        delivered = drops[drops_used] >= drop_probability
        drops_used += 1
        arrival = tick + link_delay_ticks
        first_written = log_count
        for leg in range(2):
            stop = min(arrival, send_tick) if leg == 0 else send_tick
            if stop > tick:
                rows, bad = advance(x, gyro_prev, tick, stop - tick, tick_s, plant, ctrl, sensor, latency,
                                    radio_cmd, bp, coeffs, nseg, man_start_tick, duration_s, mocap_every,
                                    mocap_noise[noise_used:], log[log_count:], fb_gains, reference, onboard,
                                    history, scratch)
                noise_used += rows
                log_count += rows
                tick = stop
                if bad != 0:
                    status = 1
                    break
            if leg == 0 and delivered and arrival <= send_tick:
                for i in range(4):
                    radio_cmd[i] = cmd[i]
                if feedback and relay_ok:
                    onboard_receive(onboard, history, fb_gains, relay_t, relay_q, relay[0:3], relay[3:6],
                                    relay_translation)
        if status != 0:
            break
        for k in range(first_written, log_count):
            for axis in range(3):
                rel = log[k, 1 + axis] - target[axis]
                if rel < volume[2 * axis] or rel > volume[2 * axis + 1]:
                    status = 2
                    bad_row = k
                    break
            if status == 2:
                break
        if status != 0:
            break
        if settle[0] > 0:
            avail_time = (tick - mocap_delay_ticks) * tick_s + 1e-12
            while available < log_count and log[available, 0] <= avail_time:
                available += 1
            if estimate_pose(log, available, est_pos, est_vel, est_quat):
                dp = math.sqrt((est_pos[0] - target[0]) ** 2 + (est_pos[1] - target[1]) ** 2
                               + (est_pos[2] - target[2]) ** 2)
                dv = math.sqrt(est_vel[0] ** 2 + est_vel[1] ** 2 + est_vel[2] ** 2)
                qx = est_quat[1]
                qy = est_quat[2]
                tilt = math.acos(max(-1.0, min(1.0, 1.0 - 2.0 * (qx * qx + qy * qy))))
                if dp < settle[1] and dv < settle[2] and tilt < settle[3]:
                    calm += tick - period_start
                    if calm >= settle[0]:
                        status = 3
                        break
                else:
                    calm = 0
    out[0] = tick
    out[1] = log_count
    out[2] = noise_used
    out[3] = drops_used
    out[4] = status
    out[5] = bad_row
