"""Compiled parts of the lab that every plant flying through motion capture shares.

``mocap_sample`` takes one motion-capture sample of a state with pre-drawn noise,
``estimate_pose`` is the supervisor's estimate from the samples so far (last pose, line-fit
velocity), ``pd_command`` the supervisor's cascaded PD(+I) hover controller and ``settled`` its
test that the vehicle is at the start and still (every plant's settle uses it). The arena's
compiled supervisor inlines them (``inline="always"``), the RotorPy and Betaflight plants call
them from their own loops; :mod:`aerobat.plants.mocap` is the NumPy side (measured states and
final-state estimates from the samples).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

__all__ = ["MOCAP_COLUMNS", "estimate_pose", "mocap_sample", "pd_command", "settled"]

# mocap record columns: t, x, y, z, qw, qx, qy, qz
MOCAP_COLUMNS = 8

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


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def settled(pos, vel, quat, target, position_m, velocity_m_s, tilt_rad):  # pragma: no cover - compiled
    """Is the estimate (``pos`` [m], ``vel`` [m/s], ``quat`` (w, x, y, z)) at ``target`` and still?

    Within ``position_m`` of the target, slower than ``velocity_m_s``, and the body z axis within
    ``tilt_rad`` of vertical. A supervisor's settle is this for its hold time.
    """
    dp = math.sqrt((pos[0] - target[0]) ** 2 + (pos[1] - target[1]) ** 2 + (pos[2] - target[2]) ** 2)
    dv = math.sqrt(vel[0] ** 2 + vel[1] ** 2 + vel[2] ** 2)
    qx = quat[1]
    qy = quat[2]
    tilt = math.acos(max(-1.0, min(1.0, 1.0 - 2.0 * (qx * qx + qy * qy))))
    return dp < position_m and dv < velocity_m_s and tilt < tilt_rad
