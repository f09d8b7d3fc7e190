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

from aerobat.plants.lab_kernels import estimate_pose, mocap_sample, pd_command, settled
from aerobat.quadrotor.dynamics import controller_constants, plant_constants, thrust_commands
from aerobat.quadrotor.feedback import apply_feedback, onboard_propagate, onboard_receive, relay_deviation
from aerobat.quadrotor.playback import rk4_plant_step

__all__ = ["advance", "supervise"]


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
                if settled(est_pos, est_vel, est_quat, target, settle[1], settle[2], settle[3]):
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
