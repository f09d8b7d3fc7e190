"""Sticks the way a pilot (or an offboard computer with a radio) gives them to Betaflight.

Two ways of flying, both ending in RC channels:

* **ANGLE mode (hover, take-off, return, landing)**: a position loop on motion-capture
  estimates asks for an acceleration; its direction becomes a roll and pitch *angle* (the
  sticks: angle = stick × ``angle_limit``), its size along the body's thrust axis becomes the
  collective and so the throttle, and the heading is held through the yaw stick (a rate in
  ANGLE mode too). :func:`angle_sticks`.
* **ACRO mode (the maneuver)**: the program's body-rate commands are stick positions through
  the linear rate curve (``rc_rate = srate = 200``, no expo: rate = 2000 °/s × stick, clamped
  at ``rate_limit`` = 1998 °/s), its collective the throttle. :func:`program_sticks`.

Collective to throttle (:func:`throttle_for_collective`): the pilot's model of the vehicle —
per-rotor thrust m·c/4 (nominal mass) through the inverse of the airframe's thrust curve gives a
motor command u, and Betaflight's throttle map ``u = idle + (1 − idle)·(us − min_check)/(2000 −
min_check)`` (settings.toml) gives the pulse. Frames: sticks are in Betaflight's sense (roll
right, pitch forward = nose down, yaw right = nose right), rates and attitudes in aerobat's body
FLU: roll stick = p/ω_max, pitch stick = q/ω_max, yaw stick = −r/ω_max (see :mod:`.physics`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from aerobat.plants.betaflight.params import Airframe
from aerobat.plants.betaflight.settings import BetaflightSettings

__all__ = [
    "L_ANGLE_LIMIT",
    "L_CLIMB",
    "L_FMAX",
    "L_GRAVITY",
    "L_IDLE",
    "L_MASS",
    "L_MIN_CHECK",
    "L_RATE_MAX",
    "L_TILT",
    "N_LIMITS",
    "StickMap",
    "angle_sticks",
    "program_sticks",
    "throttle_for_collective",
]

# limits vector of the compiled pilot
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
N_LIMITS = 11


@dataclass(frozen=True)
class StickMap:
    """What turns commands into sticks: the firmware's curves and the pilot's vehicle model.

    Attributes
    ----------
    rate_max_rad_s : body rate at full stick (ACRO, before the rate limit).
    rate_limit_rad_s : Betaflight's ``rate_limit`` (the setpoint is clamped to it).
    angle_limit_rad : tilt at full stick in ANGLE mode.
    idle : ``motor_idle`` as a motor command; min_check_us : ``min_check``.
    mass_kg, airframe : the pilot's model for collective → throttle (nominal mass, published curve).
    """

    rate_max_rad_s: float
    rate_limit_rad_s: float
    angle_limit_rad: float
    idle: float
    min_check_us: float
    mass_kg: float
    airframe: Airframe

    @classmethod
    def from_settings(cls, settings: BetaflightSettings, airframe: Airframe, mass_kg: float) -> StickMap:
        """The map for the firmware ``settings`` (linear rate curves required: same rate on every axis)."""
        rates = {axis: settings.rate_deg_s(axis, 1.0 - 1e-9) for axis in ("roll", "pitch", "yaw")}
        if len({round(r, 3) for r in rates.values()}) != 1:
            raise ValueError(f"the rate curves differ between axes: {rates}")
        full = float(settings.value("roll_rc_rate")) * 10.0
        for axis in ("roll", "pitch", "yaw"):
            settings.stick_for_rate(axis, 0.0)  # raises unless the curve is linear
        return cls(
            rate_max_rad_s=math.radians(full),
            rate_limit_rad_s=math.radians(float(settings.value("roll_rate_limit"))),
            angle_limit_rad=math.radians(float(settings.value("angle_limit"))),
            idle=float(settings.value("motor_idle")) / 10000.0,
            min_check_us=float(settings.value("min_check")),
            mass_kg=mass_kg,
            airframe=airframe,
        )

    def limits(self, *, max_tilt_rad: float, max_climb_m_s: float, gravity_m_s2: float) -> np.ndarray:
        """The compiled pilot's limits vector (indices ``L_*``)."""
        out = np.zeros(N_LIMITS)
        out[L_TILT] = max_tilt_rad
        out[L_CLIMB] = max_climb_m_s
        out[L_GRAVITY] = gravity_m_s2
        out[L_ANGLE_LIMIT] = self.angle_limit_rad
        out[L_RATE_MAX] = self.rate_max_rad_s
        out[L_MASS] = self.mass_kg
        out[L_FMAX] = self.airframe.thrust_max_n
        out[L_CURVE_R] = self.airframe.curve_min_speed_ratio
        out[L_CURVE_K] = self.airframe.curve_shape
        out[L_IDLE] = self.idle
        out[L_MIN_CHECK] = self.min_check_us
        return out


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def throttle_for_collective(collective, limits):  # pragma: no cover - compiled
    """Throttle pulse [us] for a mass-normalised collective [m/s²] (the pilot's inverted model)."""
    per_rotor = max(collective, 0.0) * limits[L_MASS] / 4.0
    r = limits[L_CURVE_R]
    k = limits[L_CURVE_K]
    s = (math.sqrt(per_rotor / limits[L_FMAX]) - r) / (1.0 - r)
    s = min(max(s, 0.0), 1.0)
    if k > 0.0:
        u = ((k - 1.0) + math.sqrt((1.0 - k) ** 2 + 4.0 * k * s * s)) / (2.0 * k)
    else:
        u = s * s
    idle = limits[L_IDLE]
    fraction = min(max((u - idle) / (1.0 - idle), 0.0), 1.0)
    return limits[L_MIN_CHECK] + fraction * (2000.0 - limits[L_MIN_CHECK])


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def program_sticks(cmd, limits, out):  # pragma: no cover - compiled
    """ACRO sticks for a program command (collective [m/s²], p̂, q̂, r̂ [rad/s], body FLU).

    ``out`` = (roll, pitch, yaw) sticks in [−1, 1] and the throttle pulse [us].
    """
    full = limits[L_RATE_MAX]
    out[0] = min(max(cmd[1] / full, -1.0), 1.0)
    out[1] = min(max(cmd[2] / full, -1.0), 1.0)
    out[2] = min(max(-cmd[3] / full, -1.0), 1.0)
    out[3] = throttle_for_collective(cmd[0], limits)


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def angle_sticks(pos, vel, quat, target, integral, gains, limits, dt, out):  # pragma: no cover - compiled
    """ANGLE-mode sticks that fly the vehicle to ``target`` (position PID on estimates).

    ``gains`` = (k_p [1/s²], k_d [1/s], k_i [1/s³], k_yaw [1/s]); the integral is updated
    in place (only near the target, clamped). ``out`` = (roll, pitch, yaw) sticks in [−1, 1]
    and the throttle pulse [us].
    """
    kp = gains[0]
    kd = gains[1]
    ki = gains[2]
    kyaw = gains[3]
    g = limits[L_GRAVITY]
    a = np.empty(3)
    for i in range(3):
        err = target[i] - pos[i]
        if abs(err) < 0.15:
            integral[i] = min(max(integral[i] + err * dt, -0.5), 0.5)
        # a velocity loop around a limited position loop: the plain PD near the target
        v_des = kp / kd * err
        if i == 2:
            v_des = min(max(v_des, -limits[L_CLIMB]), limits[L_CLIMB])
        a[i] = kd * (v_des - vel[i]) + ki * integral[i]
    a[2] = max(a[2] + g, 0.3 * g)
    horiz = math.sqrt(a[0] * a[0] + a[1] * a[1])
    most = math.tan(limits[L_TILT]) * a[2]
    if horiz > most:
        a[0] *= most / horiz
        a[1] *= most / horiz
    qw = quat[0]
    qx = quat[1]
    qy = quat[2]
    qz = quat[3]
    yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    c = math.cos(yaw)
    s = math.sin(yaw)
    norm = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    bx = (c * a[0] + s * a[1]) / norm  # desired thrust direction in the heading frame
    by = (-s * a[0] + c * a[1]) / norm
    bz = a[2] / norm
    roll = -math.asin(min(max(by, -1.0), 1.0))  # right side down
    pitch = math.atan2(bx, bz)  # nose down
    # collective along the current thrust axis (body z in the world)
    r13 = 2.0 * (qx * qz + qw * qy)
    r23 = 2.0 * (qy * qz - qw * qx)
    r33 = 1.0 - 2.0 * (qx * qx + qy * qy)
    collective = a[0] * r13 + a[1] * r23 + a[2] * r33
    angle_limit = limits[L_ANGLE_LIMIT]
    out[0] = min(max(roll / angle_limit, -1.0), 1.0)
    out[1] = min(max(pitch / angle_limit, -1.0), 1.0)
    yaw_rate = -kyaw * yaw  # heading 0; FLU rate about z-up
    out[2] = min(max(-yaw_rate / limits[L_RATE_MAX], -1.0), 1.0)
    out[3] = throttle_for_collective(collective, limits)
