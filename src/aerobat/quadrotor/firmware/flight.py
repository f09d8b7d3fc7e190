"""A program flown by the firmware model: radio frames, the firmware's loop, the airframe — one compiled kernel.

Per gyro period, as the Betaflight SITL in lockstep and the plant's physics do it: a radio frame
reaches the receiver every ``steps_per_frame`` samples (from the program's start), the firmware
reads the gyro of the true state (``gyro_reading``: the SITL's 16.4 LSB/(deg/s) integer scaled by
Betaflight's 2000/32768), runs its loop (:func:`.loop.step`) and answers a motor packet; the ESC
acts on the packet ``delay`` periods later; the rigid body, the rotors' first-order thrust and their
reaction torque integrate one period with RK4 (:func:`aerobat.quadrotor.xframe.add_rotor_reaction`).
The flight ends exactly at the program's duration (a last, shorter RK4 step), so the final state
moves smoothly with every parameter of the program.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from aerobat.quadrotor.dynamics import P_IZZ, derivative, plant_constants
from aerobat.quadrotor.firmware.layout import K_GYRO_DT, K_QUANTIZE, Q_GYRO, Q_PULSES, Z_PACKET, Z_PID, Z_PID_SETPOINT
from aerobat.quadrotor.firmware.loop import step
from aerobat.quadrotor.firmware.sticks import frame_commands, program_sticks
from aerobat.quadrotor.playback import rk4_after_first_stage
from aerobat.quadrotor.xframe import add_rotor_reaction, battery_thrust_factor, curve_thrust

__all__ = ["A_BATTERY", "A_CURVE_K", "A_CURVE_R", "A_FMAX", "A_ROTOR_J", "A_SPIN", "A_THRUST_COEF", "N_AIRFRAME",
           "N_RECORD", "fly", "gyro_reading", "work_size"]

# the airframe's constants beside the dynamics' plant vector
A_FMAX = 0
A_CURVE_R = 1
A_CURVE_K = 2
A_ROTOR_J = 3
A_THRUST_COEF = 4
A_SPIN = 5  # 4 spin signs (+1 counter-clockwise seen from above)
A_BATTERY = 9  # the battery under load: rest, sag, reference [V] (reference 0: none; Airframe.battery_constants)
N_AIRFRAME = 12
N_RECORD = 1 + 20 + 4 + 3 + 12  # time, state, motor packet, set point, P I D F per axis
_GYRO_LSB = 16.4  # the SITL's LSB per deg/s (sitl.c GYRO_SCALE)
_GYRO_SCALE = 2000.0 / 32768.0  # Betaflight's deg/s per LSB (GYRO_SCALE_2000DPS)


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def gyro_reading(rate_rad_s, quantize):  # pragma: no cover - compiled
    """The firmware's gyro [deg/s] for a true body rate [rad/s] (its axes are aerobat's FLU p, q, r)."""
    raw = rate_rad_s * _GYRO_LSB * (180.0 / math.pi)
    if quantize:
        raw = float(int(raw))
    raw = min(max(raw, -32767.0), 32767.0)
    return raw * _GYRO_SCALE


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _derivative(t, x, thrust, plant, consts, dx):  # pragma: no cover - compiled
    """:func:`~aerobat.quadrotor.dynamics.derivative` plus the rotors' reaction torque on yaw; ``consts``:
    (the plant's constants, the airframe's)."""
    const, airframe = consts
    derivative(t, x, thrust, plant, const, dx)
    add_rotor_reaction(x, dx, airframe[A_ROTOR_J], airframe[A_THRUST_COEF], airframe[A_SPIN:A_SPIN + 4], plant[P_IZZ])


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _rk4(x, t, h, thrust, plant, const, airframe, scratch):  # pragma: no cover - compiled
    consts = (const, airframe)
    _derivative(t, x, thrust, plant, consts, scratch[0])
    rk4_after_first_stage(_derivative, t, x, thrust, plant, consts, h, scratch[0], scratch[1], scratch[2], scratch[3],
                          scratch[4])


@nb.njit(cache=True, fastmath=True, error_model="numpy", nogil=True)
def fly(breaks, coefficients, hover_command, steps_per_frame, duration_s, k, memory, x, plant, airframe, limits,
        hover_packet, delay, work, record):  # pragma: no cover - compiled
    """Fly one program from ``x`` (updated in place to the state at ``duration_s``); the firmware's ``memory`` too.

    ``work``: scratch of at least (frames, 4) + (frames, 4) + (delay + 1, 4) + (6, n_state) floats, flat.
    ``record`` (steps + 1, :data:`N_RECORD`) or empty: a row after every gyro period (and at the end).
    Returns 0, or 1 when the state went non-finite.
    """
    dt = k[K_GYRO_DT]
    period = steps_per_frame * dt
    frames = int(math.ceil(duration_s / period - 1e-9)) + 1
    n = x.shape[0]
    commands = work[0:frames * 4].reshape((frames, 4))
    pulses = work[frames * 4:frames * 8].reshape((frames, 4))
    slots = delay + 1
    pending = work[frames * 8:frames * 8 + slots * 4].reshape((slots, 4))
    scratch = work[frames * 8 + slots * 4:frames * 8 + slots * 4 + 6 * n].reshape((6, n))
    frame_commands(breaks, coefficients, hover_command, period, commands)
    steps = int(k[K_QUANTIZE])
    quantize = (steps & Q_PULSES) != 0
    gyro_steps = (steps & Q_GYRO) != 0
    sticks = scratch[5, 0:4]
    for j in range(frames):
        program_sticks(commands[j], limits, sticks)
        for c in range(3):
            pulse = 1500.0 + 500.0 * min(max(sticks[c], -1.0), 1.0)
            pulses[j, 3 if c == 2 else c] = np.rint(pulse) if quantize else pulse
        throttle = min(max(sticks[3], 1000.0), 2000.0)
        pulses[j, 2] = np.rint(throttle) if quantize else throttle
    for s in range(slots):
        for m in range(4):
            pending[s, m] = hover_packet[m]
    const = plant_constants(plant)
    thrust = scratch[5, 4:8]
    gyro = scratch[5, 8:11]
    whole = int(math.floor(duration_s / dt + 1e-9))
    rest = duration_s - whole * dt
    last = whole + (1 if rest > 1e-12 else 0)
    for i in range(last):
        for a in range(3):
            gyro[a] = gyro_reading(x[10 + a], gyro_steps)
        frame = i % steps_per_frame == 0 and i // steps_per_frame < frames
        step(k, memory, gyro, frame, pulses[min(i // steps_per_frame, frames - 1)])
        for m in range(4):
            pending[i % slots, m] = memory[Z_PACKET + m]
        applied = (i - delay) % slots
        for m in range(4):
            thrust[m] = curve_thrust(pending[applied, m], airframe[A_FMAX], airframe[A_CURVE_R], airframe[A_CURVE_K])
        if airframe[A_BATTERY + 2] > 0.0:  # the pack sags under this step's load
            sag = battery_thrust_factor(pending[applied], airframe[A_BATTERY], airframe[A_BATTERY + 1],
                                        airframe[A_BATTERY + 2])
            for m in range(4):
                thrust[m] *= sag
        h = dt if i < whole else rest
        _rk4(x, i * dt, h, thrust, plant, const, airframe, scratch)
        for j in range(n):
            if not math.isfinite(x[j]):
                return 1
        if record.shape[0] > 0:
            _record(record, i + 1, i * dt + h, x, memory)
    return 0


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _record(record, row, t, x, memory):  # pragma: no cover - compiled
    if row >= record.shape[0]:
        return
    record[row, 0] = t
    for j in range(20):
        record[row, 1 + j] = x[j]
    for m in range(4):
        record[row, 21 + m] = memory[Z_PACKET + m]
    for a in range(3):
        record[row, 25 + a] = memory[Z_PID_SETPOINT + a]
    for j in range(12):
        record[row, 28 + j] = memory[Z_PID + j]


def work_size(duration_s: float, period_s: float, delay: int, n_state: int) -> int:
    """Floats of :func:`fly`'s scratch for a program of ``duration_s``."""
    frames = int(math.ceil(duration_s / period_s - 1e-9)) + 1
    return frames * 8 + (delay + 1) * 4 + 6 * n_state

