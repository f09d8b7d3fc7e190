"""How much each axis of a flight log says about the vehicle, and what identification does when it says too little.

A log identifies an axis's inertia from how the gyro answers the motors' differential on that axis. A
flight with little motion on an axis (the ROMA F5's first flight has 6.8 °/s rms of pitch in the
1–20 Hz band against 12.2 of roll) fits that axis to whatever else moves its gyro, and the fitted
value can be far off with a small jackknife spread: the spread measures how the blocks agree, not
whether the axis was flown. :func:`axis_excitation` measures each axis's motion (the gyro's rms in
:data:`~aerobat.quadrotor.log_analysis.BAND_HZ`, up to a crash at a log's end);
:func:`with_prior_for_poorly_excited_axes` replaces the inertia of a roll or pitch axis under
:data:`EXCITATION_MIN_DEG_S` by the other, well excited axis's inertia times the prior's ratio of the
two, widens its uncertainty to :data:`PRIOR_RELATIVE_SIGMA`, keeps I_zz and κ consistent with it, and
says so.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from aerobat.quadrotor.flightlog import Channel, FlightLog
from aerobat.quadrotor.log_analysis import BAND_HZ, band_pass, find_crash

__all__ = ["EXCITATION_MIN_DEG_S", "PRIOR_RELATIVE_SIGMA", "AxisExcitation", "axis_excitation",
           "with_prior_for_poorly_excited_axes"]

EXCITATION_MIN_DEG_S = 10.0
"""An axis whose gyro moves less than this in the band [°/s rms] is poorly excited."""
PRIOR_RELATIVE_SIGMA = 0.3
"""The 1-σ uncertainty given to an inertia taken from the prior's ratio, relative to it."""
_AXES = ("roll", "pitch", "yaw")
_INERTIA = ("inertia_xx_kg_m2", "inertia_yy_kg_m2")


@dataclass(frozen=True)
class AxisExcitation:
    """Each axis's motion in the logs fitted: the gyro's rms in the band [°/s], roll, pitch, yaw."""

    rms_deg_s: tuple[float, float, float]

    def poorly_excited(self) -> tuple[str, ...]:
        """The axes under :data:`EXCITATION_MIN_DEG_S`."""
        return tuple(a for a, v in zip(_AXES, self.rms_deg_s, strict=True) if v < EXCITATION_MIN_DEG_S)

    def text(self) -> str:
        return ", ".join(f"{a} {v:.1f}" for a, v in zip(_AXES, self.rms_deg_s, strict=True))


def axis_excitation(logs: Sequence[FlightLog]) -> AxisExcitation:
    """The gyro's rms per axis in :data:`~aerobat.quadrotor.log_analysis.BAND_HZ` over ``logs``, each up to a crash
    at its end (:func:`aerobat.plotting.flightlog.log_crash`'s rule), weighted by samples."""
    total = np.zeros(3)
    count = 0
    for log in logs:
        if not log.has(Channel.GYRO):
            continue
        g = log.signals[Channel.GYRO]
        rates = np.degrees(g.values)
        acc = log.signals[Channel.SPECIFIC_FORCE] if log.has(Channel.SPECIFIC_FORCE) else None
        crash = find_crash(g.time_s, rates, None if acc is None else acc.values, None if acc is None else acc.time_s)
        keep = g.time_s < crash.time_s if crash is not None else np.ones(g.samples, dtype=bool)
        if keep.sum() < 16:
            continue
        dt = float(np.median(np.diff(g.time_s)))
        for k in range(3):
            x = rates[keep, k]
            x = np.where(np.isfinite(x), x, 0.0)
            total[k] += float(np.sum(band_pass(x, dt, BAND_HZ) ** 2))
        count += int(keep.sum())
    rms = np.sqrt(total / count) if count else np.full(3, math.nan)
    return AxisExcitation(tuple(float(v) for v in rms))  # type: ignore[arg-type]


def with_prior_for_poorly_excited_axes(fit: Any, excitation: AxisExcitation, prior: Any) -> tuple[Any, list[str]]:
    """``fit`` (a :class:`~aerobat.quadrotor.identification.logfit.LogFit`) with the inertia of a poorly excited roll
    or pitch axis taken from the other axis and ``prior``'s ratio, and the notes that say so (none if nothing changed).

    Only when exactly one of roll and pitch is poorly excited: with both, there is no axis to scale from
    and the notes say the fit stands unchecked. I_zz (the assumed ratio of I_xx + I_yy) and κ (its fitted
    ratio to I_zz) follow the new inertia.
    """
    poor = [a for a in excitation.poorly_excited() if a in ("roll", "pitch")]
    where = f"1–20 Hz gyro rms {excitation.text()} °/s, below {EXCITATION_MIN_DEG_S:g} is poorly excited"
    if not poor:
        return fit, []
    if len(poor) == 2:
        return fit, [f"roll and pitch are both poorly excited ({where}): their inertias are the fit's, unchecked"]
    k = _AXES.index(poor[0])
    other = 1 - k
    v = prior.vehicle
    prior_inertia = (v.inertia_xx_kg_m2, v.inertia_yy_kg_m2)
    ratio = prior_inertia[k] / prior_inertia[other]
    values = dict(fit.values)
    fitted, sigma, unit = values[_INERTIA[k]]
    new = values[_INERTIA[other]][0] * ratio
    values[_INERTIA[k]] = (new, PRIOR_RELATIVE_SIGMA * new, unit)
    inertia = [values["inertia_xx_kg_m2"][0], values["inertia_yy_kg_m2"][0]]
    widened = f"± {100 * PRIOR_RELATIVE_SIGMA:.0f} %"
    notes = [f"{poor[0]} is poorly excited ({where}): {_INERTIA[k]} = {new:.4g} kg m² {widened} from "
             f"{_INERTIA[other]} × {prior.name}'s ratio {ratio:.3g}, not the fit's {fitted:.4g} ± {sigma:.2g}"]
    if "inertia_zz_kg_m2" in values:
        izz_old, izz_sigma, izz_unit = values["inertia_zz_kg_m2"]
        izz = fit.geometry.inertia_zz_ratio * (inertia[0] + inertia[1])
        values["inertia_zz_kg_m2"] = (izz, izz_sigma * izz / izz_old if izz_old else izz_sigma, izz_unit)
        if "kappa_m" in values and "kappa_over_izz_1_kg_m" in values:
            kappa_over, _, _ = values["kappa_over_izz_1_kg_m"]
            kappa_old, kappa_sigma, kappa_unit = values["kappa_m"]
            values["kappa_m"] = (kappa_over * izz, kappa_sigma * izz / izz_old if izz_old else kappa_sigma,
                                 kappa_unit)
        notes.append(f"inertia_zz_kg_m2 and kappa_m follow it: I_zz {izz_old:.4g} → {izz:.4g} kg m²")
    return dataclasses.replace(fit, values=values, notes=(*fit.notes, *notes)), notes
