"""Body rates estimated from a measured attitude: what motion capture tells of p, q, r.

Motion capture measures the attitude, not the body rates; a plant that measures no rates (the
arena) stores them as NaN. :func:`body_rates_from_attitude` estimates them from consecutive
attitudes: between two samples the attitude turns by Δq = q_k* ⊗ q_{k+1} (a body-frame rotation, as
the quaternions are body → world), whose rotation vector over the interval is the mean body rate
there; each sample gets the mean of its two intervals (the ends, their one). The estimate lags
nothing and is exact for a constant rate; it averages a varying one over a sample period, so it is
labelled *estimated* wherever it is shown.
"""

from __future__ import annotations

import numpy as np

from aerobat.config import as_float_array

__all__ = ["body_rates_from_attitude"]


def body_rates_from_attitude(times_s: np.ndarray, quaternions: np.ndarray) -> np.ndarray:
    """(N, 3) body rates p, q, r [rad/s] estimated from N attitudes (w, x, y, z; body → world) at ``times_s``.

    Fewer than two samples, or a sample time that does not increase, give NaN there.
    """
    t = np.asarray(times_s, dtype=float)
    q = as_float_array("quaternions", quaternions, (t.size, 4))
    out = np.full((t.size, 3), np.nan)
    if t.size < 2:
        return out
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    a, b = q[:-1], q[1:]
    # Δq = conj(a) ⊗ b, the turn from one sample to the next in the body frame
    w = a[:, 0] * b[:, 0] + np.sum(a[:, 1:] * b[:, 1:], axis=1)
    v = (a[:, :1] * b[:, 1:] - b[:, :1] * a[:, 1:] - np.cross(a[:, 1:], b[:, 1:]))
    flip = w < 0.0  # q and −q are one attitude: the shortest way round
    w = np.where(flip, -w, w)
    v = np.where(flip[:, None], -v, v)
    s = np.linalg.norm(v, axis=1)
    angle = 2.0 * np.arctan2(s, w)
    axis_scale = np.divide(angle, s, out=np.full_like(s, 2.0), where=s > 1e-12)  # small turns: 2·v
    dt = np.diff(t)
    with np.errstate(divide="ignore", invalid="ignore"):
        interval = np.where((dt > 0.0)[:, None], v * axis_scale[:, None] / dt[:, None], np.nan)
    out[0] = interval[0]
    out[-1] = interval[-1]
    out[1:-1] = 0.5 * (interval[:-1] + interval[1:])
    return out
