"""A radio frame's random draws, taken when the steps need them or while the firmware works.

A frame of ``n`` gyro steps draws, from the flight's generator and in this order: the sensor
noise (``n`` rows of 6 standard normals, when the sensors are noisy), then the motion-capture
noise (``n // every + 2`` rows: 3 position values, then the same rows' 3 attitude values, each
scaled, when nonzero). :func:`begin_draws` lays the frame's draws out in ``st`` and draws nothing;
:func:`draw_noise` takes them in that order up to a count. The values do not depend on when they
are drawn, only on the order, so a step loop draws what the next step needs just in time and
the rest while it waits for the firmware's answer (:mod:`.lockstep`, over shared memory): ~200 draws of ~12 ns
each at the frame's start had kept the firmware waiting long enough to fall asleep once a frame
(docs/performance.md, issue 27). Over UDP the frame draws everything at its start, as before.
"""

from __future__ import annotations

import numba as nb

from aerobat.plants.fpv.frames import (
    K_EVERY,
    K_SENSOR_NOISE,
    Q_ATTITUDE_NOISE_RAD,
    Q_POSITION_NOISE_M,
    S_DRAW_STEPS,
    S_DRAW_TOTAL,
    S_DRAWN,
)

__all__ = ["ALL", "begin_draws", "draw_noise", "sensor_draws_through"]

ALL = 1 << 62
"""A count beyond any frame's draws: :func:`draw_noise` up to it takes the frame's remaining draws."""


@nb.njit(cache=True, error_model="numpy")
def begin_draws(n, cfg, fcfg, st, mocap_noise):  # pragma: no cover - compiled
    """Lay out the draws of a frame of ``n`` steps (none taken yet); zero the frame's motion-capture noise rows."""
    rows = n // cfg[K_EVERY] + 2
    mocap_noise[:rows, :] = 0.0
    total = 6 * n if cfg[K_SENSOR_NOISE] else 0
    if fcfg[Q_POSITION_NOISE_M] != 0.0:
        total += 3 * rows
    if fcfg[Q_ATTITUDE_NOISE_RAD] != 0.0:
        total += 3 * rows
    st[S_DRAWN] = 0
    st[S_DRAW_TOTAL] = total
    st[S_DRAW_STEPS] = n


@nb.njit(cache=True, inline="always")
def sensor_draws_through(i):  # pragma: no cover - compiled
    """The draws to take before step ``i``'s physics (its sensor noise row, and every row before it)."""
    return 6 * (i + 1)


@nb.njit(cache=True, error_model="numpy")
def draw_noise(upto, rng, cfg, fcfg, st, noise, mocap_noise):  # pragma: no cover - compiled
    """Take the frame's draws from ``st[S_DRAWN]`` up to ``upto`` (at most all of them), in their order."""
    k = st[S_DRAWN]
    total = st[S_DRAW_TOTAL]
    stop = min(upto, total)
    if k >= stop:
        return
    sensor = 6 * st[S_DRAW_STEPS] if cfg[K_SENSOR_NOISE] else 0
    rows = st[S_DRAW_STEPS] // cfg[K_EVERY] + 2
    position = 3 * rows if fcfg[Q_POSITION_NOISE_M] != 0.0 else 0
    while k < stop:
        if k < sensor:
            noise[k // 6, k % 6] = rng.standard_normal()
        elif k < sensor + position:
            j = k - sensor
            mocap_noise[j // 3, j % 3] = fcfg[Q_POSITION_NOISE_M] * rng.standard_normal()
        else:
            j = k - sensor - position
            mocap_noise[j // 3, 3 + j % 3] = fcfg[Q_ATTITUDE_NOISE_RAD] * rng.standard_normal()
        k += 1
    st[S_DRAWN] = k
