"""The battery under load, from a log's voltage against its motor commands (issue 42).

A pack's voltage falls while the motors draw current and recovers when they idle; over a flight it
also drains. The model fitted here is the simplest that the logs support:

    V(t) = rest − drain · (t − t_mid) − sag · mean(uᵢ(t)²)

with uᵢ ∈ [0, 1] the four motor commands. mean(u²) stands for the current (thrust, and so roughly
current, grows with the square of the command); on the ROMA F5's flight 1 it explains the voltage
better than mean(u) or mean(u^1.5), and a lag between load and voltage only made the fit worse
(``scripts/results_battery.py`` measures both), so the sag is instantaneous.
Each log has its own rest voltage and drain (a log starts where the last one left the pack); the
sag is common to all. ``rest`` is the resting voltage at each log's median flying time, so at the
load a flight typically carries, rest − sag · load is close to the median voltage in flight (the
airframe's ``battery_reference_v``), where the identified thrust holds.

The airframe flies it as :func:`aerobat.quadrotor.xframe.battery_thrust_factor`: every rotor's thrust
× ((rest − sag · mean(u²)) / reference)². Only numpy here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["BatteryFit", "fit_battery"]

_MIN_SAMPLES = 50


@dataclass(frozen=True)
class BatteryFit:
    """The pack's resting voltage, its sag under full load and how well that explains the logged voltage.

    Attributes
    ----------
    rest_v : the resting (no-load) voltage at the logs' median flying time [V], weighted by their flying samples.
    sag_v : the voltage lost at full load, every motor at command 1 [V] (mean(u²) = 1).
    drain_v_per_s : how fast the resting voltage fell in flight [V/s], weighted as ``rest_v``.
    rms_v : the rms of the logged voltage about the fit [V].
    r_squared : the fraction of the logged voltage's variance the fit explains.
    samples : flying samples fitted.
    load_median : the median mean(u²) of those samples (a flight's typical load).
    """

    rest_v: float
    sag_v: float
    drain_v_per_s: float
    rms_v: float
    r_squared: float
    samples: int
    load_median: float

    def describe(self) -> str:
        """One line a person reads."""
        return (f"battery: rest {self.rest_v:.2f} V, sag {self.sag_v:.2f} V at full load (thrust × "
                f"{((self.rest_v - self.sag_v) / self.rest_v) ** 2:.2f} there against no load), drain "
                f"{self.drain_v_per_s * 60:.2f} V/min; explains {self.r_squared:.0%} of the logged voltage's "
                f"variance (rms {self.rms_v:.2f} V, {self.samples} flying samples)")


def fit_battery(series: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]], *,
                flying_command: float = 0.15) -> BatteryFit | None:
    """Fit the pack to logs given as (time [s] (n,), voltage [V] (n,), motor commands (n, 4) in [0, 1]) each.

    Samples count when flying (mean command above ``flying_command``) with a finite, positive voltage.
    None when fewer than 50 such samples, or no load variation to tell the sag from the rest.
    """
    blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    for t, v, u in series:
        t = np.asarray(t, dtype=float)
        v = np.asarray(v, dtype=float)
        u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
        ok = np.isfinite(v) & (v > 0.0) & np.all(np.isfinite(u), axis=1) & (u.mean(axis=1) > flying_command)
        if np.count_nonzero(ok) < _MIN_SAMPLES:
            continue
        tt = t[ok]
        blocks.append((tt - np.median(tt), v[ok], (u[ok] ** 2).mean(axis=1)))
    if not blocks:
        return None
    n_logs = len(blocks)
    rows = sum(b[1].size for b in blocks)
    design = np.zeros((rows, 2 * n_logs + 1))
    volts = np.empty(rows)
    at = 0
    for i, (dt, v, load) in enumerate(blocks):
        design[at:at + v.size, i] = 1.0
        design[at:at + v.size, n_logs + i] = -dt
        design[at:at + v.size, -1] = -load
        volts[at:at + v.size] = v
        at += v.size
    if np.ptp(design[:, -1]) < 1e-3:
        return None
    coef, *_ = np.linalg.lstsq(design, volts, rcond=None)
    residual = volts - design @ coef
    weights = np.array([b[1].size for b in blocks], dtype=float)
    variance = float(np.var(volts))
    return BatteryFit(rest_v=float(np.average(coef[:n_logs], weights=weights)), sag_v=float(coef[-1]),
                      drain_v_per_s=float(np.average(coef[n_logs:2 * n_logs], weights=weights)),
                      rms_v=float(np.sqrt(np.mean(residual ** 2))),
                      r_squared=float(1.0 - np.var(residual) / variance) if variance > 0 else 0.0,
                      samples=rows, load_median=float(np.median(np.concatenate([b[2] for b in blocks]))))
