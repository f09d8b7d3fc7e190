"""The paper's quadrocopter model (Sect. 6) as compiled, allocation-free kernels.

State vector (length :data:`N_STATE`, index slices defined once here):

=============  =======  ==========================================================
``POS``        0:3      position of the centre of mass, world frame [m] (z up)
``VEL``        3:6      velocity, world frame [m/s]
``QUAT``       6:10     attitude quaternion **(w, x, y, z)**, Hamilton, body→world
``OMEGA``      10:13    body rates (p, q, r) [rad/s]
``THRUST``     13:17    motor thrust states f_1..f_4 [N] (paper numbering, Fig. 4)
``RATE_INT``   17:20    ∫ω dt [rad], used only to count whole revolutions
=============  =======  ==========================================================

The attitude is a unit quaternion, renormalized after every integration step,
so the rotation matrix built from it is orthonormal to rounding error (the
paper warns that integrating R directly drifts). Euler angles follow eq 13
applied to Rᵀ (Diebel's matrix maps world→body; the paper's R maps body→world).

Plants are described by a flat parameter vector (indices ``P_*``) so one
kernel serves the nominal model and the arena's "true" vehicle: motor
positions relative to the centre of mass, per-motor thrust gains and yaw
coefficients, and aerodynamic terms that are zero for the nominal model.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from aerobat.quadrotor.vehicle import ControllerParams, VehicleConfig, VehicleParams

__all__ = [
    "N_STATE",
    "OMEGA",
    "POS",
    "QUAT",
    "RATE_INT",
    "THRUST",
    "VEL",
    "controller_constants",
    "controller_thrusts",
    "controller_vector",
    "derivative",
    "euler_zyx",
    "hover_state",
    "model_plant_vector",
    "normalize_quaternion",
    "plant_constants",
    "plant_derivative",
    "plant_vector",
    "rotation_angles",
    "rotation_matrices",
    "thrust_commands",
]

# ---------------------------------------------------------------- state layout
POS = slice(0, 3)
VEL = slice(3, 6)
QUAT = slice(6, 10)
OMEGA = slice(10, 13)
THRUST = slice(13, 17)
RATE_INT = slice(17, 20)
N_STATE = 20
STATE_NAMES = ("x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s", "qw", "qx", "qy", "qz", "p_rad_s", "q_rad_s",
               "r_rad_s", "f1_n", "f2_n", "f3_n", "f4_n", "rotation_x_rad", "rotation_y_rad", "rotation_z_rad")
"""Column names of a state vector: position, velocity (world, z up), attitude quaternion (w, x, y, z; body→world),
body rates, rotor thrusts, and the integrated body rates ∫ω dt (unwrapped rotation)."""
_IQ = 6
_IW = 10
_IF = 13
_II = 17

# ---------------------------------------------------------- plant parameters
P_MASS = 0
P_IXX = 1
P_IYY = 2
P_IZZ = 3
P_GRAV = 4
P_RATE_UP = 5
P_RATE_DN = 6
P_FMIN = 7
P_FMAX = 8
P_MX = 9  # 4 motor x positions relative to the centre of mass [m]
P_MY = 13  # 4 motor y positions relative to the centre of mass [m]
P_KYAW = 17  # 4 yaw-moment coefficients (+κ, −κ, +κ, −κ nominally) [m]
P_GAIN = 21  # 4 per-motor thrust gains [-]
P_BODY_DRAG = 25  # quadratic body drag, F = −c |v_air| v_air [N s²/m²]
P_ROTOR_DRAG = 26  # rotor drag: body in-plane force −k · T · v_air,xy [s/m]
P_ROT_DAMP = 27  # 3 rotational damping coefficients, τ = −c ω [N m s/rad]
P_WIND = 30  # 3 constant wind components, world frame [m/s]
P_GUST_AMP = 33  # 3 sinusoidal gust amplitudes [m/s]
P_GUST_FREQ = 36  # gust frequency [Hz]
P_GUST_PHASE = 37  # gust phase [rad]
P_AXIAL_DRAG = 38  # rotor drag along the body z axis: force −k · T · v_air,z [s/m]
N_PLANT = 39

# ----------------------------------------------------- controller parameters
C_GAIN = 0  # 3 rate gains P_p, P_q, P_r [1/s]
C_MASS = 3
C_ARM = 4
C_IXX = 5
C_IYY = 6
C_IZZ = 7
C_KAPPA = 8
C_ORDER = 9  # 4 physical motor slots (0-based) receiving commands 1..4
N_CTRL = 13

# --------------------------------------------------------- sensor parameters
S_SCALE = 0  # 3 gyro scale errors [-] (measured = (1 + s) ω + b)
S_BIAS = 3  # 3 gyro biases [rad/s]
N_SENSOR = 6


def plant_vector(
    vehicle: VehicleParams,
    *,
    com_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
    thrust_gains: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0),
    body_drag_n_s2_m2: float = 0.0,
    rotor_drag_s_m: float = 0.0,
    rotor_drag_axial_s_m: float = 0.0,
    rotational_damping_n_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0),
    wind_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0),
    gust_amplitude_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0),
    gust_frequency_hz: float = 0.0,
    gust_phase_rad: float = 0.0,
) -> np.ndarray:
    """Flat plant parameter vector for the kernels; the defaults give the paper's model."""
    v = np.zeros(N_PLANT)
    v[P_MASS] = vehicle.mass_kg
    v[P_IXX] = vehicle.inertia_xx_kg_m2
    v[P_IYY] = vehicle.inertia_yy_kg_m2
    v[P_IZZ] = vehicle.inertia_zz_kg_m2
    v[P_GRAV] = vehicle.gravity_m_s2
    v[P_RATE_UP] = vehicle.motor_rate_up_per_s
    v[P_RATE_DN] = vehicle.motor_rate_down_per_s
    v[P_FMIN] = vehicle.rotor_thrust_min_n
    v[P_FMAX] = vehicle.rotor_thrust_max_n
    arm = vehicle.arm_length_m
    v[P_MX : P_MX + 4] = np.array([arm, 0.0, -arm, 0.0]) - com_offset_m[0]
    v[P_MY : P_MY + 4] = np.array([0.0, arm, 0.0, -arm]) - com_offset_m[1]
    v[P_KYAW : P_KYAW + 4] = vehicle.drag_constant_m * np.array([1.0, -1.0, 1.0, -1.0])
    v[P_GAIN : P_GAIN + 4] = thrust_gains
    v[P_BODY_DRAG] = body_drag_n_s2_m2
    v[P_ROTOR_DRAG] = rotor_drag_s_m
    v[P_ROT_DAMP : P_ROT_DAMP + 3] = rotational_damping_n_m_s
    v[P_WIND : P_WIND + 3] = wind_m_s
    v[P_GUST_AMP : P_GUST_AMP + 3] = gust_amplitude_m_s
    v[P_GUST_FREQ] = gust_frequency_hz
    v[P_GUST_PHASE] = gust_phase_rad
    v[P_AXIAL_DRAG] = rotor_drag_axial_s_m
    return v


def model_plant_vector(config: VehicleConfig) -> np.ndarray:
    """The design model's plant vector: ``config.vehicle`` plus its :class:`~aerobat.quadrotor.vehicle.ModelEffects`.

    Rate damping and drag use the kernel's aerodynamic terms; a thrust-proportional moment
    arm (a, b, c) shifts every motor's lever so that the moments gain (a·T, b·T, c·T).
    The latency is not part of the plant: the simulation applies it to the rate feedback.
    """
    e = config.effects
    v = plant_vector(config.vehicle, thrust_gains=e.motor_thrust_gains, body_drag_n_s2_m2=e.body_drag_n_s2_m2,
                     rotor_drag_s_m=e.rotor_drag_s_m, rotor_drag_axial_s_m=e.rotor_drag_axial_s_m,
                     rotational_damping_n_m_s=e.rate_damping_n_m_s)
    arm = e.thrust_moment_arm_m
    v[P_MY : P_MY + 4] += arm[0]  # τ_x = Σ y_j f_j
    v[P_MX : P_MX + 4] -= arm[1]  # τ_y = −Σ x_j f_j
    v[P_KYAW : P_KYAW + 4] += arm[2]  # τ_z = Σ k_j f_j
    return v


def controller_vector(controller: ControllerParams) -> np.ndarray:
    """Flat controller parameter vector for the kernels."""
    c = np.zeros(N_CTRL)
    c[C_GAIN : C_GAIN + 3] = (controller.rate_gain_p_per_s, controller.rate_gain_q_per_s, controller.rate_gain_r_per_s)
    c[C_MASS] = controller.mass_kg
    c[C_ARM] = controller.arm_length_m
    c[C_IXX] = controller.inertia_xx_kg_m2
    c[C_IYY] = controller.inertia_yy_kg_m2
    c[C_IZZ] = controller.inertia_zz_kg_m2
    c[C_KAPPA] = controller.drag_constant_m
    c[C_ORDER : C_ORDER + 4] = np.array(controller.motor_order, dtype=float) - 1.0
    return c


def hover_state(vehicle: VehicleParams, position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Static hover of the nominal model at ``position_m``: level, at rest, motors at m·g/4."""
    x = np.zeros(N_STATE)
    x[POS] = position_m
    x[QUAT] = (1.0, 0.0, 0.0, 0.0)
    x[THRUST] = vehicle.hover_rotor_thrust_n
    return x


# ------------------------------------------------------------------ kernels
#
# The kernels never divide inside the integration loop: what the model divides by (mass,
# inertias, arm length, yaw coefficient, the quaternion's norm) is inverted once per run (from
# the parameter vectors as they are then: plant_constants, controller_constants) or once per
# step, and the controller hands its four thrusts to the motor model as values, not through an
# array. (x·(1/I) and x/I differ in the last bit: sessions recorded before aerobat 0.3.0 continue to
# ~1e-9, not bit for bit; resume_session says so.)

# plant_constants(plant) = (1/m, 1/Ixx, 1/Iyy, 1/Izz, drag or damping present)
K_INV_MASS = 0
K_INV_I = 1  # 3
K_AERO = 4
# controller_constants(ctrl) = (2/l, 1/κ, the command (0-based) that motor slot 0, 1, 2, 3 receives)
Q_TWO_OVER_ARM = 0
Q_INV_KAPPA = 1
Q_SOURCE_0 = 2
Q_SOURCE_1 = 3
Q_SOURCE_2 = 4
Q_SOURCE_3 = 5


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def plant_constants(plant):  # pragma: no cover - compiled
    """(1/m, 1/Ixx, 1/Iyy, 1/Izz, aero) of a plant vector; ``aero`` = 1 if any drag or rotational damping acts."""
    aero = (plant[P_BODY_DRAG] != 0.0 or plant[P_ROTOR_DRAG] != 0.0 or plant[P_AXIAL_DRAG] != 0.0
            or plant[P_ROT_DAMP] != 0.0 or plant[P_ROT_DAMP + 1] != 0.0 or plant[P_ROT_DAMP + 2] != 0.0)
    return (1.0 / plant[P_MASS], 1.0 / plant[P_IXX], 1.0 / plant[P_IYY], 1.0 / plant[P_IZZ], 1.0 if aero else 0.0)


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def controller_constants(ctrl):  # pragma: no cover - compiled
    """(2/l, 1/κ, s0, s1, s2, s3) of a controller vector: s_j is the command (0-based) motor slot j receives."""
    source = np.zeros(4, dtype=np.int64)
    for i in range(4):
        source[int(ctrl[C_ORDER + i])] = i
    return (2.0 / ctrl[C_ARM], 1.0 / ctrl[C_KAPPA], source[0], source[1], source[2], source[3])


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _pick(c0, c1, c2, c3, i):  # pragma: no cover - compiled
    return c0 if i == 0 else (c1 if i == 1 else (c2 if i == 2 else c3))


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def thrust_commands(cmd, p, q, r, ctrl, cc):  # pragma: no cover - compiled
    """Eqs 14–21 with ``cc`` = :func:`controller_constants`: the desired thrusts f̃ of motor slots 0–3."""
    ixx = ctrl[C_IXX]
    iyy = ctrl[C_IYY]
    izz = ctrl[C_IZZ]
    ap = ctrl[C_GAIN] * (cmd[1] - p)
    aq = ctrl[C_GAIN + 1] * (cmd[2] - q)
    ar = ctrl[C_GAIN + 2] * (cmd[3] - r)
    mp = ixx * ap + q * r * (izz - iyy)
    mq = iyy * aq + r * p * (ixx - izz)
    mr = izz * ar + p * q * (iyy - ixx)
    total = ctrl[C_MASS] * cmd[0]
    yaw = mr * cc[Q_INV_KAPPA]
    two_over_l = cc[Q_TWO_OVER_ARM]
    c0 = 0.25 * (total + yaw - two_over_l * mq)
    c1 = 0.25 * (total - yaw + two_over_l * mp)
    c2 = 0.25 * (total + yaw + two_over_l * mq)
    c3 = 0.25 * (total - yaw - two_over_l * mp)
    return (_pick(c0, c1, c2, c3, cc[Q_SOURCE_0]), _pick(c0, c1, c2, c3, cc[Q_SOURCE_1]),
            _pick(c0, c1, c2, c3, cc[Q_SOURCE_2]), _pick(c0, c1, c2, c3, cc[Q_SOURCE_3]))


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def controller_thrusts(cmd, p, q, r, ctrl, out):  # pragma: no cover - compiled
    """Eqs 14–21: rate P loop, moment inversion with nominal constants, mixer.

    ``cmd`` = (collective [m/s²], p̂, q̂, r̂ [rad/s]); ``p, q, r`` = gyro-measured
    body rates [rad/s]; ``out`` receives the desired motor thrusts f̃ [N] in
    physical motor slots. (The kernels call :func:`thrust_commands`, with the
    controller's constants computed once per run.)
    """
    f = thrust_commands(cmd, p, q, r, ctrl, controller_constants(ctrl))
    for j in range(4):
        out[j] = f[j]


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def derivative(t, x, ftilde, plant, k, dx):  # pragma: no cover - compiled
    """Eqs 8–12 plus the plant's extra effects, with ``k`` = :func:`plant_constants`; dx/dt into ``dx``.

    ``ftilde``: the desired thrusts of motor slots 0–3 (an array, or the tuple
    :func:`thrust_commands` returns).
    """
    qw = x[_IQ]
    qx = x[_IQ + 1]
    qy = x[_IQ + 2]
    qz = x[_IQ + 3]
    p = x[_IW]
    q = x[_IW + 1]
    r = x[_IW + 2]
    r13 = 2.0 * (qx * qz + qw * qy)
    r23 = 2.0 * (qy * qz - qw * qx)
    r33 = 1.0 - 2.0 * (qx * qx + qy * qy)
    fmin = plant[P_FMIN]
    fmax = plant[P_FMAX]
    up = plant[P_RATE_UP]
    down = plant[P_RATE_DN]
    for j in range(4):
        diff = min(max(ftilde[j], fmin), fmax) - x[_IF + j]
        dx[_IF + j] = (up if diff > 0.0 else down) * diff
    f0 = plant[P_GAIN] * x[_IF]
    f1 = plant[P_GAIN + 1] * x[_IF + 1]
    f2 = plant[P_GAIN + 2] * x[_IF + 2]
    f3 = plant[P_GAIN + 3] * x[_IF + 3]
    # pairwise sums: two independent chains instead of one of four
    total = (f0 + f1) + (f2 + f3)
    tx = (plant[P_MY] * f0 + plant[P_MY + 1] * f1) + (plant[P_MY + 2] * f2 + plant[P_MY + 3] * f3)
    ty = -((plant[P_MX] * f0 + plant[P_MX + 1] * f1) + (plant[P_MX + 2] * f2 + plant[P_MX + 3] * f3))
    tz = (plant[P_KYAW] * f0 + plant[P_KYAW + 1] * f1) + (plant[P_KYAW + 2] * f2 + plant[P_KYAW + 3] * f3)
    inv_m = k[K_INV_MASS]
    a_t = total * inv_m
    ax = r13 * a_t
    ay = r23 * a_t
    az = r33 * a_t - plant[P_GRAV]
    if k[K_AERO] != 0.0:
        wx = plant[P_WIND]
        wy = plant[P_WIND + 1]
        wz = plant[P_WIND + 2]
        if plant[P_GUST_FREQ] != 0.0:
            s = math.sin(2.0 * math.pi * plant[P_GUST_FREQ] * t + plant[P_GUST_PHASE])
            wx += plant[P_GUST_AMP] * s
            wy += plant[P_GUST_AMP + 1] * s
            wz += plant[P_GUST_AMP + 2] * s
        vx = x[3] - wx
        vy = x[4] - wy
        vz = x[5] - wz
        speed = math.sqrt(vx * vx + vy * vy + vz * vz)
        cb = plant[P_BODY_DRAG] * speed * inv_m
        ax -= cb * vx
        ay -= cb * vy
        az -= cb * vz
        kr = plant[P_ROTOR_DRAG] * total * inv_m
        if kr != 0.0:
            r11 = 1.0 - 2.0 * (qy * qy + qz * qz)
            r12 = 2.0 * (qx * qy - qw * qz)
            r21 = 2.0 * (qx * qy + qw * qz)
            r22 = 1.0 - 2.0 * (qx * qx + qz * qz)
            r31 = 2.0 * (qx * qz - qw * qy)
            r32 = 2.0 * (qy * qz + qw * qx)
            # body-frame in-plane airspeed (Rᵀ v), drag opposes it, map back with R
            bx = r11 * vx + r21 * vy + r31 * vz
            by = r12 * vx + r22 * vy + r32 * vz
            ax -= kr * (r11 * bx + r12 * by)
            ay -= kr * (r21 * bx + r22 * by)
            az -= kr * (r31 * bx + r32 * by)
        ka = plant[P_AXIAL_DRAG] * total * inv_m
        if ka != 0.0:
            bz = r13 * vx + r23 * vy + r33 * vz  # body-z airspeed (third column of R)
            ax -= ka * r13 * bz
            ay -= ka * r23 * bz
            az -= ka * r33 * bz
        tx -= plant[P_ROT_DAMP] * p
        ty -= plant[P_ROT_DAMP + 1] * q
        tz -= plant[P_ROT_DAMP + 2] * r
    ixx = plant[P_IXX]
    iyy = plant[P_IYY]
    izz = plant[P_IZZ]
    dx[0] = x[3]
    dx[1] = x[4]
    dx[2] = x[5]
    dx[3] = ax
    dx[4] = ay
    dx[5] = az
    dx[_IQ] = -0.5 * (qx * p + qy * q + qz * r)
    dx[_IQ + 1] = 0.5 * (qw * p + qy * r - qz * q)
    dx[_IQ + 2] = 0.5 * (qw * q + qz * p - qx * r)
    dx[_IQ + 3] = 0.5 * (qw * r + qx * q - qy * p)
    dx[_IW] = (tx - q * r * (izz - iyy)) * k[K_INV_I]
    dx[_IW + 1] = (ty - r * p * (ixx - izz)) * k[K_INV_I + 1]
    dx[_IW + 2] = (tz - p * q * (iyy - ixx)) * k[K_INV_I + 2]
    dx[_II] = p
    dx[_II + 1] = q
    dx[_II + 2] = r


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def plant_derivative(t, x, ftilde, plant, dx):  # pragma: no cover - compiled
    """Eqs 8–12 plus the plant's extra effects; writes dx/dt into ``dx``.

    (The kernels call :func:`derivative`, with the plant's constants computed once per run.)
    """
    derivative(t, x, ftilde, plant, plant_constants(plant), dx)


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def normalize_quaternion(x):  # pragma: no cover - compiled
    inv_norm = 1.0 / math.sqrt(x[_IQ] ** 2 + x[_IQ + 1] ** 2 + x[_IQ + 2] ** 2 + x[_IQ + 3] ** 2)
    for i in range(4):
        x[_IQ + i] *= inv_norm


# ------------------------------------------------------------- conversions


def rotation_matrices(states: np.ndarray) -> np.ndarray:
    """Body→world rotation matrices from states (…, N_STATE) → (…, 3, 3)."""
    q = np.asarray(states)[..., QUAT]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def euler_zyx(states: np.ndarray) -> np.ndarray:
    """Eq 13 Z–Y–X Euler angles (φ, θ, ψ) [rad] from states (…, N_STATE) → (…, 3).

    Eq 13 is Diebel's formula for the world→body matrix, so it is applied to Rᵀ:
    φ = atan2(R₃₂, R₃₃), θ = −asin(R₃₁), ψ = atan2(R₂₁, R₁₁).
    """
    R = rotation_matrices(states)
    phi = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    theta = -np.arcsin(np.clip(R[..., 2, 0], -1.0, 1.0))
    psi = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([phi, theta, psi], axis=-1)


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a ⊗ b of (w, x, y, z) quaternions."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    ])


def quaternion_from_rotation_vector(v: np.ndarray) -> np.ndarray:
    """Unit quaternion of the rotation by |v| [rad] about v/|v|."""
    angle = float(np.linalg.norm(v))
    if angle < 1e-15:
        return np.array([1.0, 0.5 * v[0], 0.5 * v[1], 0.5 * v[2]]) / np.sqrt(1.0 + 0.25 * angle**2)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * (v / angle)])


def rotation_vector_from_quaternion(q: np.ndarray) -> np.ndarray:
    """Rotation vector [rad] of a (not necessarily normalized) quaternion, shortest way round."""
    q = q / np.linalg.norm(q)
    if q[0] < 0:  # q and −q are the same attitude
        q = -q
    s = float(np.linalg.norm(q[1:]))
    if s < 1e-12:
        return 2.0 * q[1:]
    return q[1:] / s * 2.0 * np.arctan2(s, q[0])


def rotation_angles(states: np.ndarray) -> np.ndarray:
    """Unwrapped rotation angles about body x, y, z [rad], (…, N_STATE) → (…, 3).

    The Euler angle of each axis plus the whole number of turns that the
    integrated body rate ∫ω dt has accumulated: a triple roll flip ends at
    6π + φ, not at φ. Exact at hover-like attitudes, which is where maneuvers
    are evaluated.
    """
    states = np.asarray(states)
    euler = euler_zyx(states)
    integral = states[..., RATE_INT]
    turns = np.round((integral - euler) / (2.0 * np.pi))
    return euler + 2.0 * np.pi * turns
