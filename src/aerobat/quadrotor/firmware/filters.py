"""The flight controller's digital filters as compiled, allocation-free kernels.

Betaflight's filters (``common/filter.c``): first-, second- and third-order lowpasses built from
cascaded first-order sections (PT1, PT2, PT3, their cutoffs corrected so each is −3 dB at the
cutoff), the biquad lowpass (Butterworth, direct form I where the cutoff moves, II where it does
not) and the biquad notch. One filter lives in :data:`SIZE` consecutive slots of a state vector:
its five coefficients, then four memory slots (so a cutoff that moves in flight stays with the
filter). Arithmetic in float64 (the firmware's is float32: the two differ by parts in 10⁷).
"""

from __future__ import annotations

import math

import numba as nb

__all__ = [
    "BIQUAD_DF1",
    "BIQUAD_DF2",
    "NONE",
    "NOTCH",
    "PT1",
    "PT2",
    "PT3",
    "SIZE",
    "apply",
    "notch_q",
    "pt_gain",
    "reset",
    "set_lowpass",
    "set_notch",
]

NONE = 0
PT1 = 1
PT2 = 2
PT3 = 3
BIQUAD_DF1 = 4  # a biquad lowpass whose cutoff may move (Betaflight's dynamic lowpasses)
BIQUAD_DF2 = 5  # a fixed biquad lowpass
NOTCH = 6  # a fixed biquad notch (direct form II)
SIZE = 9  # coefficients b0, b1, b2, a1, a2 (a PT's gain in the first), then four memory slots
_MEMORY = 5
_PT2_CORRECTION = 1.553773974
_PT3_CORRECTION = 1.961459177
_BIQUAD_Q = 1.0 / math.sqrt(2.0)


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def pt_gain(cutoff_hz, dt_s, order):  # pragma: no cover - compiled
    """The gain of one section of an ``order``-th order PT lowpass at ``cutoff_hz`` sampled every ``dt_s``."""
    if order == 2:
        cutoff_hz *= _PT2_CORRECTION
    elif order == 3:
        cutoff_hz *= _PT3_CORRECTION
    omega = 2.0 * math.pi * cutoff_hz * dt_s
    return omega / (omega + 1.0)


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _biquad(state, o, frequency_hz, dt_s, q, notch):  # pragma: no cover - compiled
    omega = 2.0 * math.pi * frequency_hz * dt_s
    sn = math.sin(omega)
    cs = math.cos(omega)
    alpha = sn / (2.0 * q)
    if notch:
        b0 = 1.0
        b1 = -2.0 * cs
        b2 = 1.0
    else:
        b1 = 1.0 - cs
        b0 = b1 * 0.5
        b2 = b0
    a1 = -2.0 * cs
    a2 = 1.0 - alpha
    a0 = 1.0 + alpha
    state[o] = b0 / a0
    state[o + 1] = b1 / a0
    state[o + 2] = b2 / a0
    state[o + 3] = a1 / a0
    state[o + 4] = a2 / a0


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def set_lowpass(kind, state, o, cutoff_hz, dt_s):  # pragma: no cover - compiled
    """Set (or move) the cutoff of the lowpass at ``state[o:o + SIZE]``; its memory is kept."""
    if kind == PT1 or kind == PT2 or kind == PT3:
        state[o] = pt_gain(cutoff_hz, dt_s, kind)
    elif kind == BIQUAD_DF1 or kind == BIQUAD_DF2:
        _biquad(state, o, cutoff_hz, dt_s, _BIQUAD_Q, False)


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def notch_q(center_hz, cutoff_hz):  # pragma: no cover - compiled
    """Betaflight's notch Q from its centre and lower cutoff (``filterGetNotchQ``)."""
    return center_hz * cutoff_hz / (center_hz * center_hz - cutoff_hz * cutoff_hz)


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def set_notch(state, o, center_hz, cutoff_hz, dt_s):  # pragma: no cover - compiled
    """Set the notch at ``state[o:o + SIZE]``."""
    _biquad(state, o, center_hz, dt_s, notch_q(center_hz, cutoff_hz), True)


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def reset(state, o, value, kind):  # pragma: no cover - compiled
    """The filter's memory as if it had seen ``value`` for ever (its steady state)."""
    m = o + _MEMORY
    if kind == BIQUAD_DF1:
        for i in range(4):
            state[m + i] = value
    elif kind == BIQUAD_DF2 or kind == NOTCH:
        # direct form II transposed at rest on a constant (both pass it with gain 1): x1 = (1 − b0)·v,
        # x2 = (b2 − a2)·v
        state[m] = (1.0 - state[o]) * value
        state[m + 1] = (state[o + 2] - state[o + 4]) * value
    else:
        for i in range(3):
            state[m + i] = value


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def apply(kind, state, o, x):  # pragma: no cover - compiled
    """Filter the sample ``x`` through the filter at ``state[o:o + SIZE]``; the output."""
    m = o + _MEMORY
    if kind == NONE:
        return x
    if kind == PT1 or kind == PT2 or kind == PT3:
        k = state[o]
        state[m] += k * (x - state[m])
        if kind == PT1:
            return state[m]
        state[m + 1] += k * (state[m] - state[m + 1])
        if kind == PT2:
            return state[m + 1]
        state[m + 2] += k * (state[m + 1] - state[m + 2])
        return state[m + 2]
    b0 = state[o]
    b1 = state[o + 1]
    b2 = state[o + 2]
    a1 = state[o + 3]
    a2 = state[o + 4]
    if kind == BIQUAD_DF1:  # memory: x1, x2, y1, y2
        y = b0 * x + b1 * state[m] + b2 * state[m + 1] - a1 * state[m + 2] - a2 * state[m + 3]
        state[m + 1] = state[m]
        state[m] = x
        state[m + 3] = state[m + 2]
        state[m + 2] = y
        return y
    y = b0 * x + state[m]  # direct form II transposed: memory x1, x2
    state[m] = b1 * x - a1 * y + state[m + 1]
    state[m + 1] = b2 * x - a2 * y
    return y
