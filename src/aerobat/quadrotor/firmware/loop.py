"""One gyro sample of the firmware, in its scheduler's order, and the firmware at rest in hover.

Per state packet (one gyro period) the SITL in lockstep runs, at the same simulated instant:
the gyro task (:func:`.pid.sample`), then, when the PID loop counter says so, the filter task
(:func:`.pid.filter_gyro`) and the PID task (:func:`.rc_path.process`, :func:`.pid.pid`,
:func:`.mixer.mix`), and after them the receiver task with a radio frame that arrived with the
packet (:func:`.rc_path.receive`): a frame's set point reaches the PID one loop later. The motor
packet it answers with is ``Z_PACKET``.

:func:`hover` puts the memory where a firmware that has hovered for a while has it: set points
and gyro zero, the throttle steady at the hover throttle (its smoothing, throttle boost,
anti-gravity, TPA and the dynamic lowpasses' cutoffs settled on it), I-terms zero, D-max's
multiplier at 1, the motors at the hover command.
"""

from __future__ import annotations

import math

import numba as nb

from aerobat.quadrotor.firmware import filters
from aerobat.quadrotor.firmware.layout import (
    K_AG_HZ,
    K_BOOST_HZ,
    K_DENOM,
    K_DTERM_LPF1,
    K_DTERM_LPF2,
    K_DTERM_NOTCH,
    K_GYRO_DT,
    K_GYRO_LPF1,
    K_GYRO_LPF2,
    K_GYRO_NOTCH,
    K_MIN_COMMAND,
    K_MOTOR_HIGH,
    K_MOTOR_LOW,
    K_PID_DT,
    K_QUANTIZE,
    K_RELAX,
    K_RELAX_HZ,
    K_RX_INTERVAL,
    K_SMOOTH_FACTOR,
    K_SMOOTH_HZ,
    K_THROTTLE_COMPENSATE,
    K_THRUST_LINEAR,
    K_YAW_LOWPASS_HZ,
    N_MEMORY,
    Q_MOTORS,
    Z_AG,
    Z_AG_PREV,
    Z_AIRMODE_ACTIVE,
    Z_BOOST,
    Z_COUNTER,
    Z_DMAX_LOW,
    Z_DMAX_RANGE,
    Z_DTERM_LPF1,
    Z_DTERM_LPF2,
    Z_DTERM_NOTCH,
    Z_DYN_LAST_US,
    Z_DYN_PREV,
    Z_FF_SMOOTH,
    Z_GYRO_LPF1,
    Z_GYRO_LPF2,
    Z_GYRO_NOTCH1,
    Z_GYRO_NOTCH2,
    Z_MOTOR,
    Z_PACKET,
    Z_PREV_DUPLICATE,
    Z_PREV_RX_INTERVAL,
    Z_RC_COMMAND,
    Z_RX_INTERVAL,
    Z_SMOOTH,
    Z_STEP,
    Z_TIME_US,
    Z_TO_SMOOTH,
    Z_TPA,
    Z_TPA_FADED,
    Z_WINDUP,
    Z_YAW_P,
)
from aerobat.quadrotor.firmware.mixer import PACKET_SLOT, mix, tpa_factor
from aerobat.quadrotor.firmware.pid import dynamic_cutoff, filter_gyro, notch_active, pid, sample
from aerobat.quadrotor.firmware.rc_path import process, receive

__all__ = ["hover", "hover_throttle", "smoothing_cutoff", "step"]

_S = filters.SIZE
_D_MAX_RANGE_HZ = 85.0
_D_MAX_LOWPASS_HZ = 35.0


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def step(k, z, gyro_dps, frame, pulses):  # pragma: no cover - compiled
    """One gyro sample ``gyro_dps`` (firmware axes, deg/s); ``frame``: a radio frame (``pulses``, AETR µs) arrived."""
    denom = int(k[K_DENOM])
    counter = int(z[Z_COUNTER])
    if counter % denom == 0:
        counter = 0
    counter += 1
    z[Z_COUNTER] = counter
    sample(k, z, gyro_dps)
    if counter % denom == 0:
        filter_gyro(k, z)
    if counter % denom == denom // 2:
        z[Z_TIME_US] = math.floor(z[Z_STEP] * k[K_GYRO_DT] * 1e6 + 0.5)
        process(k, z)
        pid(k, z)
        mix(k, z, z[Z_TIME_US])
    if frame:
        receive(k, z, pulses)
    z[Z_STEP] += 1.0


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def smoothing_cutoff(k, index):  # pragma: no cover - compiled
    """An RC smoothing cutoff [Hz]: the setting, or auto from the radio's rate (``rcSmoothingSetFilterCutoffs``)."""
    setting = k[K_SMOOTH_HZ + index]
    if setting != 0.0:
        return setting
    factor = k[K_SMOOTH_FACTOR + (1 if index == 1 else 0)]
    return max(15.0, float(int((1.0 / k[K_RX_INTERVAL]) * factor)))


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def hover_throttle(k, motor):  # pragma: no cover - compiled
    """The throttle fraction (after the throttle curve) that holds every motor at ``motor`` (packet units) with no mix.

    The mixer's chain inverted: packet → output units → thrust linearisation → its compensation.
    """
    truncation = 0.0 if (int(k[K_QUANTIZE]) & Q_MOTORS) != 0 else 0.5  # the smooth model's mean truncation
    out = (motor * 1000.0 + truncation + k[K_MIN_COMMAND] - k[K_MOTOR_LOW]) / (k[K_MOTOR_HIGH] - k[K_MOTOR_LOW])
    linear = k[K_THRUST_LINEAR]
    if linear == 0.0:
        return min(max(out, 0.0), 1.0)
    low = 0.0
    high = 1.0
    for _ in range(60):  # out = t (1 + L (1 − t)²) rises with t
        t = 0.5 * (low + high)
        if t * (1.0 + linear * (1.0 - t) ** 2) < out:
            low = t
        else:
            high = t
    compensated = 0.5 * (low + high)
    low = 0.0
    high = 1.0
    for _ in range(60):  # compensated = thr / (1 + c (1 − thr)²) rises with thr
        thr = 0.5 * (low + high)
        if thr / (1.0 + k[K_THROTTLE_COMPENSATE] * (1.0 - thr) ** 2) < compensated:
            low = thr
        else:
            high = thr
    return 0.5 * (low + high)


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def hover(k, z, motor):  # pragma: no cover - compiled
    """The firmware's memory after a long hover with every motor at ``motor`` (packet units), sticks centred."""
    for i in range(N_MEMORY):
        z[i] = 0.0
    pid_dt = k[K_PID_DT]
    gyro_dt = k[K_GYRO_DT]
    throttle = hover_throttle(k, motor)
    command = 1000.0 + 1000.0 * throttle
    z[Z_RC_COMMAND + 3] = command
    z[Z_TO_SMOOTH + 3] = command
    z[Z_RX_INTERVAL] = k[K_RX_INTERVAL]
    z[Z_RX_INTERVAL + 1] = k[K_RX_INTERVAL]
    z[Z_PREV_RX_INTERVAL] = k[K_RX_INTERVAL]
    for axis in range(3):
        z[Z_PREV_DUPLICATE + axis] = 1.0
    for i in range(4):
        filters.set_lowpass(filters.PT3, z, Z_SMOOTH + i * _S, smoothing_cutoff(k, 1 if i == 3 else 0), pid_dt)
        filters.reset(z, Z_SMOOTH + i * _S, command if i == 3 else 0.0, filters.PT3)
    for axis in range(3):
        filters.set_lowpass(filters.PT3, z, Z_FF_SMOOTH + axis * _S, smoothing_cutoff(k, 2), pid_dt)
    z[Z_AIRMODE_ACTIVE] = 1.0  # the take-off raised the throttle
    quantized = float(round(throttle * 100.0))
    z[Z_DYN_PREV] = quantized
    z[Z_DYN_LAST_US] = -1e12
    kind2 = int(k[K_GYRO_LPF2])
    rate = 1.0 / pid_dt
    for axis in range(3):
        if kind2 != filters.NONE:
            filters.set_lowpass(kind2, z, Z_GYRO_LPF2 + axis * _S, k[K_GYRO_LPF2 + 1], gyro_dt)
        for n, zo in ((0, Z_GYRO_NOTCH1), (2, Z_GYRO_NOTCH2)):
            center = notch_active(k, K_GYRO_NOTCH + n, rate)
            if center != 0.0:
                filters.set_notch(z, zo + axis * _S, center, k[K_GYRO_NOTCH + n + 1], pid_dt)
        center = notch_active(k, K_DTERM_NOTCH, rate)
        if center != 0.0:
            filters.set_notch(z, Z_DTERM_NOTCH + axis * _S, center, k[K_DTERM_NOTCH + 1], pid_dt)
        for o, zo in ((K_GYRO_LPF1, Z_GYRO_LPF1), (K_DTERM_LPF1, Z_DTERM_LPF1)):
            cutoff = dynamic_cutoff(k, o, quantized / 100.0) if k[o + 1] != 0.0 else k[o + 5]
            filters.set_lowpass(int(k[o]), z, zo + axis * _S, cutoff, pid_dt)
        if int(k[K_DTERM_LPF2]) != filters.NONE:
            filters.set_lowpass(int(k[K_DTERM_LPF2]), z, Z_DTERM_LPF2 + axis * _S, k[K_DTERM_LPF2 + 1], pid_dt)
        if k[K_RELAX] != 0.0:
            filters.set_lowpass(filters.PT1, z, Z_WINDUP + axis * _S, k[K_RELAX_HZ], pid_dt)
        filters.set_lowpass(filters.PT2, z, Z_DMAX_RANGE + axis * _S, _D_MAX_RANGE_HZ, pid_dt)
        filters.set_lowpass(filters.PT2, z, Z_DMAX_LOW + axis * _S, _D_MAX_LOWPASS_HZ, pid_dt)
        filters.reset(z, Z_DMAX_LOW + axis * _S, 1.0, filters.PT2)
    if k[K_YAW_LOWPASS_HZ] > 0.0:
        filters.set_lowpass(filters.PT1, z, Z_YAW_P, k[K_YAW_LOWPASS_HZ], pid_dt)
    filters.set_lowpass(filters.PT2, z, Z_AG, k[K_AG_HZ], pid_dt)
    z[Z_AG_PREV] = throttle
    filters.set_lowpass(filters.PT1, z, Z_BOOST, k[K_BOOST_HZ], pid_dt)
    filters.reset(z, Z_BOOST, throttle, filters.PT1)
    z[Z_TPA_FADED] = 1.0
    z[Z_TPA] = tpa_factor(k, z, throttle)
    for i in range(4):
        z[Z_MOTOR + i] = k[K_MIN_COMMAND] + 1000.0 * motor
        z[Z_PACKET + PACKET_SLOT[i]] = motor
    # the PID loop's phase: the SITL's first gyro sample is at step 1 and frames reach the receiver at
    # multiples of the frame's steps, so with a denominator d the counter stands at ((−2) mod d) + 1 when
    # a frame arrives (measured with d = 2: the PID runs one sample after the frame)
    denom = int(k[K_DENOM])
    z[Z_COUNTER] = float((denom - 2) % denom + 1) if denom > 1 else 0.0
