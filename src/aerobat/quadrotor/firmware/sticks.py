"""A program as a flight controller's sticks: radio frames, rate curves inverted, collective as throttle.

A ground station that streams a program to a flight controller sends one radio frame per
period. :func:`frame_commands` gives each frame the program's *mean* command over the frame's
period (its integral over the frame, divided by the period): a switch inside a frame moves that
frame's value continuously with the switch time, so the commanded rotation (the integral of the
rate command) survives the radio exactly, and the flight depends smoothly on the switch times.
A frame entirely inside one constant stretch of the program carries that constant exactly (no
rounding), so the firmware sees repeated frames as exact duplicates, as it does from a pilot.

:func:`program_sticks` turns a command (collective [m/s²], p̂, q̂, r̂ [rad/s], body FLU) into
ACRO sticks through the firmware's rate curves (tables, inverted) and the throttle through the
pilot's model of the vehicle (its mass and the published thrust curve) and the firmware's
throttle curve. The curves and the model are one flat vector (indices ``L_*``) that the plant
builds from the firmware's settings (:class:`aerobat.plants.fpv.pilot.StickMap`).

Frames: sticks are in Betaflight's sense (roll right, pitch forward = nose down, yaw right =
nose right); rates in aerobat's body FLU: roll stick from p, pitch stick from q, yaw stick from −r.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from aerobat.quadrotor.xframe import sagging_command

__all__ = [
    "L_ANGLE_LIMIT",
    "L_CLIMB",
    "L_BATTERY",
    "L_CURVE_K",
    "L_CURVE_R",
    "L_DEADBAND",
    "L_FMAX",
    "L_GRAVITY",
    "L_IDLE",
    "L_MASS",
    "L_MIN_CHECK",
    "L_MOTOR_TABLE",
    "L_RATE_MAX",
    "L_RATE_TABLES",
    "L_ROLL_TABLE",
    "L_THROTTLE_TABLE",
    "L_TILT",
    "N_LIMITS",
    "N_TABLE",
    "frame_commands",
    "program_sticks",
    "stick_for_rate",
    "throttle_for_collective",
    "throttle_for_motor",
]

# the limits vector of the compiled pilot
L_TILT = 0  # largest tilt asked for [rad]
L_CLIMB = 1  # vertical speed limit [m/s]
L_GRAVITY = 2
L_ANGLE_LIMIT = 3  # Betaflight's angle_limit [rad]: full stick in ANGLE mode
L_RATE_MAX = 4  # rate at full stick in ACRO [rad/s] (before the rate_limit clamp)
L_MASS = 5  # the pilot's vehicle mass [kg]
L_FMAX = 6  # thrust curve: f_max [N], min-speed ratio r, shape k
L_CURVE_R = 7
L_CURVE_K = 8
L_IDLE = 9  # motor_idle as a motor command
L_MIN_CHECK = 10  # throttle pulse where the throttle starts [us]
L_RATE_TABLES = 11  # 1: the rate curves are the tables below (a tune's), 0: linear with L_RATE_MAX
L_THROTTLE_TABLE = 12  # 1: the throttle curve is the table below, 0: linear with L_IDLE and L_MIN_CHECK
N_TABLE = 129  # samples per table: stick |x| = i/(N-1), or throttle pulse 1000 + 1000 i/(N-1) us
L_ROLL_TABLE = 13  # rate [rad/s] at stick i/(N-1), roll, pitch, yaw one after the other
L_MOTOR_TABLE = L_ROLL_TABLE + 3 * N_TABLE  # motor command at pulse 1000 + 1000 i/(N-1) us
L_DEADBAND = L_MOTOR_TABLE + N_TABLE  # the firmware's stick deadband per axis [µs of 500] (the tables start past it)
L_BATTERY = L_DEADBAND + 3  # the pack under load: rest, sag, reference [V] (0: none; Airframe.battery_constants)
N_LIMITS = L_BATTERY + 3


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def stick_for_rate(rate, axis, limits):  # pragma: no cover - compiled
    """Stick in [−1, 1] that commands ``rate`` [rad/s] on ``axis`` (0 roll, 1 pitch, 2 yaw; Betaflight's sense)."""
    if limits[L_RATE_TABLES] == 0.0:
        return min(max(rate / limits[L_RATE_MAX], -1.0), 1.0)
    base = L_ROLL_TABLE + axis * N_TABLE
    target = abs(rate)
    if target >= limits[base + N_TABLE - 1]:
        return 1.0 if rate > 0.0 else -1.0
    if target == 0.0:
        return 0.0
    low = 0
    high = N_TABLE - 1
    while high - low > 1:  # the last sample at or below the target (the curve rises)
        middle = (low + high) // 2
        if limits[base + middle] <= target:
            low = middle
        else:
            high = middle
    r0 = limits[base + low]
    r1 = limits[base + high]
    x = (low + (target - r0) / (r1 - r0)) / (N_TABLE - 1) if r1 > r0 else high / (N_TABLE - 1)
    band = limits[L_DEADBAND + axis]
    if band > 0.0 and x > 0.0:  # the tables are over the deflection past the deadband: step over it
        x = (x * (500.0 - band) + band) / 500.0
    return x if rate >= 0.0 else -x


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def throttle_for_motor(u, limits):  # pragma: no cover - compiled
    """Throttle pulse [us] for the motor command ``u`` (the firmware's throttle curve, inverted)."""
    if limits[L_THROTTLE_TABLE] == 0.0:
        idle = limits[L_IDLE]
        fraction = min(max((u - idle) / (1.0 - idle), 0.0), 1.0)
        return limits[L_MIN_CHECK] + fraction * (2000.0 - limits[L_MIN_CHECK])
    base = L_MOTOR_TABLE
    if u <= limits[base]:
        return 1000.0
    for i in range(1, N_TABLE):
        m1 = limits[base + i]
        if m1 >= u:
            m0 = limits[base + i - 1]
            f = (u - m0) / (m1 - m0) if m1 > m0 else 1.0
            return 1000.0 + 1000.0 * (i - 1 + f) / (N_TABLE - 1)
    return 2000.0


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def throttle_for_collective(collective, limits):  # pragma: no cover - compiled
    """Throttle pulse [us] for a mass-normalised collective [m/s²] (the pilot's inverted model).

    With a battery (``L_BATTERY``) the command is the one whose thrust, the pack's sag at that load on
    all four motors included, gives the collective (a fixed point: the sag changes slowly with u).
    """
    per_rotor = max(collective, 0.0) * limits[L_MASS] / 4.0
    u = sagging_command(per_rotor, limits[L_FMAX], limits[L_CURVE_R], limits[L_CURVE_K], limits[L_BATTERY],
                        limits[L_BATTERY + 1], limits[L_BATTERY + 2])
    return throttle_for_motor(u, limits)


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def program_sticks(cmd, limits, out):  # pragma: no cover - compiled
    """ACRO sticks for a program command (collective [m/s²], p̂, q̂, r̂ [rad/s], body FLU).

    ``out`` = (roll, pitch, yaw) sticks in [−1, 1] and the throttle pulse [us].
    """
    out[0] = stick_for_rate(cmd[1], 0, limits)
    out[1] = stick_for_rate(cmd[2], 1, limits)
    out[2] = stick_for_rate(-cmd[3], 2, limits)
    out[3] = throttle_for_collective(cmd[0], limits)


@nb.njit(cache=True, error_model="numpy")
def frame_commands(breaks, coefficients, hover, period_s, out):  # pragma: no cover - compiled
    """Each radio frame's command: the program's mean over the frame, ``out`` (frames, 4).

    Frame ``j`` covers [j·period, (j + 1)·period) from the program's start; ``breaks`` (K+1,) and
    ``coefficients`` (K, 4, 3) are a :class:`~aerobat.quadrotor.program.CompiledProgram`'s, and past
    its end the command is ``hover``. A frame inside one segment whose command is constant gets
    that constant exactly.
    """
    end = breaks[breaks.shape[0] - 1]
    segments = coefficients.shape[0]
    k = 0
    for j in range(out.shape[0]):
        a = j * period_s
        b = a + period_s
        if a >= end:
            for c in range(4):
                out[j, c] = hover[c]
            continue
        while k < segments - 1 and breaks[k + 1] <= a:
            k += 1
        if b <= breaks[k + 1]:  # inside segment k: the mean of its polynomial (exact for a constant)
            ta = a - breaks[k]
            tb = b - breaks[k]
            for c in range(4):
                c1 = coefficients[k, c, 1]
                c2 = coefficients[k, c, 2]
                out[j, c] = coefficients[k, c, 0]
                if c1 != 0.0 or c2 != 0.0:
                    out[j, c] += c1 * 0.5 * (ta + tb) + c2 * (ta * ta + ta * tb + tb * tb) / 3.0
            continue
        for c in range(4):
            out[j, c] = 0.0
        m = k
        lo = a
        while lo < b:
            hi = min(b, breaks[m + 1]) if m < segments else b
            if m >= segments:  # past the program's end: the hover command
                for c in range(4):
                    out[j, c] += hover[c] * (hi - lo)
            else:
                ta = lo - breaks[m]
                tb = hi - breaks[m]
                for c in range(4):
                    out[j, c] += (coefficients[m, c, 0] * (tb - ta) + coefficients[m, c, 1] * 0.5 * (tb * tb - ta * ta)
                                  + coefficients[m, c, 2] * (tb * tb * tb - ta * ta * ta) / 3.0)
            lo = hi
            m += 1
        for c in range(4):
            out[j, c] /= period_s


def frame_count(duration_s: float, period_s: float, margin_s: float = 0.0) -> int:
    """Frames that cover ``duration_s`` plus ``margin_s`` at ``period_s`` per frame."""
    return max(1, int(math.ceil((duration_s + margin_s) / period_s - 1e-9)))


def frames_of(program: object, period_s: float, frames: int) -> np.ndarray:
    """(frames, 4) frame-mean commands of a :class:`~aerobat.quadrotor.program.CompiledProgram`."""
    out = np.empty((frames, 4))
    frame_commands(program.breakpoints_s, program.coefficients, program.hover,  # type: ignore[attr-defined]
                   float(period_s), out)
    return out
