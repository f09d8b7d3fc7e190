"""Stick to set point: a radio frame's channels, the rate curves, feedforward and RC smoothing.

Betaflight 4.6's ``fc/rc.c`` as compiled kernels over the model's vectors (:mod:`.layout`):
:func:`receive` is what the receiver task does with a new frame (``updateRcCommands`` and the
air-mode and I-term-reset decisions of ``processRx``); :func:`process` is what every PID loop
does first (``processRcCommand``): on a new frame the rate curve and the feedforward
(``calculateFeedforward``, with its duplicate-frame interpolation, jitter reduction, boost and
the limit near full rate), then the PT3 smoothing of set points, throttle and feedforward.
"""

from __future__ import annotations

import math

import numba as nb

from aerobat.quadrotor.firmware import filters
from aerobat.quadrotor.firmware.layout import (
    K_AIRMODE_START,
    K_DEADBAND,
    K_EXPO,
    K_FF_BOOST,
    K_FF_INTERPOLATE,
    K_FF_JITTER_INV,
    K_FF_MAX_RATE_LIMIT,
    K_FF_SMOOTH,
    K_FF_TRANSITION,
    K_FF_TRANSITION_INV,
    K_FF_YAW_HOLD_GAIN,
    K_FF_YAW_HOLD_TIME,
    K_MAX_RC_RATE,
    K_MIDRC,
    K_MINCHECK,
    K_QUANTIZE,
    K_QUICK_EXPO,
    K_RATE_LIMIT,
    K_RATES_TYPE,
    K_RC_RATE,
    K_RX_INTERVAL,
    K_SMOOTHING,
    K_SRATE,
    K_THROTTLE_TABLE,
    K_YAW_DIRECTION,
    Q_THROTTLE,
    Z_AIRMODE_ACTIVE,
    Z_DEFLECTION,
    Z_FF,
    Z_FF_RAW,
    Z_FF_SMOOTH,
    Z_ITERM_RESET,
    Z_PREV_COMMAND,
    Z_PREV_DELTA_ABS,
    Z_PREV_DUPLICATE,
    Z_PREV_RX_INTERVAL,
    Z_PREV_SETPOINT,
    Z_PREV_SPEED,
    Z_PREV_SPEED_DELTA,
    Z_RAW_SETPOINT,
    Z_RC_COMMAND,
    Z_RX_INTERVAL,
    Z_RX_NEW,
    Z_SETPOINT,
    Z_SMOOTH,
    Z_TO_SMOOTH,
    Z_YAW_HOLD,
)

__all__ = ["apply_rates", "process", "receive", "throttle_command"]


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def apply_rates(k, axis, x):  # pragma: no cover - compiled
    """The rate curve [deg/s] at deflection ``x`` ∈ [−1, 1] (``applyRates``), before ``rate_limit``."""
    kind = k[K_RATES_TYPE]
    rc_rate = k[K_RC_RATE + axis]
    srate = k[K_SRATE + axis]
    e = k[K_EXPO + axis] / 100.0
    a = abs(x)
    if kind == 0.0:  # BETAFLIGHT
        xc = x * a * a * a * e + x * (1.0 - e) if e != 0.0 else x
        rcr = rc_rate / 100.0
        if rcr > 2.0:
            rcr += 14.54 * (rcr - 2.0)
        rate = 200.0 * rcr * xc
        if srate != 0.0:
            rate /= min(max(1.0 - a * srate / 100.0, 0.01), 1.0)
        return rate
    if kind == 1.0:  # RACEFLIGHT
        xc = (1.0 + 0.01 * k[K_EXPO + axis] * (x * x - 1.0)) * x
        return 10.0 * rc_rate * xc * (1.0 + a * srate * 0.01)
    if kind == 2.0:  # KISS
        use = 1.0 / min(max(1.0 - a * srate / 100.0, 0.01), 1.0)
        return min(max(2000.0 * use * (x * x * x * e + x * (1.0 - e)) * (rc_rate / 1000.0), -1998.0), 1998.0)
    if kind == 3.0:  # ACTUAL
        curve = a * (x ** 5 * e + x * (1.0 - e))
        return x * rc_rate * 10.0 + max(0.0, srate * 10.0 - rc_rate * 10.0) * curve
    rcr = float(int(rc_rate) * 2)  # QUICK
    top = max(srate * 10.0, rcr)
    factor = (top / rcr - 1.0) / (top / rcr)
    if k[K_QUICK_EXPO] != 0.0:
        curve = x * x * x * e + x * (1.0 - e)
        rate = curve * rcr / min(max(1.0 - a * factor, 0.01), 1.0)
    else:
        curve = a * a * a * e + a * (1.0 - e)
        rate = x * rcr / min(max(1.0 - curve * factor, 0.01), 1.0)
    return min(max(rate, -1998.0), 1998.0)


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def throttle_command(k, pulse):  # pragma: no cover - compiled
    """``rcCommand[THROTTLE]`` [µs] for a throttle pulse: min_check to 2000 onto the throttle curve's table.

    Quantized: the firmware's integer steps (``(int)`` of the pulse, integer division, integer
    interpolation); else the same map without them.
    """
    mincheck = k[K_MINCHECK]
    if (int(k[K_QUANTIZE]) & Q_THROTTLE) != 0:
        tmp = float(min(max(int(pulse), int(mincheck)), 2000))
        tmp = float((int(tmp) - int(mincheck)) * 1000 // (2000 - int(mincheck)))
        scaled = int(tmp) * 11
        idx = scaled // 1000
        rem = scaled % 1000
        if idx >= 11:
            return k[K_THROTTLE_TABLE + 11]
        lo = int(k[K_THROTTLE_TABLE + idx])
        hi = int(k[K_THROTTLE_TABLE + idx + 1])
        a = (hi - lo) * rem
        q = abs(a) // 1000
        return float((q if a >= 0 else -q) + lo)  # C's division truncates toward zero
    # smooth: the same map with the integer steps' mean effect (each truncation loses half a unit on
    # average: the division by (2000 − min_check), then the table's interpolation where it moves)
    tmp = max((min(max(pulse, mincheck), 2000.0) - mincheck) * 1000.0 / (2000.0 - mincheck) - 0.5, 0.0)
    scaled = tmp * 11.0 / 1000.0
    idx = min(int(scaled), 10)
    f = scaled - idx
    lo = k[K_THROTTLE_TABLE + idx]
    hi = k[K_THROTTLE_TABLE + idx + 1]
    return lo + f * (hi - lo) - (0.5 if hi != lo else 0.0)


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def receive(k, z, pulses):  # pragma: no cover - compiled
    """A new radio frame reaches the receiver: ``pulses`` = roll, pitch, throttle, yaw [µs] (AETR)."""
    for axis in range(3):
        pulse = pulses[3] if axis == 2 else pulses[axis]
        rc = min(max(pulse - k[K_MIDRC], -500.0), 500.0)
        if axis == 2:
            rc *= k[K_YAW_DIRECTION]
        band = k[K_DEADBAND + axis]
        if abs(rc) < band:
            rc = 0.0
        elif rc >= 0.0:
            rc -= band
        else:
            rc += band
        z[Z_RC_COMMAND + axis] = rc
    z[Z_RC_COMMAND + 3] = throttle_command(k, pulses[2])
    z[Z_RX_NEW] = 1.0
    z[Z_RX_INTERVAL + 1] = z[Z_RX_INTERVAL]
    z[Z_RX_INTERVAL] = k[K_RX_INTERVAL]
    # processRx: air mode latches on once the throttle was raised; the I-term is reset at low throttle without it
    percent = (min(max(pulses[2], k[K_MINCHECK]), 2000.0) - k[K_MINCHECK]) / (2000.0 - k[K_MINCHECK])
    if percent >= k[K_AIRMODE_START]:
        z[Z_AIRMODE_ACTIVE] = 1.0
    low = pulses[2] < k[K_MINCHECK]
    z[Z_ITERM_RESET] = 1.0 if (low and z[Z_AIRMODE_ACTIVE] == 0.0) else 0.0


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def _feedforward(k, z, axis):  # pragma: no cover - compiled
    """``calculateFeedforward`` for one axis on a new frame (rcCommand and raw set point already updated)."""
    interval = z[Z_RX_INTERVAL]
    rate = 1.0 / interval
    delta = z[Z_RC_COMMAND + axis] - z[Z_PREV_COMMAND + axis]
    z[Z_PREV_COMMAND + axis] = z[Z_RC_COMMAND + axis]
    delta_abs = abs(delta)
    setpoint = z[Z_RAW_SETPOINT + axis]
    setpoint_delta = setpoint - z[Z_PREV_SETPOINT + axis]
    z[Z_PREV_SETPOINT + axis] = setpoint
    speed = 0.0
    if k[K_FF_INTERPOLATE] != 0.0:
        if delta_abs != 0.0:  # movement
            if z[Z_PREV_DUPLICATE + axis] != 0.0:
                rate = 1.0 / (interval + z[Z_PREV_RX_INTERVAL])
            speed = setpoint_delta * rate
            z[Z_PREV_DUPLICATE + axis] = 0.0
        else:
            if z[Z_PREV_DUPLICATE + axis] == 0.0:
                if abs(setpoint) < 0.90 * k[K_MAX_RC_RATE + axis]:
                    speed = z[Z_PREV_SPEED + axis] + z[Z_PREV_SPEED_DELTA + axis]
                    delta_abs = z[Z_PREV_DELTA_ABS + axis]
            else:
                z[Z_PREV_SPEED + axis] = 0.0
            z[Z_PREV_DUPLICATE + axis] = 1.0
        z[Z_PREV_RX_INTERVAL] = interval
    else:
        speed = setpoint_delta * rate
    jitter = ((delta_abs + z[Z_PREV_DELTA_ABS + axis]) * 0.5 + 1.0) * k[K_FF_JITTER_INV]
    jitter = min(jitter, 1.0)
    z[Z_PREV_DELTA_ABS + axis] = delta_abs
    smooth = k[K_FF_SMOOTH]
    speed = z[Z_PREV_SPEED + axis] + smooth * (speed - z[Z_PREV_SPEED + axis])
    speed_delta = speed - z[Z_PREV_SPEED + axis]
    z[Z_PREV_SPEED + axis] = speed
    speed_delta = z[Z_PREV_SPEED_DELTA + axis] + smooth * (speed_delta - z[Z_PREV_SPEED_DELTA + axis])
    z[Z_PREV_SPEED_DELTA + axis] = speed_delta
    boost = speed_delta * rate * k[K_FF_BOOST]
    ff = speed
    if axis < 2:
        ff += boost
        ff *= jitter
        limit_gain = k[K_FF_MAX_RATE_LIMIT]
        if limit_gain != 0.0 and ff * setpoint > 0.0:
            limit = (k[K_MAX_RC_RATE + axis] - abs(setpoint)) * limit_gain
            ff = min(max(ff, -limit), limit) if limit > 0.0 else 0.0
    else:
        ff *= jitter
        hold = k[K_FF_YAW_HOLD_TIME]
        gain = 1.0
        if hold > 0.0:
            omega = 2.0 * math.pi * (1.0 / (2.0 * math.pi * hold)) * interval
            gain = omega / (omega + 1.0)
        z[Z_YAW_HOLD] += gain * (setpoint - z[Z_YAW_HOLD])
        ff += k[K_FF_YAW_HOLD_GAIN] * (setpoint - z[Z_YAW_HOLD])
    transition = k[K_FF_TRANSITION]
    deflection = abs(z[Z_DEFLECTION + axis])
    if transition != 0.0 and deflection < transition:
        ff *= deflection * k[K_FF_TRANSITION_INV]
    z[Z_FF_RAW + axis] = ff


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def process(k, z):  # pragma: no cover - compiled
    """``processRcCommand``: set points and feedforward on a new frame, then RC smoothing (every PID loop)."""
    if z[Z_RX_NEW] != 0.0:
        for axis in range(3):
            deflection = z[Z_RC_COMMAND + axis] / (500.0 - k[K_DEADBAND + axis])
            z[Z_DEFLECTION + axis] = deflection
            rate = apply_rates(k, axis, deflection)
            limit = k[K_RATE_LIMIT + axis]
            z[Z_RAW_SETPOINT + axis] = min(max(rate, -limit), limit)
            _feedforward(k, z, axis)
        for i in range(4):
            z[Z_TO_SMOOTH + i] = z[Z_RC_COMMAND + 3] if i == 3 else z[Z_RAW_SETPOINT + i]
    smoothing = k[K_SMOOTHING] != 0.0
    for i in range(4):
        value = z[Z_TO_SMOOTH + i]
        if smoothing:
            value = filters.apply(filters.PT3, z, Z_SMOOTH + i * filters.SIZE, value)
        if i == 3:
            z[Z_RC_COMMAND + 3] = value
        else:
            z[Z_SETPOINT + i] = value
    for axis in range(3):
        # the firmware's feedforward always passes its smoothing filter, which RC smoothing OFF leaves
        # uninitialised (gain 0): no feedforward then
        ff = filters.apply(filters.PT3, z, Z_FF_SMOOTH + axis * filters.SIZE, z[Z_FF_RAW + axis]) if smoothing else 0.0
        z[Z_FF + axis] = ff
    z[Z_RX_NEW] = 0.0
