"""What a robustness study varies on the Betaflight plant: the 5-inch racer's airframe and surroundings.

The firmware, its settings and the pilot's vehicle model (published mass and thrust curve) stay fixed.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from aerobat.plants.fpv.params import BetaflightParams, params_to_table
from aerobat.plants.sampling import RobustnessRanges, Sampling, body_draws, scaled_environment, uniform

__all__ = ["BETAFLIGHT_PROPERTIES", "SAMPLING", "sample_betaflight"]


BETAFLIGHT_PROPERTIES = (
    "mass_scale", "inertia_xx_scale", "inertia_yy_scale", "inertia_zz_scale", "drag_constant_scale",
    "motor_tau_scale", "thrust_gain_min", "com_offset_norm_m", "aerodynamics_scale", "noise_scale",
    "pilot_mass_scale",
)
"""What :func:`sample_betaflight` reports of each vehicle."""


def sample_betaflight(ranges: RobustnessRanges, seed: int,
                      base: BetaflightParams | None = None) -> tuple[dict[str, Any], dict[str, float]]:
    """One sampled 5-inch racer: (table for :class:`BetaflightParams`, the sampled properties).

    Varies the airframe (mass, inertia, κ, both motor time constants by one scale, per-motor
    thrust gains, centre-of-mass offset), the aerodynamics (drag and damping by one scale) and
    every noise (gyro, accelerometer, motion capture, wind, gusts, thrust jitter by one scale).
    Unchanged: the firmware and its settings, the thrust curve's shape, the rotor inertia, the
    radio. The pilot's model of the vehicle is off by ``pilot_mass_scale`` (the mass it believes).
    """
    rng = np.random.default_rng(seed)
    base = base or BetaflightParams()
    a = base.airframe
    body = body_draws(ranges, rng)
    ixx, iyy, izz = body.inertia_scale
    g = body.thrust_gains
    c = body.com_offset_xy_m
    props = {
        "mass_scale": uniform(rng, ranges.mass_scale),
        "inertia_xx_scale": ixx,
        "inertia_yy_scale": iyy,
        "inertia_zz_scale": izz,
        "drag_constant_scale": uniform(rng, ranges.drag_constant_scale),
        "motor_tau_scale": uniform(rng, ranges.motor_tau_scale),
        "thrust_gain_min": float(min(g)),
        "com_offset_norm_m": float(np.hypot(c[0], c[1])),
        "aerodynamics_scale": uniform(rng, ranges.aerodynamics_scale),
        "noise_scale": uniform(rng, ranges.noise_scale),
    }
    props["pilot_mass_scale"] = uniform(rng, ranges.pilot_mass_scale)
    aero, noise = props["aerodynamics_scale"], props["noise_scale"]
    s = base.sensors
    params = base.replace(
        airframe=dataclasses.replace(
            a, mass_kg=a.mass_kg * props["mass_scale"],
            inertia_kg_m2=(a.inertia_kg_m2[0] * ixx, a.inertia_kg_m2[1] * iyy, a.inertia_kg_m2[2] * izz),
            kappa_m=a.kappa_m * props["drag_constant_scale"],
            motor_tau_up_s=a.motor_tau_up_s * props["motor_tau_scale"],
            motor_tau_down_s=a.motor_tau_down_s * props["motor_tau_scale"],
            thrust_gains=(a.thrust_gains[0] * float(g[0]), a.thrust_gains[1] * float(g[1]),
                          a.thrust_gains[2] * float(g[2]), a.thrust_gains[3] * float(g[3])),
            com_offset_m=(float(c[0]), float(c[1]), a.com_offset_m[2])),
        **scaled_environment(base, aero, noise),
        sensors=dataclasses.replace(
            s, gyro_noise_rad_s=s.gyro_noise_rad_s * noise, accel_noise_m_s2=s.accel_noise_m_s2 * noise),
        pilot=dataclasses.replace(base.pilot, vehicle_mass_kg=base.pilot.vehicle_mass_kg * props["pilot_mass_scale"]),
    )
    return params_to_table(params), props


SAMPLING = Sampling(sample_betaflight, BETAFLIGHT_PROPERTIES)
"""The Betaflight plant's robustness sampling (:attr:`aerobat.plants.PlantSpec.robustness`)."""
