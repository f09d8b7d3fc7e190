"""The machine's limit for aerobat's model: a bare numba RK4 of the same quadrocopter.

Same model as :mod:`aerobat.quadrotor.dynamics` (the paper's Sect. 6): position,
velocity, unit quaternion renormalized every step, body rates, four first-order
motors with separate up/down rates and thrust limits, the onboard rate controller
with its mixer (eqs 14–21), and ∫ω dt — the same 20 states, the same operations
per step. What it leaves out is everything aerobat does *around* the physics:

* fixed inputs — one constant command (collective, p̂, q̂, r̂) for the whole run,
  no program, no breakpoints, no ramps;
* nothing recorded;
* the nominal vehicle's constants written into the code (motors on the arms in
  the paper's + layout, unit thrust gains, no drag, no wind) instead of aerobat's
  generic plant vector, with every division by a constant precomputed as a
  reciprocal;
* the state size known at compile time (loops unrolled) and one workspace for the
  state and the four stages.

It is written the way one would write the fastest plain kernel of this model, so
its speed is the yardstick: measured on the same machine, in the same process,
interleaved with aerobat's kernel, the ratio does not depend on how busy the
(shared) machine is.

``make bench`` (``benchmarks/run.py``) runs it interleaved with aerobat's kernel in
one process and reports aerobat's speed as a ratio of this one.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

__all__ = ["constants", "reference_run"]

# constants vector layout
(_M, _IXX, _IYY, _IZZ, _G, _UP, _DN, _FMIN, _FMAX, _ARM, _KAPPA, _KP, _KQ, _KR,
 _INV_M, _INV_IXX, _INV_IYY, _INV_IZZ, _INV_KAPPA, _TWO_OVER_ARM) = range(20)
_N = 20  # state size, as in aerobat.quadrotor.dynamics


def constants(vehicle, controller) -> np.ndarray:
    """The reference's constants from aerobat's vehicle and controller (nominal model: they coincide)."""
    c = [
        vehicle.mass_kg, vehicle.inertia_xx_kg_m2, vehicle.inertia_yy_kg_m2, vehicle.inertia_zz_kg_m2,
        vehicle.gravity_m_s2, vehicle.motor_rate_up_per_s, vehicle.motor_rate_down_per_s,
        vehicle.rotor_thrust_min_n, vehicle.rotor_thrust_max_n, vehicle.arm_length_m, vehicle.drag_constant_m,
        controller.rate_gain_p_per_s, controller.rate_gain_q_per_s, controller.rate_gain_r_per_s,
    ]
    c += [1.0 / c[_M], 1.0 / c[_IXX], 1.0 / c[_IYY], 1.0 / c[_IZZ], 1.0 / c[_KAPPA], 2.0 / c[_ARM]]
    return np.array(c)


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _derivative(x, cmd, c, dx):  # pragma: no cover - compiled
    qw, qx, qy, qz = x[6], x[7], x[8], x[9]
    p, q, r = x[10], x[11], x[12]
    ixx, iyy, izz, arm, kappa = c[_IXX], c[_IYY], c[_IZZ], c[_ARM], c[_KAPPA]
    two_over_arm = c[_TWO_OVER_ARM]
    # rate controller and mixer (the nominal model inverts exactly)
    mp = ixx * c[_KP] * (cmd[1] - p) + q * r * (izz - iyy)
    mq = iyy * c[_KQ] * (cmd[2] - q) + r * p * (ixx - izz)
    mr = izz * c[_KR] * (cmd[3] - r) + p * q * (iyy - ixx)
    total = c[_M] * cmd[0]
    yaw = mr * c[_INV_KAPPA]
    f1 = 0.25 * (total + yaw - two_over_arm * mq)
    f2 = 0.25 * (total - yaw + two_over_arm * mp)
    f3 = 0.25 * (total + yaw + two_over_arm * mq)
    f4 = 0.25 * (total - yaw - two_over_arm * mp)
    # motors
    fmin, fmax, up, dn = c[_FMIN], c[_FMAX], c[_UP], c[_DN]
    d1 = min(max(f1, fmin), fmax) - x[13]
    d2 = min(max(f2, fmin), fmax) - x[14]
    d3 = min(max(f3, fmin), fmax) - x[15]
    d4 = min(max(f4, fmin), fmax) - x[16]
    dx[13] = (up if d1 > 0.0 else dn) * d1
    dx[14] = (up if d2 > 0.0 else dn) * d2
    dx[15] = (up if d3 > 0.0 else dn) * d3
    dx[16] = (up if d4 > 0.0 else dn) * d4
    # rigid body
    a = (x[13] + x[14] + x[15] + x[16]) * c[_INV_M]
    dx[0] = x[3]
    dx[1] = x[4]
    dx[2] = x[5]
    dx[3] = 2.0 * (qx * qz + qw * qy) * a
    dx[4] = 2.0 * (qy * qz - qw * qx) * a
    dx[5] = (1.0 - 2.0 * (qx * qx + qy * qy)) * a - c[_G]
    dx[6] = -0.5 * (qx * p + qy * q + qz * r)
    dx[7] = 0.5 * (qw * p + qy * r - qz * q)
    dx[8] = 0.5 * (qw * q + qz * p - qx * r)
    dx[9] = 0.5 * (qw * r + qx * q - qy * p)
    tx = arm * (x[14] - x[16])
    ty = arm * (x[15] - x[13])
    tz = kappa * (x[13] - x[14] + x[15] - x[16])
    dx[10] = (tx - q * r * (izz - iyy)) * c[_INV_IXX]
    dx[11] = (ty - r * p * (ixx - izz)) * c[_INV_IYY]
    dx[12] = (tz - p * q * (iyy - ixx)) * c[_INV_IZZ]
    dx[17] = p
    dx[18] = q
    dx[19] = r


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def reference_run(x, cmd, c, h, steps):  # pragma: no cover - compiled
    """``steps`` RK4 steps of length ``h`` from ``x`` (advanced in place) under the constant ``cmd``."""
    work = np.empty((6, _N))
    xs, k1, k2, k3, k4, tmp = work[0], work[1], work[2], work[3], work[4], work[5]
    for j in range(_N):
        xs[j] = x[j]
    for _ in range(steps):
        _derivative(xs, cmd, c, k1)
        for j in range(_N):
            tmp[j] = xs[j] + 0.5 * h * k1[j]
        _derivative(tmp, cmd, c, k2)
        for j in range(_N):
            tmp[j] = xs[j] + 0.5 * h * k2[j]
        _derivative(tmp, cmd, c, k3)
        for j in range(_N):
            tmp[j] = xs[j] + h * k3[j]
        _derivative(tmp, cmd, c, k4)
        for j in range(_N):
            xs[j] += h / 6.0 * (k1[j] + 2.0 * (k2[j] + k3[j]) + k4[j])
        inv_norm = 1.0 / math.sqrt(xs[6] * xs[6] + xs[7] * xs[7] + xs[8] * xs[8] + xs[9] * xs[9])
        for j in range(6, 10):
            xs[j] *= inv_norm
    for j in range(_N):
        x[j] = xs[j]
