"""The gyro's filters and the PID rate loop, as Betaflight 4.6 runs them (``sensors/gyro*.c``, ``flight/pid.c``).

:func:`sample` is the gyro task (every gyro sample: lowpass 2, or the plain average it replaces),
:func:`filter_gyro` the filter task (static notches, then lowpass 1, whose cutoff moves with the
throttle), :func:`pid` the PID controller in ACRO: the error against the smoothed set point, P
(yaw's through its lowpass), I with I-term relax and anti-gravity's accelerator, D on the
filtered gyro with D-max boosting it and TPA scaling it, feedforward, anti-gravity's P boost.
:func:`update_cutoffs` moves the dynamic lowpasses (``updateDynLpfCutoffs``, from the mixer).
"""

from __future__ import annotations

import numba as nb

from aerobat.quadrotor.firmware import filters
from aerobat.quadrotor.firmware.layout import (
    K_AG_ENABLED,
    K_AG_GAIN,
    K_AG_P_GAIN,
    K_DMAX_GYRO_GAIN,
    K_DMAX_PERCENT,
    K_DMAX_SETPOINT_GAIN,
    K_DTERM_LPF1,
    K_DTERM_LPF2,
    K_DTERM_NOTCH,
    K_GYRO_LPF1,
    K_GYRO_LPF2,
    K_GYRO_NOTCH,
    K_ITERM_LIMIT,
    K_ITERM_LIMIT_YAW,
    K_KD,
    K_KF,
    K_KI,
    K_KP,
    K_MAX_VELOCITY,
    K_PID_DT,
    K_RELAX,
    K_RELAX_TYPE,
    K_TPA_D_ONLY,
    K_YAW_LOWPASS_HZ,
    Z_ACCEL_PREV,
    Z_AG_D,
    Z_DMAX_LOW,
    Z_DMAX_RANGE,
    Z_DTERM_LPF1,
    Z_DTERM_LPF2,
    Z_DTERM_NOTCH,
    Z_DYN_LAST_US,
    Z_DYN_PREV,
    Z_FF,
    Z_GYRO,
    Z_GYRO_COUNT,
    Z_GYRO_LPF1,
    Z_GYRO_LPF2,
    Z_GYRO_NOTCH1,
    Z_GYRO_NOTCH2,
    Z_GYRO_SAMPLE,
    Z_ITERM_RESET,
    Z_PID,
    Z_PID_SETPOINT,
    Z_PID_SUM,
    Z_PREV_DTERM,
    Z_SETPOINT,
    Z_TPA,
    Z_WINDUP,
    Z_YAW_P,
)

__all__ = ["dynamic_cutoff", "filter_gyro", "notch_active", "pid", "sample", "update_cutoffs"]

_S = filters.SIZE
_ANTIGRAVITY_KI = 0.34
_RELAX_THRESHOLD = 40.0  # ITERM_RELAX_SETPOINT_THRESHOLD [deg/s]


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def sample(k, z, gyro_dps):  # pragma: no cover - compiled
    """The gyro task: one sample [deg/s] (firmware axes) into lowpass 2, or into the average it replaces."""
    kind = int(k[K_GYRO_LPF2])
    for axis in range(3):
        if kind != filters.NONE:
            z[Z_GYRO_SAMPLE + axis] = filters.apply(kind, z, Z_GYRO_LPF2 + axis * _S, gyro_dps[axis])
        else:
            z[Z_GYRO_SAMPLE + axis] += gyro_dps[axis]
    if kind == filters.NONE:
        z[Z_GYRO_COUNT] += 1.0


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def notch_active(k, o, rate_hz):  # pragma: no cover - compiled
    """The notch centre actually used (0: none): above Nyquist it moves there or goes (``gyroInitFilterNotch``)."""
    center = k[o]
    cutoff = k[o + 1]
    if center == 0.0 or cutoff == 0.0:
        return 0.0
    nyquist = float(int(rate_hz / 2.0))
    if center > nyquist:
        return nyquist if cutoff < nyquist else 0.0
    return center


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def filter_gyro(k, z):  # pragma: no cover - compiled
    """The filter task: static notches and lowpass 1 on the (downsampled) gyro → ``Z_GYRO``."""
    rate = 1.0 / k[K_PID_DT]
    n1 = notch_active(k, K_GYRO_NOTCH, rate)
    n2 = notch_active(k, K_GYRO_NOTCH + 2, rate)
    kind1 = int(k[K_GYRO_LPF1])
    averaged = int(k[K_GYRO_LPF2]) == filters.NONE
    for axis in range(3):
        if averaged:
            count = z[Z_GYRO_COUNT]
            v = z[Z_GYRO_SAMPLE + axis] / count if count > 0.0 else 0.0
            z[Z_GYRO_SAMPLE + axis] = 0.0
        else:
            v = z[Z_GYRO_SAMPLE + axis]
        if n1 != 0.0:
            v = filters.apply(filters.NOTCH, z, Z_GYRO_NOTCH1 + axis * _S, v)
        if n2 != 0.0:
            v = filters.apply(filters.NOTCH, z, Z_GYRO_NOTCH2 + axis * _S, v)
        z[Z_GYRO + axis] = filters.apply(kind1, z, Z_GYRO_LPF1 + axis * _S, v)
    z[Z_GYRO_COUNT] = 0.0


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def dynamic_cutoff(k, o, throttle):  # pragma: no cover - compiled
    """A dynamic lowpass's cutoff [Hz] at ``throttle`` (``dynLpfCutoffFreq``, or ``dynThrottle`` without expo)."""
    low = k[o + 2]
    high = k[o + 3]
    expo = k[o + 4]
    if expo > 0.0:
        e = expo / 10.0
        curve = throttle * (1.0 - throttle) * e + throttle
        return (high - low) * curve + low
    return max(throttle * (1.0 - throttle * throttle / 3.0) * 1.5 * high, low)


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def update_cutoffs(k, z, time_us, throttle):  # pragma: no cover - compiled
    """``updateDynLpfCutoffs``: at most every 5 ms, and only when the throttle moved by a percent."""
    if time_us - z[Z_DYN_LAST_US] < 5000.0:
        return
    quantized = float(round(throttle * 100.0))
    if quantized == z[Z_DYN_PREV]:
        return
    t = quantized / 100.0
    for o, zo, dt in ((K_GYRO_LPF1, Z_GYRO_LPF1, k[K_PID_DT]), (K_DTERM_LPF1, Z_DTERM_LPF1, k[K_PID_DT])):
        if k[o + 1] != 0.0:
            cutoff = dynamic_cutoff(k, o, t)
            for axis in range(3):
                filters.set_lowpass(int(k[o]), z, zo + axis * _S, cutoff, dt)
    z[Z_DYN_PREV] = quantized
    z[Z_DYN_LAST_US] = time_us


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def pid(k, z):  # pragma: no cover - compiled
    """``pidController`` in ACRO: P, I, D, F and their sum per axis from ``Z_SETPOINT``, ``Z_GYRO``, ``Z_FF``."""
    dt = k[K_PID_DT]
    frequency = 1.0 / dt
    accelerator = 0.0
    if k[K_AG_ENABLED] != 0.0:
        z[Z_AG_D] *= k[K_AG_GAIN]
        accelerator = z[Z_AG_D] * _ANTIGRAVITY_KI
    else:
        z[Z_AG_D] = 0.0
    rate = 1.0 / k[K_PID_DT]
    notch = notch_active(k, K_DTERM_NOTCH, rate)
    kind1 = int(k[K_DTERM_LPF1])
    kind2 = int(k[K_DTERM_LPF2])
    tpa = z[Z_TPA]
    relax = int(k[K_RELAX])
    for axis in range(3):
        gyro = z[Z_GYRO + axis]
        dterm = gyro
        if notch != 0.0:
            dterm = filters.apply(filters.NOTCH, z, Z_DTERM_NOTCH + axis * _S, dterm)
        dterm = filters.apply(kind1, z, Z_DTERM_LPF1 + axis * _S, dterm)
        dterm = filters.apply(kind2, z, Z_DTERM_LPF2 + axis * _S, dterm)
        setpoint = z[Z_SETPOINT + axis]
        limit_v = k[K_MAX_VELOCITY + axis]
        if limit_v != 0.0:
            velocity = setpoint - z[Z_ACCEL_PREV + axis]
            if abs(velocity) > limit_v:
                setpoint = z[Z_ACCEL_PREV + axis] + (limit_v if velocity > 0.0 else -limit_v)
            z[Z_ACCEL_PREV + axis] = setpoint
        error = setpoint - gyro
        previous_i = z[Z_PID + 3 + axis]
        iterm_error = error
        # I-term relax: the set point's high-pass lowers (or ends) the I-term's growth while sticks move
        setpoint_lpf = filters.apply(filters.PT1, z, Z_WINDUP + axis * _S, setpoint)
        setpoint_hpf = abs(setpoint - setpoint_lpf)
        if relax != 0 and (axis < 2 or relax == 2 or relax == 4):
            factor = max(0.0, 1.0 - setpoint_hpf / _RELAX_THRESHOLD)
            decreasing = (previous_i > 0.0 and iterm_error < 0.0) or (previous_i < 0.0 and iterm_error > 0.0)
            if relax >= 3 and decreasing:
                pass
            elif k[K_RELAX_TYPE] != 0.0:
                iterm_error *= factor
            else:
                band = setpoint_hpf
                e = setpoint_lpf - gyro
                iterm_error = 0.0 if abs(e) < band else (e - band if e >= 0.0 else e + band)
        error = setpoint - gyro
        p = k[K_KP + axis] * error * (1.0 if k[K_TPA_D_ONLY] != 0.0 else tpa)
        if axis == 2 and k[K_YAW_LOWPASS_HZ] > 0.0:
            p = filters.apply(filters.PT1, z, Z_YAW_P, p)
        ki = k[K_KI + axis]
        i_limit = k[K_ITERM_LIMIT]
        if axis == 2:
            i_limit = k[K_ITERM_LIMIT_YAW]
            accelerator = 0.0  # no anti-gravity on the yaw I-term
        i_term = min(max(previous_i + (ki + accelerator) * dt * iterm_error, -i_limit), i_limit)
        feedforward = z[Z_FF + axis]
        z[Z_PID_SETPOINT + axis] = setpoint
        d_term = 0.0
        kd = k[K_KD + axis]
        if kd > 0.0:
            delta = -(dterm - z[Z_PREV_DTERM + axis]) * frequency
            pre_tpa = kd * delta
            percent = k[K_DMAX_PERCENT + axis]
            if percent > 1.0:
                gyro_factor = filters.apply(filters.PT2, z, Z_DMAX_RANGE + axis * _S, delta)
                gyro_factor = abs(gyro_factor) * k[K_DMAX_GYRO_GAIN]
                setpoint_factor = abs(feedforward) * k[K_DMAX_SETPOINT_GAIN]
                multiplier = 1.0 + (percent - 1.0) * max(gyro_factor, setpoint_factor)
                multiplier = filters.apply(filters.PT2, z, Z_DMAX_LOW + axis * _S, multiplier)
                pre_tpa *= min(multiplier, percent)
            d_term = pre_tpa * tpa
        z[Z_PREV_DTERM + axis] = dterm
        f_term = k[K_KF + axis] * feedforward
        if axis != 2:
            attenuator = max(abs(setpoint) / 50.0, 1.0)
            p *= 1.0 + (z[Z_AG_D] / attenuator) * k[K_AG_P_GAIN]
        z[Z_PID + axis] = p
        z[Z_PID + 3 + axis] = i_term
        z[Z_PID + 6 + axis] = d_term
        z[Z_PID + 9 + axis] = f_term
        z[Z_PID_SUM + axis] = p + i_term + d_term + f_term
    if z[Z_ITERM_RESET] != 0.0:
        for axis in range(3):
            z[Z_PID + 3 + axis] = 0.0

