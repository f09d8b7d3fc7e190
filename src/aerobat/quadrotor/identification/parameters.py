"""What an identification fits: the nominal model's identifiable parameters, and the vehicle they make.

Everything the design model does is decided by a few combinations of the vehicle's
constants and its onboard controller's, and only those can be measured from motion
capture. The fit works on them directly (:data:`PARAMETERS`):

=====================  ==========================================================================
collective gain k      physical collective per commanded collective, m_c/m (m_c: the mass the
                       controller inverts with); the hover command is g/k
collective limits      4 f_max/m and 4 f_min/m: what saturated motors give [m/s²]
motor rates            first-order thrust rates up and down [1/s]
rate-loop gain K       per body axis, how fast the rate loop closes [1/s]: P·I_c/I for roll and
                       pitch, P_r·(κ/κ_c)·(I_c,zz/I_zz) for yaw
rate-loop latency      per axis, the delay of the rate the loop acts on [s]
rate shortfall d       per axis, steady rate = command/(1 + d): damping (and a gyro scale error)
moments per thrust     roll and pitch moments per unit thrust at equal motor commands [m]: a
                       centre-of-mass offset plus the uneven motors' share
uneven motors          thrust differences between opposite motors and between the two yaw pairs
                       (the yaw moment per thrust comes from the last one); telling a motor
                       difference from a centre-of-mass offset rests on small couplings, so
                       their split is far less certain than their sum
drag                   in-plane and axial rotor drag ∝ thrust [s/m], quadratic body drag [N s²/m²]
=====================  ==========================================================================

:func:`config_from_parameters` turns them into a :class:`~aerobat.quadrotor.vehicle.VehicleConfig`
around a *prior* (the vehicle the user believed in, whose onboard controller is kept as it is):
m = m_c/k, f = a·m/4, I_xx = I_c,xx·P_p/K_p, I_yy likewise. Two things cannot be told apart
from the outside and are split by an assumption, said again wherever they are reported:
I_zz and κ act only through their ratio (the yaw gain), so I_zz is scaled like the mean of
I_xx and I_yy and κ takes the rest; and the reduced envelope β̲, β̄ keeps the prior's margins
as fractions of the identified thrust span (Table 1's are 13.9 % and 10.1 %).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aerobat.errors import ConfigError
from aerobat.quadrotor.vehicle import ControllerParams, ModelEffects, VehicleConfig, VehicleParams

__all__ = [
    "AXES",
    "PARAMETERS",
    "ParameterInfo",
    "config_from_parameters",
    "envelope_margins",
    "hover_command_m_s2",
    "parameter_index",
    "parameters_from_config",
]

AXES = ("p", "q", "r")


@dataclass(frozen=True, kw_only=True)
class ParameterInfo:
    """One identified parameter.

    Attributes
    ----------
    name : identifier (``collective_gain``, ``rate_gain_p`` …).
    symbol : short symbol for tables.
    unit : its unit.
    description : what it is.
    lower, upper : what the fit allows.
    scale : a typical change (the least-squares variable scale).
    relative : the scale is relative to the prior value (a multiplier), not absolute.
    """

    name: str
    symbol: str
    unit: str
    description: str
    lower: float
    upper: float
    scale: float
    relative: bool = False


def _axis(name: str, symbol: str, unit: str, description: str, lower: float, upper: float, scale: float,
          relative: bool = False) -> tuple[ParameterInfo, ...]:
    return tuple(ParameterInfo(name=f"{name}_{a}", symbol=f"{symbol}_{a}", unit=unit,
                               description=f"{description} ({label})", lower=lower, upper=upper, scale=scale,
                               relative=relative)
                 for a, label in zip(AXES, ("roll", "pitch", "yaw"), strict=True))


PARAMETERS: tuple[ParameterInfo, ...] = (
    ParameterInfo(name="collective_gain", symbol="k", unit="-", lower=0.2, upper=5.0, scale=0.02,
                  description="physical collective per commanded collective (m_c/m)"),
    ParameterInfo(name="collective_max", symbol="a_max", unit="m/s²", lower=1.0, upper=300.0, scale=0.05,
                  relative=True, description="mass-normalized collective with every motor at f_max, 4 f_max/m"),
    ParameterInfo(name="collective_min", symbol="a_min", unit="m/s²", lower=0.0, upper=9.0, scale=0.1,
                  description="mass-normalized collective with every motor at f_min, 4 f_min/m"),
    ParameterInfo(name="motor_rate_up", symbol="P_up", unit="1/s", lower=1.0, upper=500.0, scale=0.1,
                  relative=True, description="first-order motor rate when thrust rises"),
    ParameterInfo(name="motor_rate_down", symbol="P_dn", unit="1/s", lower=1.0, upper=500.0, scale=0.1,
                  relative=True, description="first-order motor rate when thrust falls"),
    *_axis("rate_gain", "K", "1/s", "rate-loop gain", 0.5, 1e4, 0.1, relative=True),
    *_axis("rate_latency", "L", "s", "rate-loop latency", 0.0, 0.05, 0.002),
    *_axis("rate_shortfall", "d", "-", "steady rate shortfall, rate = command/(1 + d)", -0.2, 1.0, 0.01),
    ParameterInfo(name="moment_arm_p", symbol="A_p", unit="m", lower=-0.1, upper=0.1, scale=0.002,
                  description="roll moment per thrust at equal motor commands (centre of mass and uneven motors)"),
    ParameterInfo(name="moment_arm_q", symbol="A_q", unit="m", lower=-0.1, upper=0.1, scale=0.002,
                  description="pitch moment per thrust at equal motor commands (centre of mass and uneven motors)"),
    ParameterInfo(name="rotor_drag", symbol="k_rd", unit="s/m", lower=0.0, upper=1.0, scale=0.01,
                  description="in-plane rotor drag per thrust"),
    ParameterInfo(name="rotor_drag_axial", symbol="k_ra", unit="s/m", lower=0.0, upper=1.0, scale=0.01,
                  description="axial rotor drag per thrust"),
    ParameterInfo(name="body_drag", symbol="c_b", unit="N s²/m²", lower=0.0, upper=1.0, scale=0.005,
                  description="quadratic body drag"),
    ParameterInfo(name="motor_gain_roll", symbol="δ_p", unit="-", lower=-0.3, upper=0.3, scale=0.005,
                  description="uneven motors, (g₂ − g₄)/2: motor 2 (+y) against motor 4 (−y)"),
    ParameterInfo(name="motor_gain_pitch", symbol="δ_q", unit="-", lower=-0.3, upper=0.3, scale=0.005,
                  description="uneven motors, (g₁ − g₃)/2: motor 1 (+x) against motor 3 (−x)"),
    ParameterInfo(name="motor_gain_yaw", symbol="δ_r", unit="-", lower=-0.3, upper=0.3, scale=0.005,
                  description="uneven motors, (g₁ + g₃ − g₂ − g₄)/4: the +κ pair against the −κ pair"),
)
"""The fitted parameters, in the order of the parameter vector."""

_INDEX = {p.name: k for k, p in enumerate(PARAMETERS)}


def parameter_index(name: str) -> int:
    """Position of parameter ``name`` in the parameter vector."""
    try:
        return _INDEX[name]
    except KeyError:
        raise ConfigError(f"unknown identified parameter {name!r}; known: {', '.join(_INDEX)}") from None


def _gains(controller: ControllerParams) -> np.ndarray:
    gains = np.array([controller.rate_gain_p_per_s, controller.rate_gain_q_per_s, controller.rate_gain_r_per_s])
    if np.any(gains <= 0.0):
        raise ConfigError(f"controller rate gains {gains.tolist()} 1/s: identification needs a rate loop on every "
                          f"axis (P_p, P_q, P_r > 0)")
    return gains


def envelope_margins(vehicle: VehicleParams) -> tuple[float, float]:
    """(lower, upper) margins of the reduced envelope as fractions of the absolute thrust span.

    β̲ = a_min + lower·span and β̄ = a_max − upper·span; Table 1 gives (0.139, 0.101).
    """
    a_min, a_max = vehicle.collective_min_m_s2, vehicle.collective_max_m_s2
    span = a_max - a_min
    return ((vehicle.collective_reduced_min_m_s2 - a_min) / span, (a_max - vehicle.collective_reduced_max_m_s2) / span)


def parameters_from_config(config: VehicleConfig) -> np.ndarray:
    """The parameter vector of ``config`` (inverse of :func:`config_from_parameters` up to its assumptions)."""
    v, c, e = config.vehicle, config.controller, config.effects
    gains = _gains(c)
    inertia = np.array([v.inertia_xx_kg_m2, v.inertia_yy_kg_m2, v.inertia_zz_kg_m2])
    inertia_c = np.array([c.inertia_xx_kg_m2, c.inertia_yy_kg_m2, c.inertia_zz_kg_m2])
    loop = gains * inertia_c / inertia
    loop[2] *= v.drag_constant_m / c.drag_constant_m
    shortfall = np.array(e.rate_damping_n_m_s) / (inertia * loop)
    roll, pitch, yaw = _gain_differences(e.motor_thrust_gains)
    half_arm = 0.5 * v.arm_length_m
    return np.array([
        c.mass_kg / v.mass_kg, v.collective_max_m_s2, v.collective_min_m_s2,
        v.motor_rate_up_per_s, v.motor_rate_down_per_s, *loop, *e.rate_latency_s, *shortfall,
        e.thrust_moment_arm_m[0] + half_arm * roll, e.thrust_moment_arm_m[1] - half_arm * pitch,
        e.rotor_drag_s_m, e.rotor_drag_axial_s_m, e.body_drag_n_s2_m2, roll, pitch, yaw,
    ])


def _gain_differences(gains: tuple[float, float, float, float]) -> tuple[float, float, float]:
    g = np.asarray(gains, dtype=float) / np.mean(gains)
    return 0.5 * (g[1] - g[3]), 0.5 * (g[0] - g[2]), 0.25 * (g[0] + g[2] - g[1] - g[3])


def _gains_from_differences(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    return (1.0 + pitch + yaw, 1.0 + roll - yaw, 1.0 - pitch + yaw, 1.0 - roll - yaw)


def config_from_parameters(theta: np.ndarray, prior: VehicleConfig, *, name: str = "identified",
                           margins: tuple[float, float] | None = None) -> VehicleConfig:
    """The vehicle ``theta`` describes, around ``prior`` (whose controller, arm length and gravity are kept).

    Raises :class:`ConfigError` if ``theta`` makes no flyable vehicle (e.g. a thrust envelope
    without hover inside it).
    """
    theta = np.asarray(theta, dtype=float)
    if theta.shape != (len(PARAMETERS),) or not np.all(np.isfinite(theta)):
        raise ConfigError(f"identified parameters: expected {len(PARAMETERS)} finite values, got {theta!r}")
    v, c = prior.vehicle, prior.controller
    gains = _gains(c)
    k, a_max, a_min, rate_up, rate_dn = theta[0:5]
    loop, latency, shortfall = theta[5:8], theta[8:11], theta[11:14]
    # the moments per thrust include the uneven motors' share; the centre-of-mass arm is the rest
    arm = (float(theta[14] - 0.5 * v.arm_length_m * theta[19]), float(theta[15] + 0.5 * v.arm_length_m * theta[20]),
           prior.effects.thrust_moment_arm_m[2])
    rotor_drag, rotor_drag_axial, body_drag = theta[16:19]
    motor_gains = _gains_from_differences(*theta[19:22])
    mass = c.mass_kg / k
    inertia_c = np.array([c.inertia_xx_kg_m2, c.inertia_yy_kg_m2, c.inertia_zz_kg_m2])
    ixx, iyy = inertia_c[:2] * gains[:2] / loop[:2]
    izz = inertia_c[2] * 0.5 * (ixx / inertia_c[0] + iyy / inertia_c[1])  # the split assumption
    kappa = c.drag_constant_m * (loop[2] / gains[2]) * (izz / inertia_c[2])
    lower, upper = margins if margins is not None else envelope_margins(v)
    a_min = max(float(a_min), 0.0)
    span = a_max - a_min
    inertia = np.array([ixx, iyy, izz])
    damping = shortfall * inertia * loop
    vehicle = VehicleParams(
        mass_kg=float(mass), arm_length_m=v.arm_length_m,
        inertia_xx_kg_m2=float(ixx), inertia_yy_kg_m2=float(iyy), inertia_zz_kg_m2=float(izz),
        motor_rate_up_per_s=float(rate_up), motor_rate_down_per_s=float(rate_dn),
        rotor_thrust_min_n=float(a_min * mass / 4.0), rotor_thrust_max_n=float(a_max * mass / 4.0),
        collective_reduced_min_m_s2=float(a_min + lower * span),
        collective_reduced_max_m_s2=float(a_max - upper * span),
        drag_constant_m=float(kappa), gravity_m_s2=v.gravity_m_s2,
    )
    effects = ModelEffects(
        rate_latency_s=_triple(np.maximum(latency, 0.0)), rate_damping_n_m_s=_triple(damping),
        thrust_moment_arm_m=arm, motor_thrust_gains=motor_gains, rotor_drag_s_m=float(max(rotor_drag, 0.0)),
        rotor_drag_axial_s_m=float(max(rotor_drag_axial, 0.0)), body_drag_n_s2_m2=float(max(body_drag, 0.0)),
    )
    return VehicleConfig(vehicle=vehicle, controller=c, name=name, effects=effects)


def _triple(values: np.ndarray) -> tuple[float, float, float]:
    return float(values[0]), float(values[1]), float(values[2])


def hover_command_m_s2(theta: np.ndarray, gravity_m_s2: float) -> float:
    """The collective command that hovers, g/k [m/s²]."""
    return gravity_m_s2 / float(theta[0]) if theta[0] > 0 else math.inf
