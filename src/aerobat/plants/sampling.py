"""What a robustness study samples, shared by the plants that can be sampled (:attr:`PlantSpec.robustness`).

A plant's package says how one sampled vehicle of it is drawn (:class:`Sampling`: a function of the
:class:`RobustnessRanges` and a seed, and the properties it reports); the study
(:mod:`aerobat.experiments.studies.robustness`) asks the plant's spec and names no plant. The feedback
study's scenarios are a plant's too (:class:`Scenario`, :attr:`PlantSpec.scenarios`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from aerobat.core.bounds import Interval, Span, bounded, validate

__all__ = ["DEFAULT_SCENARIO", "BodyDraws", "RobustnessRanges", "Sampling", "Scenario", "body_draws",
           "scaled_environment", "uniform"]


_RANGE = Span(Interval(low=0.0))
"""A uniform range (low, high) with 0 <= low <= high."""
_SPREAD = Interval(0.0, 0.5)
"""A "± x" spread, relative or in metres, in [0, 0.5]."""


@dataclass(frozen=True, kw_only=True)
class RobustnessRanges:
    """Uniform ranges from which each sampled vehicle's arena is drawn.

    Scales multiply the plant's defaults (``docs/plants.md``); "± x" ranges are
    relative (0.05 = ±5 %). Units in field names. ``motor_rate_*`` are the arena's absolute
    motor rates; the Betaflight airframe scales its motor time constants by ``motor_tau_scale``
    instead (and the arena ignores it).
    """

    mass_scale: tuple[float, float] = bounded((0.98, 1.08), _RANGE)
    inertia_scale: tuple[float, float] = bounded((1.00, 1.25), _RANGE)
    inertia_zz_scale: tuple[float, float] = bounded((1.05, 1.35), _RANGE)
    drag_constant_scale: tuple[float, float] = bounded((1.00, 1.30), _RANGE)
    motor_rate_up_per_s: tuple[float, float] = bounded((62.0, 80.0), _RANGE)
    motor_rate_down_per_s: tuple[float, float] = bounded((40.0, 55.0), _RANGE)
    thrust_gain_spread: float = bounded(0.04, _SPREAD)
    com_offset_m: float = bounded(0.006, _SPREAD)
    aerodynamics_scale: tuple[float, float] = bounded((0.7, 1.3), _RANGE)
    noise_scale: tuple[float, float] = bounded((0.7, 1.3), _RANGE)
    motor_tau_scale: tuple[float, float] = bounded((0.85, 1.25), _RANGE)
    pilot_mass_scale: tuple[float, float] = bounded((0.85, 1.15), _RANGE)
    """Betaflight only: the mass the offboard pilot believes, relative to the published one (issue 31 B1: its
    take-off, hover and return must hold with its model off by ±15 %); drawn after every other property."""

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class Sampling:
    """How a plant draws one vehicle for a robustness study.

    Attributes
    ----------
    sample : ``sample(ranges, seed, base) -> (settings table, properties)``: the sampled plant's stored
        settings (what :meth:`PlantSpec.settings_from_table` reads) and the sampled properties by name;
        ``base`` the settings sampled around (None: the plant's defaults). Deterministic in ``seed``.
    properties : the names ``sample`` reports, in the order the study's report lists them.
    """

    sample: Callable[[RobustnessRanges, int, Any], tuple[dict[str, Any], dict[str, float]]]
    properties: tuple[str, ...]


@dataclass(frozen=True)
class Scenario:
    """A named change to a plant's settings for the feedback study, and what it tests."""

    name: str
    summary: str
    change: Callable[[Any], Any]
    """``change(settings) -> settings`` (``settings`` the plant's, never None)."""


DEFAULT_SCENARIO = Scenario("default", "the plant's settings as given", lambda settings: settings)
"""The scenario every plant runs: its settings unchanged."""


def uniform(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    """One draw from the range ``bounds`` (low, high)."""
    return float(rng.uniform(bounds[0], bounds[1]))


@dataclass(frozen=True)
class BodyDraws:
    """What every sampled vehicle draws first, in this order: its inertia scales, per-motor thrust gains and
    centre-of-mass offset (so that a plant's samples stay what they were when its other draws change)."""

    inertia_scale: tuple[float, float, float]
    thrust_gains: tuple[float, float, float, float]
    com_offset_xy_m: tuple[float, float]


def body_draws(ranges: RobustnessRanges, rng: np.random.Generator) -> BodyDraws:
    """The :class:`BodyDraws` of one vehicle from ``rng``."""
    inertia = (uniform(rng, ranges.inertia_scale), uniform(rng, ranges.inertia_scale),
               uniform(rng, ranges.inertia_zz_scale))
    g = 1.0 + ranges.thrust_gain_spread * rng.uniform(-1, 1, 4)
    c = ranges.com_offset_m * rng.uniform(-1, 1, 2)
    return BodyDraws(inertia, (float(g[0]), float(g[1]), float(g[2]), float(g[3])), (float(c[0]), float(c[1])))


def scaled_environment(base: Any, aero: float, noise: float) -> dict[str, Any]:
    """The aerodynamics, disturbance and motion-capture sections of ``base`` (arena or Betaflight
    settings) with their coefficients scaled by ``aero`` and their noise levels by ``noise``."""
    a, d, mc = base.aerodynamics, base.disturbances, base.motion_capture
    return {
        "aerodynamics": dataclasses.replace(
            a, body_drag_n_s2_m2=a.body_drag_n_s2_m2 * aero, rotor_drag_s_m=a.rotor_drag_s_m * aero,
            rotational_damping_n_m_s=(a.rotational_damping_n_m_s[0] * aero, a.rotational_damping_n_m_s[1] * aero,
                                      a.rotational_damping_n_m_s[2] * aero)),
        "disturbances": dataclasses.replace(
            d, wind_std_m_s=d.wind_std_m_s * noise, gust_amplitude_std_m_s=d.gust_amplitude_std_m_s * noise,
            thrust_gain_jitter=d.thrust_gain_jitter * noise, motor_gain_jitter=d.motor_gain_jitter * noise),
        "motion_capture": dataclasses.replace(
            mc, position_noise_m=mc.position_noise_m * noise, attitude_noise_rad=mc.attitude_noise_rad * noise),
    }
