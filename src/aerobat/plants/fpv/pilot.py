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
FLU: roll stick = p/ω_max, pitch stick = q/ω_max, yaw stick = −r/ω_max (see :mod:`aerobat.plants.betaflight.physics`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from aerobat.firmware.betaflight.settings import BetaflightSettings
from aerobat.plants.fpv.params import Airframe
from aerobat.quadrotor.firmware.sticks import (
    L_ANGLE_LIMIT,
    L_BATTERY,
    L_CLIMB,
    L_CURVE_K,
    L_CURVE_R,
    L_DEADBAND,
    L_FMAX,
    L_GRAVITY,
    L_IDLE,
    L_MASS,
    L_MIN_CHECK,
    L_MOTOR_TABLE,
    L_RATE_MAX,
    L_RATE_TABLES,
    L_ROLL_TABLE,
    L_THROTTLE_TABLE,
    L_TILT,
    N_LIMITS,
    N_TABLE,
    program_sticks,
    stick_for_rate,
    throttle_for_collective,
    throttle_for_motor,
)

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
    "stick_for_rate",
    "throttle_for_collective",
    "throttle_for_motor",
]

_HOVER_WINDOW_M = 0.5  # height error within which the hover-throttle integral acts [m]
_HOVER_AUTHORITY = 0.35  # the largest collective the hover integral adds or takes away [fraction of g]


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
    rate_tables_rad_s: tuple[tuple[float, ...], ...] | None = None
    motor_table: tuple[float, ...] | None = None
    deadbands_us: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @classmethod
    def from_settings(cls, settings: BetaflightSettings, airframe: Airframe, mass_kg: float) -> StickMap:
        """The map for the firmware ``settings``.

        aerobat's own settings have linear rate curves, the same on every axis (rate = stick × full rate);
        a tune's curves of any ``rates_type`` (and a throttle curve that is not the identity) are sampled
        into tables that the pilot inverts (:func:`stick_for_rate`). A tune's stick deadband is stepped
        over: the tables are the curves of the deflection past it, so the smallest rate asked for reaches
        the firmware instead of vanishing in the deadband.
        """
        rates = {axis: settings.rate_deg_s(axis, 1.0 - 1e-9) for axis in ("roll", "pitch", "yaw")}
        tables = None
        if not settings.linear_rates() or len({round(r, 3) for r in rates.values()}) != 1:
            grid = np.linspace(0.0, 1.0, N_TABLE)
            tables = tuple(tuple(math.radians(settings.rate_deg_s(axis, float(x), deadband=False)) for x in grid)
                           for axis in ("roll", "pitch", "yaw"))
            for axis, table in zip(("roll", "pitch", "yaw"), tables, strict=True):
                if np.any(np.diff(table) < 0.0) or table[-1] <= 0.0:
                    raise ValueError(f"the {axis} rate curve does not rise with the stick")
        motor = None
        if not settings.linear_throttle():
            motor = tuple(settings.motor_for_throttle_us(1000.0 + 1000.0 * i / (N_TABLE - 1)) for i in range(N_TABLE))
        full = float(settings.value("roll_rc_rate")) * 10.0 if tables is None else math.degrees(tables[0][-1])
        return cls(
            rate_max_rad_s=math.radians(full),
            rate_limit_rad_s=math.radians(float(settings.value("roll_rate_limit"))),
            angle_limit_rad=math.radians(float(settings.value("angle_limit"))),
            idle=float(settings.value("motor_idle")) / 10000.0,
            min_check_us=float(settings.value("min_check")),
            mass_kg=mass_kg,
            airframe=airframe,
            rate_tables_rad_s=tables,
            motor_table=motor,
            deadbands_us=(settings.deadband_us("roll"), settings.deadband_us("pitch"), settings.deadband_us("yaw")),
        )

    def full_rates_deg_s(self) -> tuple[float, float, float]:
        """Body rate at full stick, roll, pitch, yaw [deg/s] (after the rate limit)."""
        if self.rate_tables_rad_s is None:
            top = math.degrees(min(self.rate_max_rad_s, self.rate_limit_rad_s))
            return (top, top, top)
        return tuple(math.degrees(t[-1]) for t in self.rate_tables_rad_s)  # type: ignore[return-value]

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
        if self.rate_tables_rad_s is not None:
            out[L_RATE_TABLES] = 1.0
            for axis, table in enumerate(self.rate_tables_rad_s):
                out[L_ROLL_TABLE + axis * N_TABLE:L_ROLL_TABLE + (axis + 1) * N_TABLE] = table
        if self.motor_table is not None:
            out[L_THROTTLE_TABLE] = 1.0
            out[L_MOTOR_TABLE:L_MOTOR_TABLE + N_TABLE] = self.motor_table
        out[L_DEADBAND:L_DEADBAND + 3] = self.deadbands_us
        out[L_BATTERY:L_BATTERY + 3] = self.airframe.battery_constants()
        return out


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
        if i < 2 and abs(err) < 0.15:
            integral[i] = min(max(integral[i] + err * dt, -0.5), 0.5)
        elif i == 2 and abs(err) < _HOVER_WINDOW_M and ki > 0.0:
            # the hover throttle: the pilot's model of mass and thrust may be off by tens of percent
            # (a battery, a worn prop); the integral may take up HOVER_AUTHORITY of g either way
            most = _HOVER_AUTHORITY * g / ki
            integral[i] = min(max(integral[i] + err * dt, -most), most)
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
    out[2] = stick_for_rate(-yaw_rate, 2, limits)
    out[3] = throttle_for_collective(collective, limits)
