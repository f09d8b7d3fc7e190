"""The mixer and the throttle path, as Betaflight 4.6 runs them (``flight/mixer.c``, ``mixTable``).

The throttle from the smoothed ``rcCommand``, its limit, anti-gravity's throttle filter and TPA
(both for the next PID loop), the dynamic lowpasses' cutoffs, throttle boost, thrust
linearisation's compensation; the PID sums mixed for QUADX, air mode fitting the mix and the
throttle into the motors' range (``applyMixerAdjustment``, or the LINEAR/DYNAMIC mixer), thrust
linearisation, the motor endpoints (``motor_idle``, ``motor_output_limit``); and the SITL's motor
packet (its integer microseconds above ``min_command``, in its slot order).
"""

from __future__ import annotations

import numba as nb

from aerobat.quadrotor.firmware import filters
from aerobat.quadrotor.firmware.layout import (
    K_AIRMODE,
    K_BOOST,
    K_MIN_COMMAND,
    K_MIXER,
    K_MOTOR_HIGH,
    K_MOTOR_LOW,
    K_PID_DT,
    K_PIDSUM_LIMIT,
    K_PIDSUM_LIMIT_YAW,
    K_QUANTIZE,
    K_THROTTLE_COMPENSATE,
    K_THROTTLE_LIMIT,
    K_THROTTLE_LIMIT_TYPE,
    K_THRUST_LINEAR,
    K_TPA_BREAKPOINT,
    K_TPA_LOW_ALWAYS,
    K_TPA_LOW_BREAKPOINT,
    K_TPA_LOW_MULTIPLIER,
    K_TPA_MULTIPLIER,
    K_YAW_SIGN,
    Q_MOTORS,
    Z_AG,
    Z_AG_D,
    Z_AG_PREV,
    Z_BOOST,
    Z_MIX,
    Z_MOTOR,
    Z_PACKET,
    Z_PID_SUM,
    Z_RC_COMMAND,
    Z_TPA,
    Z_TPA_FADED,
)
from aerobat.quadrotor.firmware.pid import update_cutoffs

__all__ = ["MIXER_QUADX", "PACKET_SLOT", "mix", "tpa_factor"]

MIXER_QUADX = ((1.0, -1.0, 1.0, -1.0), (1.0, -1.0, -1.0, 1.0), (1.0, 1.0, 1.0, 1.0), (1.0, 1.0, -1.0, -1.0))
"""Betaflight's QUADX mix (throttle, roll, pitch, yaw): M1 rear right, M2 front right, M3 rear left, M4 front left."""
PACKET_SLOT = (3, 0, 1, 2)
"""The SITL motor packet's slot of M1..M4 (sitl.c ``pwmCompleteMotorUpdate``)."""


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def tpa_factor(k, z, throttle):  # pragma: no cover - compiled
    """``getTpaFactorClassic``: D (and P with tpa_mode PD) scaled down above the breakpoint, up below the low one."""
    low = k[K_TPA_LOW_BREAKPOINT]
    past_low = throttle >= low or low <= 0.01
    if past_low or z[Z_TPA_FADED] != 0.0:
        rate = k[K_TPA_MULTIPLIER] * max(throttle - k[K_TPA_BREAKPOINT], 0.0)
        if k[K_TPA_LOW_ALWAYS] == 0.0:
            z[Z_TPA_FADED] = 1.0
    else:
        rate = k[K_TPA_LOW_MULTIPLIER] * (low - throttle)
    return 1.0 - rate


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def _anti_gravity(k, z, throttle):  # pragma: no cover - compiled
    """``pidUpdateAntiGravityThrottleFilter``: the throttle's rate of change, weighted low, PT2-smoothed."""
    previous = z[Z_AG_PREV]
    inverse = 1.0 - throttle
    derivative = abs(throttle - previous) / k[K_PID_DT]
    derivative *= inverse * inverse
    if throttle > previous:
        derivative *= inverse * 0.5
    z[Z_AG_PREV] = throttle
    z[Z_AG_D] = filters.apply(filters.PT2, z, Z_AG, derivative)


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def mix(k, z, time_us):  # pragma: no cover - compiled
    """``mixTable`` and ``writeMotors``: ``Z_MOTOR`` (M1..M4, output units) and ``Z_PACKET`` (slots, 0..1)."""
    throttle = min(max((z[Z_RC_COMMAND + 3] - 1000.0) / 1000.0, 0.0), 1.0)
    limit = k[K_PIDSUM_LIMIT]
    yaw_limit = k[K_PIDSUM_LIMIT_YAW]
    roll = min(max(z[Z_PID_SUM], -limit), limit) / 1000.0
    pitch = min(max(z[Z_PID_SUM + 1], -limit), limit) / 1000.0
    yaw = k[K_YAW_SIGN] * min(max(z[Z_PID_SUM + 2], -yaw_limit), yaw_limit) / 1000.0
    kind = k[K_THROTTLE_LIMIT_TYPE]
    if kind != 0.0 and k[K_THROTTLE_LIMIT] < 1.0:
        throttle = throttle * k[K_THROTTLE_LIMIT] if kind == 1.0 else min(throttle, k[K_THROTTLE_LIMIT])
    _anti_gravity(k, z, throttle)
    z[Z_TPA] = tpa_factor(k, z, throttle)
    update_cutoffs(k, z, time_us, throttle)
    boost = k[K_BOOST]
    if boost > 0.0:
        high_pass = throttle - filters.apply(filters.PT1, z, Z_BOOST, throttle)
        throttle = min(max(throttle + boost * high_pass, 0.0), 1.0)
    linear = k[K_THRUST_LINEAR]
    if linear != 0.0:
        throttle /= 1.0 + k[K_THROTTLE_COMPENSATE] * (1.0 - throttle) ** 2
    high = 0.0
    low = 0.0
    m = z[Z_MIX:Z_MIX + 4]
    for i in range(4):
        row = MIXER_QUADX[i]
        v = roll * row[1] + pitch * row[2] + yaw * row[3]
        if v > high:
            high = v
        elif v < low:
            low = v
        m[i] = v
    spread = high - low
    airmode = k[K_AIRMODE] != 0.0
    transition = 1.0
    if not airmode and throttle < 0.5:
        transition = 0.5 + throttle  # scaleRangef(throttle, 0, 0.5, 0.5, 1)
    mixer = k[K_MIXER]
    if mixer == 0.0:  # LEGACY
        norm = transition / spread if spread > 1.0 else transition
        for i in range(4):
            m[i] *= norm
        throttle = min(max(throttle, -low * norm), 1.0 - high * norm)
    else:  # LINEAR, DYNAMIC
        delta = 0.5 * transition * spread
        norm = transition / spread if spread > 1.0 else transition
        top = -1e300
        bottom = 1e300
        for i in range(4):
            v = m[i]
            if mixer == 1.0:
                hi = v + delta
                lo = v - delta
            else:
                hi = v + abs(v)
                lo = v - abs(v)
            v = (lo - hi) * throttle + hi
            v *= norm
            top = max(top, v)
            bottom = min(bottom, v)
            m[i] = v
        throttle = min(max(throttle, -bottom), 1.0 - top)
    out_low = k[K_MOTOR_LOW]
    out_high = k[K_MOTOR_HIGH]
    span = out_high - out_low
    quantize = (int(k[K_QUANTIZE]) & Q_MOTORS) != 0
    for i in range(4):
        out = m[i] + throttle
        if linear != 0.0:
            out *= 1.0 + linear * (1.0 - out) ** 2
        motor = min(max(out_low + span * out, out_low), out_high)
        z[Z_MOTOR + i] = motor
        above = motor - k[K_MIN_COMMAND]
        # int16 in sitl.c: truncated toward zero (smooth: its mean effect, half a microsecond)
        above = float(int(above)) if quantize else above - 0.5
        z[Z_PACKET + PACKET_SLOT[i]] = above / 1000.0
