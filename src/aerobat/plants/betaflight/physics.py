"""The physical world around the firmware: one compiled, allocation-free step per state packet.

The vehicle is aerobat's rigid body (:func:`aerobat.quadrotor.dynamics.plant_derivative`, the
state layout of :mod:`aerobat.quadrotor.dynamics`: world frame z up, body FLU) with an X-frame
rotor layout in Betaflight's motor order, each rotor's steady-state thrust from the airframe's
thrust curve at the firmware's motor command, first-order thrust dynamics with rising and falling
time constants, drag, wind, and a floor. :func:`step` advances one gyro period and writes the
next state packet (what the firmware's sensors read at the new instant).

Frames. aerobat's world is (x, y, z-up); it is read as north-west-up, so NED = (x, −y, −z) and
body FRD = (x_b, −y_b, −z_b). The same 180° turn about x maps both, hence the FRD→NED quaternion
is (w, x, −y, −z) of aerobat's FLU→world quaternion, gyro FRD = (p, −q, −r) and the
accelerometer's specific force FRD = (f_x, −f_y, −f_z). A positive roll (right side down) is
+p in both frames; a nose-down pitch is +q in FLU and −q in FRD; a nose-right yaw is −r in FLU.

Motor slots (Betaflight packet order, QUADX, props in): 0 front-right CCW, 1 rear-left CCW,
2 front-left CW, 3 rear-right CW. A counter-clockwise propeller (seen from above) pushes the
body clockwise: its yaw moment about z-up is −κ f.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from aerobat.plants.fpv.params import BetaflightParams
from aerobat.quadrotor.dynamics import N_STATE, P_GAIN, P_IZZ, plant_derivative
from aerobat.quadrotor.playback import rk4_after_first_stage
from aerobat.quadrotor.xframe import add_rotor_reaction, battery_thrust_factor, curve_thrust, xframe_plant

__all__ = [
    "A_ACCEL_NOISE",
    "A_ATT_ERR",
    "A_BATTERY",
    "A_BIAS",
    "A_VIBRATION",
    "A_CURVE_K",
    "A_CURVE_R",
    "A_FMAX",
    "A_GRAVITY",
    "A_GROUND",
    "A_GYRO_NOISE",
    "A_SCALE",
    "A_STEP",
    "C_CONTACT",
    "C_DELAY",
    "C_TICK",
    "N_AUX",
    "N_COUNTERS",
    "PACKET_DOUBLES",
    "PHASE_ROW",
    "SCRATCH_ROWS",
    "advance",
    "airframe_plant",
    "aux_vector",
    "ground_state",
    "prime",
    "step",
    "store_motors",
    "thrust_curve",
    "write_packet",
]

PACKET_DOUBLES = 18
"""The state packet: t, gyro FRD (3), specific force FRD (3), quaternion FRD→NED (4), velocity (3),
position (3), pressure."""

# aux vector: the step's constants
A_STEP = 0  # step length [s]
A_GRAVITY = 1
A_GROUND = 2  # floor height, world z [m]
A_FMAX = 3  # thrust curve: f_max [N], min-speed ratio r, shape k
A_CURVE_R = 4
A_CURVE_K = 5
A_SCALE = 6  # 3 gyro scale errors (FLU)
A_BIAS = 9  # 3 gyro biases [rad/s] (FLU)
A_ATT_ERR = 12  # roll, pitch error of the attitude sent to the firmware [rad]
A_GYRO_NOISE = 14
A_ACCEL_NOISE = 15
A_ROTOR_J = 16  # rotor (prop + bell) inertia about its axis [kg m²]
A_THRUST_COEF = 17  # f = k Ω² [N/(rad/s)²]
A_SPIN = 18  # 4 spin signs (+1: counter-clockwise seen from above)
A_BATTERY = 22  # the battery under load: rest, sag, reference [V] (reference 0: none; Airframe.battery_constants)
A_VIBRATION = 25  # the rotors' vibration lines: roll, pitch, yaw amplitude [rad/s] at a reference thrust [N]
# (reference 0: none; Airframe.vibration_constants)
N_AUX = 29

PHASE_ROW = 7
"""``scratch``'s row whose first four entries are the rotors' angles [rad] (their vibration lines' phases); rows
0–5 are the step's work space, row 6 the frame loop's held motion-capture sample (``fpv.frames.HELD_ROW``)."""
SCRATCH_ROWS = 8
"""Rows of the ``scratch`` a flight gives :func:`step`, :func:`advance` and :func:`prime`."""
_FIRST_ANGLES = 2.399963229728653  # the rotors start a golden angle apart [rad], not in phase

# counters: integers the step keeps
C_TICK = 0  # steps taken
C_DELAY = 1  # motor-output delay in steps
C_CONTACT = 2  # 1 while resting on the floor
N_COUNTERS = 3

_SEA_LEVEL_PA = 101325.0


def airframe_plant(params: BetaflightParams, *, thrust_gains: tuple[float, float, float, float] | None = None,
                   wind_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0),
                   gust_amplitude_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0),
                   gust_frequency_hz: float = 0.0, gust_phase_rad: float = 0.0) -> np.ndarray:
    """The plant vector of :mod:`aerobat.quadrotor.dynamics` for the X-frame airframe in packet order."""
    aero = params.aerodynamics
    extra: dict = {}
    if aero.enabled:
        extra = {"body_drag_n_s2_m2": aero.body_drag_n_s2_m2, "rotor_drag_s_m": aero.rotor_drag_s_m,
                 "rotational_damping_n_m_s": aero.rotational_damping_n_m_s}
    return xframe_plant(params.airframe, thrust_gains=thrust_gains, wind_m_s=wind_m_s,
                        gust_amplitude_m_s=gust_amplitude_m_s, gust_frequency_hz=gust_frequency_hz,
                        gust_phase_rad=gust_phase_rad, **extra)


def aux_vector(params: BetaflightParams, *, step_s: float, ground_z_m: float, gravity_m_s2: float) -> np.ndarray:
    """The step's constants (indices ``A_*``)."""
    a, s = params.airframe, params.sensors
    aux = np.zeros(N_AUX)
    aux[A_STEP] = step_s
    aux[A_GRAVITY] = gravity_m_s2
    aux[A_GROUND] = ground_z_m
    aux[A_FMAX] = a.thrust_max_n
    aux[A_CURVE_R] = a.curve_min_speed_ratio
    aux[A_CURVE_K] = a.curve_shape
    aux[A_SCALE : A_SCALE + 3] = s.gyro_scale_error
    aux[A_BIAS : A_BIAS + 3] = s.gyro_bias_rad_s
    aux[A_ATT_ERR : A_ATT_ERR + 2] = s.attitude_error_rad
    aux[A_GYRO_NOISE] = s.gyro_noise_rad_s
    aux[A_ACCEL_NOISE] = s.accel_noise_m_s2
    aux[A_ROTOR_J] = a.rotor_inertia_kg_m2
    aux[A_THRUST_COEF] = a.thrust_coefficient_n_s2
    aux[A_SPIN : A_SPIN + 4] = [1.0 if ccw else -1.0 for ccw in a.spins_ccw]
    aux[A_BATTERY : A_BATTERY + 3] = a.battery_constants()
    aux[A_VIBRATION : A_VIBRATION + 4] = a.vibration_constants()
    return aux


def ground_state(position_m: tuple[float, float, float]) -> np.ndarray:
    """The vehicle standing level on the floor at ``position_m``, motors stopped."""
    x = np.zeros(N_STATE)
    x[0:3] = position_m
    x[6] = 1.0
    return x


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def thrust_curve(u, aux):  # pragma: no cover - compiled
    """Steady-state rotor thrust [N] at motor command ``u`` (0 or less: stopped)."""
    return curve_thrust(u, aux[A_FMAX], aux[A_CURVE_R], aux[A_CURVE_K])


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def derivative(t, x, ft, plant, aux, dx):  # pragma: no cover - compiled
    """:func:`~aerobat.quadrotor.dynamics.plant_derivative` plus the rotors' reaction torque on yaw
    (:func:`~aerobat.quadrotor.xframe.add_rotor_reaction`)."""
    plant_derivative(t, x, ft, plant, dx)
    add_rotor_reaction(x, dx, aux[A_ROTOR_J], aux[A_THRUST_COEF], aux[A_SPIN:A_SPIN + 4], plant[P_IZZ])


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def write_packet(x, t, deriv, aux, contact, noise, packet):  # pragma: no cover - compiled
    """The state packet the firmware reads at time ``t`` for true state ``x`` (``deriv`` = dx/dt there)."""
    g = aux[A_GRAVITY]
    qw = x[6]
    qx = x[7]
    qy = x[8]
    qz = x[9]
    # specific force in the world: a − g_vec (on the floor the normal force cancels gravity)
    if contact != 0:
        fx = 0.0
        fy = 0.0
        fz = g
    else:
        fx = deriv[3]
        fy = deriv[4]
        fz = deriv[5] + g
    # to the body: Rᵀ f
    r11 = 1.0 - 2.0 * (qy * qy + qz * qz)
    r12 = 2.0 * (qx * qy - qw * qz)
    r13 = 2.0 * (qx * qz + qw * qy)
    r21 = 2.0 * (qx * qy + qw * qz)
    r22 = 1.0 - 2.0 * (qx * qx + qz * qz)
    r23 = 2.0 * (qy * qz - qw * qx)
    r31 = 2.0 * (qx * qz - qw * qy)
    r32 = 2.0 * (qy * qz + qw * qx)
    r33 = 1.0 - 2.0 * (qx * qx + qy * qy)
    bx = r11 * fx + r21 * fy + r31 * fz
    by = r12 * fx + r22 * fy + r32 * fz
    bz = r13 * fx + r23 * fy + r33 * fz
    an = aux[A_ACCEL_NOISE]
    gn = aux[A_GYRO_NOISE]
    p = (1.0 + aux[A_SCALE]) * x[10] + aux[A_BIAS] + gn * noise[0]
    q = (1.0 + aux[A_SCALE + 1]) * x[11] + aux[A_BIAS + 1] + gn * noise[1]
    r = (1.0 + aux[A_SCALE + 2]) * x[12] + aux[A_BIAS + 2] + gn * noise[2]
    # attitude the firmware flies on: q ⊗ δ, δ = small roll/pitch error in the body
    dx = 0.5 * aux[A_ATT_ERR]
    dy = 0.5 * aux[A_ATT_ERR + 1]
    dw = math.sqrt(max(0.0, 1.0 - dx * dx - dy * dy))
    mw = qw * dw - qx * dx - qy * dy
    mx = qw * dx + qx * dw - qz * dy
    my = qw * dy + qy * dw + qz * dx
    mz = qz * dw + qx * dy - qy * dx
    packet[0] = t
    packet[1] = p  # gyro FRD
    packet[2] = -q
    packet[3] = -r
    packet[4] = bx + an * noise[3]  # specific force FRD
    packet[5] = -(by + an * noise[4])
    packet[6] = -(bz + an * noise[5])
    packet[7] = mw  # FRD→NED quaternion
    packet[8] = mx
    packet[9] = -my
    packet[10] = -mz
    for i in range(11, 17):
        packet[i] = 0.0  # GPS velocity and position: no GPS in this build
    altitude = x[2]
    packet[17] = _SEA_LEVEL_PA * (1.0 - 2.25577e-5 * altitude) ** 5.25588


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _vibrate(x, plant, aux, angles, h, packet):  # pragma: no cover - compiled
    """Turn each rotor by its speed over ``h`` (``angles``), then add its vibration line to the packet's gyro.

    Rotor m turns at Ω = √(f / k) (f its thrust: its gain × the state's x[13 + m]; k ``A_THRUST_COEF``), so
    rotors with other gains turn at other speeds and their lines beat; a line's amplitude is the reference
    amplitude × f / the reference thrust (an imbalance's force grows with Ω²).
    """
    reference = aux[A_VIBRATION + 3]
    k = aux[A_THRUST_COEF]
    roll = 0.0
    pitch = 0.0
    yaw = 0.0
    for m in range(4):
        f = max(plant[P_GAIN + m] * x[13 + m], 0.0)
        angle = angles[m] + h * math.sqrt(f / k)
        angle -= 2.0 * math.pi * math.floor(angle / (2.0 * math.pi))
        angles[m] = angle
        share = f / reference
        s = math.sin(angle)
        roll += share * s
        pitch += share * math.cos(angle)
        yaw += share * s
    packet[1] += aux[A_VIBRATION] * roll  # gyro FRD: (p, −q, −r)
    packet[2] -= aux[A_VIBRATION + 1] * pitch
    packet[3] -= aux[A_VIBRATION + 2] * yaw


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def step(x, motors, plant, aux, pending, counters, noise, packet, scratch):  # pragma: no cover - compiled
    """Advance the world one gyro period with the firmware's latest ``motors``; write the next packet.

    ``motors`` (4, float32): the motor packet just received (commands in [0, 1], 0 = stopped).
    ``pending`` (D+1, 4): ring of motor commands for the output delay of D steps (``counters``).
    ``noise`` (6,): standard normal draws for the next packet's gyro and accelerometer noise.
    ``scratch`` (:data:`SCRATCH_ROWS`, N_STATE): work space, and the rotors' angles (:data:`PHASE_ROW`).
    Returns 1 if the state went non-finite, else 0.
    :func:`store_motors` then :func:`advance`.
    """
    store_motors(motors, pending, counters[C_TICK])
    return advance(x, plant, aux, pending, counters, noise, packet, scratch)


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def store_motors(motors, pending, tick):  # pragma: no cover - compiled
    """Put the motor packet answering step ``tick`` into the output delay's ring ``pending``."""
    slots = pending.shape[0]
    for j in range(4):
        pending[tick % slots, j] = motors[j]


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def advance(x, plant, aux, pending, counters, noise, packet, scratch):  # pragma: no cover - compiled
    """:func:`step` without storing the motor packet: the world one gyro period on, with the delayed command.

    With an output delay of at least one step (``counters[C_DELAY] >= 1``) the command acting in
    this step was stored steps ago, so this can run before the step's own motor packet arrives
    (:func:`store_motors` it afterwards): the physics overlaps the firmware's work.
    """
    h = aux[A_STEP]
    tick = counters[C_TICK]
    delay = counters[C_DELAY]
    slots = pending.shape[0]
    applied = (tick - delay) % slots if tick >= delay else -1
    ft = scratch[5]
    for j in range(4):
        ft[j] = thrust_curve(pending[applied, j], aux) if applied >= 0 else 0.0
    if applied >= 0 and aux[A_BATTERY + 2] > 0.0:  # the pack sags under this step's load
        sag = battery_thrust_factor(pending[applied], aux[A_BATTERY], aux[A_BATTERY + 1], aux[A_BATTERY + 2])
        for j in range(4):
            ft[j] *= sag
    t = tick * h
    k1 = scratch[0]
    k2 = scratch[1]
    k3 = scratch[2]
    k4 = scratch[3]
    tmp = scratch[4]
    n = x.shape[0]
    resting = counters[C_CONTACT] != 0
    derivative(t, x, ft, plant, aux, k1)
    if resting and k1[5] <= 0.0:
        # standing on the floor: only the rotors change (thrust states, first order)
        for j in range(4):
            x[13 + j] += h * k1[13 + j]
    else:
        counters[C_CONTACT] = 0
        rk4_after_first_stage(derivative, t, x, ft, plant, aux, h, k1, k2, k3, k4, tmp)
        if x[2] < aux[A_GROUND]:
            # the floor: stop, stand level on the legs, keep the heading
            x[2] = aux[A_GROUND]
            for j in range(3, 6):
                x[j] = 0.0
            for j in range(10, 13):
                x[j] = 0.0
            yaw = math.atan2(2.0 * (x[6] * x[9] + x[7] * x[8]), 1.0 - 2.0 * (x[8] * x[8] + x[9] * x[9]))
            x[6] = math.cos(0.5 * yaw)
            x[7] = 0.0
            x[8] = 0.0
            x[9] = math.sin(0.5 * yaw)
            counters[C_CONTACT] = 1
    counters[C_TICK] = tick + 1
    for j in range(n):
        if not math.isfinite(x[j]):
            return 1
    derivative(t + h, x, ft, plant, aux, k1)
    write_packet(x, t + h, k1, aux, counters[C_CONTACT], noise, packet)
    if aux[A_VIBRATION + 3] > 0.0:
        _vibrate(x, plant, aux, scratch[PHASE_ROW], h, packet)
    return 0


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def prime(x, plant, aux, counters, noise, packet, scratch):  # pragma: no cover - compiled
    """Write the packet of the current instant (before the first :func:`step`), motors stopped; the rotors'
    angles start a golden angle apart."""
    for m in range(4):
        scratch[PHASE_ROW, m] = m * _FIRST_ANGLES
    ft = scratch[5]
    for j in range(4):
        ft[j] = 0.0
    t = counters[C_TICK] * aux[A_STEP]
    plant_derivative(t, x, ft, plant, scratch[0])
    write_packet(x, t, scratch[0], aux, counters[C_CONTACT], noise, packet)
