"""An X-frame airframe: the physical vehicle a flight controller flies, and its compiled pieces.

The rigid body is aerobat's (:mod:`aerobat.quadrotor.dynamics`); an X frame adds what a
firmware's mixer and its motors need: four rotors at (±x, ±y) in the firmware's QUADX motor
order with their spin directions, a steady-state thrust curve of the motor command, first-order
thrust dynamics, the rotors' own inertia (whose reaction torque acts on yaw), a centre-of-mass
offset, uneven motors and the delay from the firmware's output to the ESC.

Motor order (the Betaflight SITL's packet order, QUADX, props in), positions body FRD:

====  ========  ====================
slot  position  spin (seen from top)
====  ========  ====================
0     front-R   CCW
1     rear-L    CCW
2     front-L   CW
3     rear-R    CW
====  ========  ====================

The Betaflight plant flies an :class:`Airframe` as the world
(:mod:`aerobat.plants.betaflight.physics`); the firmware design model
(:mod:`aerobat.quadrotor.firmware`) flies one as the vehicle the user believes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numba as nb
import numpy as np

from aerobat.core.bounds import Interval, Items, bounded, validate
from aerobat.errors import ConfigError
from aerobat.quadrotor.dynamics import P_FMAX, P_FMIN, P_KYAW, P_MX, P_MY, P_RATE_DN, P_RATE_UP, plant_vector
from aerobat.quadrotor.vehicle import VehicleParams

__all__ = [
    "MOTOR_POSITIONS_FRD",
    "MOTOR_SPIN_CCW",
    "Airframe",
    "add_rotor_reaction",
    "battery_thrust_factor",
    "curve_command",
    "curve_thrust",
    "sagging_command",
    "xframe_plant",
]

MOTOR_POSITIONS_FRD: tuple[tuple[float, float], ...] = ((1.0, 1.0), (-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0))
"""Unit (x forward, y right) direction of each motor slot from the centre (QUADX, packet order)."""
MOTOR_SPIN_CCW: tuple[bool, ...] = (True, True, False, False)
"""Whether each motor slot's propeller spins counter-clockwise seen from above (props in)."""

_XYZ = "three numbers (x, y, z)"
_MASS = Interval(0.05, 20.0, unit="kg")


@dataclass(frozen=True, kw_only=True)
class Airframe:
    """The physical X-frame vehicle (defaults: the 5-inch racer of ``vehicles/fpv5.toml``).

    Attributes
    ----------
    mass_kg, inertia_kg_m2 : rigid body [kg], principal inertia (x, y, z) [kg m²].
    motor_x_m, motor_y_m : motor distance from the centre along body x (forward) and y [m];
        motors sit at (±x, ±y) in Betaflight's QUADX order.
    com_offset_m : centre of mass relative to the frame centre, body FLU [m].
    thrust_max_n : per-rotor thrust at motor command 1.
    curve_min_speed_ratio, curve_shape : the steady-state thrust curve
        ``f(u) = f_max [(1 − r) √(k u² + (1 − k) u) + r]²`` (r, k) for motor command u ∈ (0, 1];
        a stopped motor (u = 0, disarmed) gives no thrust.
    motor_tau_up_s, motor_tau_down_s : first-order thrust time constants, rising and falling [s].
    thrust_gains : per-motor thrust multipliers, Betaflight packet order (motor and prop spread).
    kappa_m : rotor drag-torque to thrust ratio [m].
    rotor_inertia_kg_m2 : inertia of one rotor (propeller and motor bell) about its axis; its
        reaction torque when the rotor speeds up or slows down acts on yaw.
    thrust_coefficient_n_s2 : k in f = k Ω² (relates thrust to rotor speed for that torque).
    output_delay_s : time from the firmware's motor output to the ESC acting on it [s]
        (DShot frame and ESC processing; lockstep computes the loop in zero time).
    props_out : the propellers turn the other way round from Betaflight's default (props in): every
        motor's drag torque reverses, and the firmware flies with ``yaw_motors_reversed = ON``.
    battery_reference_v : the battery voltage at which ``thrust_max_n`` holds [V] (an identified
        airframe: the fitted logs' median in flight); a log replay scales thrust by (V/this)² with the
        logged voltage V. None: the replayed log's own median in flight.
    battery_rest_v, battery_sag_v : the battery under load (identified from a log's voltage against its
        motor commands, :mod:`aerobat.quadrotor.identification.battery`): at motor commands u₁…u₄ the
        pack gives V = rest − sag · mean(uᵢ²) [V] and every rotor's thrust is × (V / battery_reference_v)²,
        so a punch to full throttle sags as the real pack does. Flown when ``battery_rest_v`` and
        ``battery_reference_v`` are both given (a log replay that follows the logged voltage uses that
        instead); None: thrust does not depend on the load.
    vibration_rms_rad_s, vibration_thrust_n : the frame's vibration in the gyro (identified from a log's
        unfiltered gyro, :mod:`aerobat.quadrotor.identification.vibration`): each rotor adds a line at its
        rotation frequency √(f / thrust_coefficient_n_s2) / 2π, whose amplitude grows with its thrust f (an
        imbalance's force grows with Ω²); with every rotor at ``vibration_thrust_n`` [N] the four lines
        together have rms ``vibration_rms_rad_s`` per body axis (roll, pitch, yaw) [rad/s]. Roll and yaw
        follow the sine of each rotor's angle, pitch its cosine. A thrust of 0 (the default): no vibration.
    """

    mass_kg: float = bounded(0.752, _MASS)
    inertia_kg_m2: tuple[float, float, float] = bounded(
        (2.5e-3, 2.1e-3, 4.3e-3), Items.each(Interval(1e-6, 10.0, unit="kg m²"), 3, _XYZ))
    motor_x_m: float = bounded(0.075, Interval(0.01, 2.0, unit="m"))
    motor_y_m: float = bounded(0.10, Interval(0.01, 2.0, unit="m"))
    com_offset_m: tuple[float, float, float] = bounded(
        (0.003, -0.002, 0.0), Items.each(Interval(-0.05, 0.05, unit="m"), 3, _XYZ))
    thrust_max_n: float = bounded(8.5, Interval(0.1, 1000.0, unit="N"))
    curve_min_speed_ratio: float = bounded(341.75 / 3100.0, Interval(0.0, 0.9))
    curve_shape: float = bounded(0.5, Interval(0.0, 1.0))
    motor_tau_up_s: float = bounded(0.033, Interval(1e-3, 1.0, unit="s"))
    motor_tau_down_s: float = bounded(0.033, Interval(1e-3, 1.0, unit="s"))
    thrust_gains: tuple[float, float, float, float] = bounded(
        (1.00, 0.98, 1.01, 0.97), Items.each(Interval(0.5, 1.5), 4, "four numbers (motors 1-4)"))
    kappa_m: float = bounded(0.022, Interval(1e-4, 0.5, unit="m"))
    rotor_inertia_kg_m2: float = bounded(8e-6, Interval(0.0, 1e-2, unit="kg m²"))
    thrust_coefficient_n_s2: float = bounded(1.562522e-6, Interval(1e-9, 1e-2, unit="N s²"))
    output_delay_s: float = bounded(125e-6, Interval(0.0, 0.05, unit="s"))
    props_out: bool = False
    battery_reference_v: float | None = bounded(None, Interval(1.0, 100.0, unit="V"))
    battery_rest_v: float | None = bounded(None, Interval(1.0, 100.0, unit="V"))
    battery_sag_v: float = bounded(0.0, Interval(0.0, 50.0, unit="V"))
    vibration_rms_rad_s: tuple[float, float, float] = bounded(
        (0.0, 0.0, 0.0), Items.each(Interval(0.0, 10.0, unit="rad/s"), 3, "three numbers (roll, pitch, yaw)"))
    vibration_thrust_n: float = bounded(0.0, Interval(0.0, 1000.0, unit="N"))

    def __post_init__(self) -> None:
        validate(self, skip=tuple(name for name in ("battery_reference_v", "battery_rest_v")
                                  if getattr(self, name) is None))
        if self.battery_rest_v is not None and self.battery_sag_v >= self.battery_rest_v:
            raise ConfigError(f"battery_sag_v = {self.battery_sag_v:g}: allowed [0, battery_rest_v = "
                              f"{self.battery_rest_v:g}) V (the pack would reach 0 V at full load)")
        if not isinstance(self.props_out, bool):
            raise ConfigError(f"props_out = {self.props_out!r}: expected true or false")

    @property
    def spins_ccw(self) -> tuple[bool, ...]:
        """Whether each motor slot's propeller turns counter-clockwise seen from above: :data:`MOTOR_SPIN_CCW`
        (props in), every one reversed with ``props_out``."""
        return tuple(not ccw for ccw in MOTOR_SPIN_CCW) if self.props_out else MOTOR_SPIN_CCW

    @property
    def battery_flown(self) -> bool:
        """Thrust follows the battery's sag under load (``battery_rest_v`` and ``battery_reference_v`` given)."""
        return self.battery_rest_v is not None and self.battery_reference_v is not None

    def battery_constants(self) -> tuple[float, float, float]:
        """(rest, sag, reference) [V] for :func:`battery_thrust_factor`; a reference of 0 turns it off."""
        if not self.battery_flown:
            return 0.0, 0.0, 0.0
        assert self.battery_rest_v is not None and self.battery_reference_v is not None
        return self.battery_rest_v, self.battery_sag_v, self.battery_reference_v

    @property
    def vibration_flown(self) -> bool:
        """The gyro carries the rotors' vibration lines (``vibration_thrust_n`` > 0 and some rms)."""
        return self.vibration_thrust_n > 0.0 and any(v > 0.0 for v in self.vibration_rms_rad_s)

    def vibration_constants(self) -> tuple[float, float, float, float]:
        """(roll, pitch, yaw amplitude of one rotor's line at the reference thrust [rad/s], that thrust [N]); a
        thrust of 0 turns it off. Four lines of amplitude a have rms a √2 together, so a = rms / √2."""
        if not self.vibration_flown:
            return 0.0, 0.0, 0.0, 0.0
        roll, pitch, yaw = (v / math.sqrt(2.0) for v in self.vibration_rms_rad_s)
        return roll, pitch, yaw, self.vibration_thrust_n

    def battery_factor(self, commands: Any) -> float:
        """Every rotor's thrust factor at motor ``commands`` (four, 0 … 1): (V/V_ref)², 1 without a battery."""
        rest, sag, ref = self.battery_constants()
        return float(battery_thrust_factor(np.asarray(commands, dtype=float), rest, sag, ref))

    def thrust_n(self, command: float) -> float:
        """Steady-state thrust of one rotor at motor command ``command`` (0 = stopped)."""
        if command <= 0.0:
            return 0.0
        u = min(command, 1.0)
        r, k = self.curve_min_speed_ratio, self.curve_shape
        return self.thrust_max_n * ((1.0 - r) * math.sqrt(k * u * u + (1.0 - k) * u) + r) ** 2

    def command_for_thrust(self, thrust_n: float) -> float:
        """Inverse of :meth:`thrust_n` on (0, 1] (clamped to the curve's range)."""
        r, k = self.curve_min_speed_ratio, self.curve_shape
        s = (math.sqrt(max(thrust_n, 0.0) / self.thrust_max_n) - r) / (1.0 - r)
        s = min(max(s, 0.0), 1.0)
        if k == 0.0:
            return s * s
        # k u² + (1 − k) u − s² = 0
        return min(((k - 1.0) + math.sqrt((1.0 - k) ** 2 + 4.0 * k * s * s)) / (2.0 * k), 1.0)


def xframe_plant(airframe: Airframe, *, thrust_gains: tuple[float, float, float, float] | None = None,
                 **terms: Any) -> np.ndarray:
    """The plant vector of :mod:`aerobat.quadrotor.dynamics` for ``airframe`` in the QUADX motor order.

    ``thrust_gains`` replace the airframe's (e.g. a trial's jitter); ``terms`` are
    :func:`~aerobat.quadrotor.dynamics.plant_vector`'s aerodynamic and wind keywords.
    """
    a = airframe
    carrier = VehicleParams(mass_kg=a.mass_kg, arm_length_m=math.hypot(a.motor_x_m, a.motor_y_m),
                            inertia_xx_kg_m2=a.inertia_kg_m2[0], inertia_yy_kg_m2=a.inertia_kg_m2[1],
                            inertia_zz_kg_m2=a.inertia_kg_m2[2], motor_rate_up_per_s=1.0 / a.motor_tau_up_s,
                            motor_rate_down_per_s=1.0 / a.motor_tau_down_s, rotor_thrust_min_n=0.0,
                            rotor_thrust_max_n=a.thrust_max_n, collective_reduced_min_m_s2=1.0,
                            collective_reduced_max_m_s2=20.0, drag_constant_m=a.kappa_m)
    plant = plant_vector(carrier, thrust_gains=thrust_gains or a.thrust_gains, **terms)
    for slot, ((fwd, right), ccw) in enumerate(zip(MOTOR_POSITIONS_FRD, a.spins_ccw, strict=True)):
        plant[P_MX + slot] = fwd * a.motor_x_m - a.com_offset_m[0]
        plant[P_MY + slot] = -right * a.motor_y_m - a.com_offset_m[1]  # FRD right = FLU −y
        plant[P_KYAW + slot] = -a.kappa_m if ccw else a.kappa_m
    plant[P_FMIN] = 0.0
    plant[P_FMAX] = a.thrust_max_n
    plant[P_RATE_UP] = 1.0 / a.motor_tau_up_s
    plant[P_RATE_DN] = 1.0 / a.motor_tau_down_s
    return plant


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def curve_thrust(u, thrust_max, r, k):  # pragma: no cover - compiled
    """Steady-state rotor thrust [N] at motor command ``u`` (0 or less: stopped), :meth:`Airframe.thrust_n`."""
    if u <= 0.0:
        return 0.0
    if u > 1.0:
        u = 1.0
    s = (1.0 - r) * math.sqrt(k * u * u + (1.0 - k) * u) + r
    return thrust_max * s * s


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def curve_command(thrust, thrust_max, r, k):  # pragma: no cover - compiled
    """The motor command whose steady thrust is ``thrust`` [N] (:func:`curve_thrust` inverted, clamped to [0, 1])."""
    s = (math.sqrt(thrust / thrust_max) - r) / (1.0 - r)
    s = min(max(s, 0.0), 1.0)
    if k > 0.0:
        return ((k - 1.0) + math.sqrt((1.0 - k) ** 2 + 4.0 * k * s * s)) / (2.0 * k)
    return s * s


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def sagging_command(thrust, thrust_max, r, k, rest_v, sag_v, reference_v):  # pragma: no cover - compiled
    """The command at which each of four equal rotors gives ``thrust`` [N] with the pack's sag at that load
    (:func:`battery_thrust_factor`; a reference of 0: no battery, :func:`curve_command`). A fixed point: the
    sag changes slowly with the command."""
    u = curve_command(thrust, thrust_max, r, k)
    if reference_v <= 0.0:
        return u
    for _ in range(30):
        load = min(u, 1.0)
        v = (rest_v - sag_v * load * load) / reference_v
        nxt = curve_command(thrust / max(v * v, 1e-6), thrust_max, r, k)
        if abs(nxt - u) < 1e-13:
            return nxt
        u = nxt
    return u


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def battery_thrust_factor(u, rest_v, sag_v, reference_v):  # pragma: no cover - compiled
    """Every rotor's thrust factor (V / ``reference_v``)² with V = ``rest_v`` − ``sag_v`` · mean(uᵢ²) for
    the four motor commands ``u`` (each clipped to [0, 1]); 1.0 when ``reference_v`` is 0 (no battery)."""
    if reference_v <= 0.0:
        return 1.0
    load = 0.0
    for j in range(4):
        c = min(max(u[j], 0.0), 1.0)
        load += c * c
    v = (rest_v - 0.25 * sag_v * load) / reference_v
    return v * v


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def add_rotor_reaction(x, dx, rotor_inertia, thrust_coefficient, spins, izz):  # pragma: no cover - compiled
    """Add the rotors' reaction torque to the yaw acceleration ``dx[12]`` (``spins``: +1 counter-clockwise).

    Spinning a rotor up takes a torque J_r Ω̇ that the motor's stator puts on the body, the other
    way round (Ω = √(f/k), so Ω̇ = ḟ / (2 √(k f))). On a racer it acts faster than the drag moment
    κ f, which only follows once the rotor has sped up.
    """
    if rotor_inertia > 0.0:
        torque = 0.0
        for j in range(4):
            f = max(x[13 + j], 1e-3)
            torque -= spins[j] * rotor_inertia * dx[13 + j] / (2.0 * math.sqrt(thrust_coefficient * f))
        dx[12] += torque / izz
