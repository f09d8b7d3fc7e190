"""What the studies vary on the arena: a sampled true vehicle (robustness) and the feedback study's scenarios."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from aerobat.config import dataclass_to_table
from aerobat.plants.arena.params import ArenaParams
from aerobat.plants.sampling import (
    DEFAULT_SCENARIO,
    RobustnessRanges,
    Sampling,
    Scenario,
    body_draws,
    scaled_environment,
    uniform,
)

__all__ = ["ARENA_PROPERTIES", "SAMPLING", "SCENARIOS", "sample_arena"]

ARENA_PROPERTIES = (
    "mass_scale", "inertia_xx_scale", "inertia_yy_scale", "inertia_zz_scale", "drag_constant_scale",
    "motor_rate_up_per_s", "motor_rate_down_per_s", "thrust_gain_min", "com_offset_norm_m",
    "aerodynamics_scale", "noise_scale",
)
"""What :func:`sample_arena` reports of each vehicle."""


def sample_arena(ranges: RobustnessRanges, seed: int,
                 base: ArenaParams | None = None) -> tuple[dict[str, Any], dict[str, float]]:
    """One sampled vehicle: (arena table for :class:`ArenaParams`, the sampled properties).

    ``base``: the settings sampled around (None: the defaults); the true vehicle's properties are drawn
    afresh, the aerodynamics and noise scaled from ``base``'s."""
    rng = np.random.default_rng(seed)
    base = base or ArenaParams()
    body = body_draws(ranges, rng)
    ixx, iyy, izz = body.inertia_scale
    gains = body.thrust_gains
    com = (*body.com_offset_xy_m, 0.0)
    aero = uniform(rng, ranges.aerodynamics_scale)
    noise = uniform(rng, ranges.noise_scale)
    props = {
        "mass_scale": uniform(rng, ranges.mass_scale),
        "inertia_xx_scale": ixx,
        "inertia_yy_scale": iyy,
        "inertia_zz_scale": izz,
        "drag_constant_scale": uniform(rng, ranges.drag_constant_scale),
        "motor_rate_up_per_s": uniform(rng, ranges.motor_rate_up_per_s),
        "motor_rate_down_per_s": uniform(rng, ranges.motor_rate_down_per_s),
        "thrust_gain_min": min(gains),
        "com_offset_norm_m": float(np.hypot(com[0], com[1])),
        "aerodynamics_scale": aero,
        "noise_scale": noise,
    }
    params = base.replace(
        true_vehicle=dataclasses.replace(
            base.true_vehicle, mass_scale=props["mass_scale"], inertia_scale=(ixx, iyy, izz),
            drag_constant_scale=props["drag_constant_scale"], motor_rate_up_per_s=props["motor_rate_up_per_s"],
            motor_rate_down_per_s=props["motor_rate_down_per_s"], thrust_gains=gains, com_offset_m=com),
        **scaled_environment(base, aero, noise),
    )
    return dataclass_to_table(params), props


SAMPLING = Sampling(sample_arena, ARENA_PROPERTIES)
"""The arena's robustness sampling (:attr:`aerobat.plants.PlantSpec.robustness`)."""


def _gyro_x5(p: ArenaParams) -> ArenaParams:
    o = p.onboard
    return dataclasses.replace(p, onboard=dataclasses.replace(
        o, gyro_scale_error=(5.0 * o.gyro_scale_error[0], 5.0 * o.gyro_scale_error[1], 5.0 * o.gyro_scale_error[2]),
        gyro_bias_rad_s=(5.0 * o.gyro_bias_rad_s[0], 5.0 * o.gyro_bias_rad_s[1], 5.0 * o.gyro_bias_rad_s[2])))


def _lossy(p: ArenaParams) -> ArenaParams:
    return dataclasses.replace(p, links=dataclasses.replace(p.links, command_drop_probability=0.3))


def _slow(p: ArenaParams) -> ArenaParams:
    return dataclasses.replace(p, links=dataclasses.replace(p.links, command_rate_hz=30.0, command_latency_s=0.03))


SCENARIOS: tuple[Scenario, ...] = (
    dataclasses.replace(DEFAULT_SCENARIO, summary="the default arena"),
    Scenario("gyro-x5", "gyro scale errors and biases 5× the default: the estimator integrates a bad gyro", _gyro_x5),
    Scenario("lossy-link", "30 % of command packets lost, and the relayed estimates with them", _lossy),
    Scenario("slow-link", "a 30 Hz radio with 30 ms latency (default 70 Hz, 10 ms): relayed estimates arrive "
                          "late and seldom", _slow),
)
"""The arena's scenarios for the feedback study: each changes the arena so that a feedback's assumptions fail."""
