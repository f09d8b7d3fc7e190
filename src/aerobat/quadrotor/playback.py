"""Compiled playback of programs: the numba kernels behind :mod:`aerobat.quadrotor.simulate`.

* :func:`run_continuous` — continuous mode (the design model): RK4 steps that land on every
  breakpoint, the program evaluated exactly at every stage, the controller acting on the
  body rates (or, with rate-loop latency, on the rates ``delay`` ago, interpolated in a
  history of the steps: :func:`run_continuous_lagged`, the same loop). It plays the rows of a
  packed batch, one after the other.
* :func:`run_sampled` — the onboard command generator: program and controller sampled every
  tick, motor commands held between ticks.
* :func:`rk4_plant_step` — one RK4 step of the plant with the motor commands held (the
  arena's vehicle runs on it); :func:`rk4_after_first_stage`, its last three stages for any
  derivative (the Betaflight plant's physics takes it too).

Everything they call is ``inline="always"``, one level deep, so each is compiled as one unit
(its results do not depend on numba's cache) and compiles in seconds. They allocate nothing
inside their loops.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from aerobat.quadrotor.dynamics import (
    N_STATE,
    controller_constants,
    derivative,
    normalize_quaternion,
    plant_constants,
    thrust_commands,
)

__all__ = ["rk4_after_first_stage", "rk4_plant_step", "run_continuous", "run_continuous_lagged", "run_sampled"]


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _command(poly, tau, cmd):  # pragma: no cover - compiled
    """The commands at local time ``tau`` of a segment with coefficients ``poly`` (4 × 3) into ``cmd``."""
    for ch in range(4):
        cmd[ch] = poly[ch, 0] + tau * (poly[ch, 1] + tau * poly[ch, 2])


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _delayed_rates(hist_t, hist_w, count, t, x, delay, out):  # pragma: no cover - compiled
    """Body rates ``delay`` seconds before ``t`` (per axis): from the history, or between its end and ``x`` at ``t``.

    An axis without latency (``delay`` 0) gets ``x``'s own rate, whatever the history."""
    for a in range(3):
        lag = delay[a]
        now = x[10 + a]
        if lag <= 0.0 or count == 0:
            out[a] = now
            continue
        s = t - lag
        last = hist_t[count - 1]
        if s >= last:
            span = t - last
            out[a] = now if span <= 0.0 else hist_w[count - 1, a] + (s - last) / span * (now - hist_w[count - 1, a])
        elif s <= hist_t[0]:
            out[a] = hist_w[0, a]
        else:
            j = count - 2
            while j > 0 and hist_t[j] > s:
                j -= 1
            w = (s - hist_t[j]) / (hist_t[j + 1] - hist_t[j])
            out[a] = hist_w[j, a] + w * (hist_w[j + 1, a] - hist_w[j, a])


@nb.njit(cache=True, fastmath=True, error_model="numpy", nogil=True)
def run_continuous(x0, bp, coeffs, nseg, plant, ctrl, delays, max_step, out, rows, rec_t, rec_x, rec_u,
                   lagged=None):  # pragma: no cover - compiled
    """Continuous-time playback of the batch rows ``rows``, one after the other.

    Row b: start state ``x0[b]``, final state into ``out[b]``. With non-empty ``rec_*`` (one
    program) every step is recorded; returns the number of records. Every continuous-mode
    simulation runs through this one compiled loop (``simulate``, and each thread's share of a
    batch), so they agree bit for bit whatever the batch. Everything it calls is inlined (a
    kernel that calls another compiled kernel ran ~8 % slower once numba loaded it from its
    cache), one level deep (nested inlining multiplied the compile time).

    ``lagged``: left out, the rows have no rate-loop latency and ``delays`` is not read;
    :func:`run_continuous_lagged` passes the constant True, and the controller acts on the body
    rates ``delays[b]`` [s] per axis before each stage's time, interpolated in the history of the
    integration steps (the rate at the start before that; the history is allocated once, for the
    longest row). numba compiles one version for each and drops the other's branches as it
    compiles: it drops a branch on ``x is None`` when ``x`` is None, left out with the default
    None, or a literal constant, not when it is a bool or an array. With the history's branches
    in its stages the loop without latency ran 4× slower.
    """
    n = N_STATE
    work = np.empty((6, n))  # the state and the four stages side by side
    xs = work[0]
    k1 = work[1]
    k2 = work[2]
    k3 = work[3]
    k4 = work[4]
    tmp = work[5]
    cmds = np.empty((3, 4))
    cmd0 = cmds[0]
    cmdm = cmds[1]
    cmd1 = cmds[2]
    poly = np.empty((4, 3))  # the current segment's coefficients
    rates = np.empty(3)
    longest = 0  # integration steps of the longest row (lagged: its history)
    for b in rows:
        if lagged is not None:
            breaks = bp[b]
            steps = 0
            for seg in range(nseg[b]):
                steps += max(1, int(math.ceil((breaks[seg + 1] - breaks[seg]) / max_step - 1e-9)))
            longest = max(longest, steps)
    hist_t = np.empty(longest + 1)
    hist_w = np.empty((longest + 1, 3))
    record = rec_t.shape[0] > 0
    idx = 0
    for b in rows:
        pl = plant[b]
        ct = ctrl[b]
        breaks = bp[b]
        cf = coeffs[b]
        pc = plant_constants(pl)
        cc = controller_constants(ct)
        for j in range(n):
            xs[j] = x0[b, j]
        hist_t[0] = breaks[0]
        hist_w[0, 0] = xs[10]
        hist_w[0, 1] = xs[11]
        hist_w[0, 2] = xs[12]
        count = 1
        if record:
            for ch in range(4):
                for power in range(3):
                    poly[ch, power] = cf[0, ch, power]
            _command(poly, 0.0, cmd0)
            rec_t[0] = breaks[0]
            rec_x[0, :] = xs
            rec_u[0, :] = cmd0
            idx = 1
        for seg in range(nseg[b]):
            t0 = breaks[seg]
            length = breaks[seg + 1] - t0
            m = max(1, int(math.ceil(length / max_step - 1e-9)))
            h = length / m
            for ch in range(4):
                for power in range(3):
                    poly[ch, power] = cf[seg, ch, power]
            _command(poly, 0.0, cmd1)
            for i in range(m):
                tau = i * h
                t = t0 + tau
                # the program at the step's start (the previous step's end), middle and end
                for ch in range(4):
                    cmd0[ch] = cmd1[ch]
                _command(poly, tau + 0.5 * h, cmdm)
                _command(poly, (i + 1) * h, cmd1)
                if lagged is None:
                    ft = thrust_commands(cmd0, xs[10], xs[11], xs[12], ct, cc)
                else:
                    _delayed_rates(hist_t, hist_w, count, t, xs, delays[b], rates)
                    ft = thrust_commands(cmd0, rates[0], rates[1], rates[2], ct, cc)
                derivative(t, xs, ft, pl, pc, k1)
                for j in range(n):
                    tmp[j] = xs[j] + 0.5 * h * k1[j]
                if lagged is None:
                    ft = thrust_commands(cmdm, tmp[10], tmp[11], tmp[12], ct, cc)
                else:
                    _delayed_rates(hist_t, hist_w, count, t + 0.5 * h, tmp, delays[b], rates)
                    ft = thrust_commands(cmdm, rates[0], rates[1], rates[2], ct, cc)
                derivative(t + 0.5 * h, tmp, ft, pl, pc, k2)
                for j in range(n):
                    tmp[j] = xs[j] + 0.5 * h * k2[j]
                if lagged is None:
                    ft = thrust_commands(cmdm, tmp[10], tmp[11], tmp[12], ct, cc)
                else:
                    _delayed_rates(hist_t, hist_w, count, t + 0.5 * h, tmp, delays[b], rates)
                    ft = thrust_commands(cmdm, rates[0], rates[1], rates[2], ct, cc)
                derivative(t + 0.5 * h, tmp, ft, pl, pc, k3)
                for j in range(n):
                    tmp[j] = xs[j] + h * k3[j]
                if lagged is None:
                    ft = thrust_commands(cmd1, tmp[10], tmp[11], tmp[12], ct, cc)
                else:
                    _delayed_rates(hist_t, hist_w, count, t + h, tmp, delays[b], rates)
                    ft = thrust_commands(cmd1, rates[0], rates[1], rates[2], ct, cc)
                derivative(t + h, tmp, ft, pl, pc, k4)
                for j in range(n):
                    xs[j] += h / 6.0 * (k1[j] + 2.0 * (k2[j] + k3[j]) + k4[j])
                normalize_quaternion(xs)
                t_end = t0 + (i + 1) * h if i + 1 < m else breaks[seg + 1]
                if lagged is not None:
                    hist_t[count] = t_end
                    hist_w[count, 0] = xs[10]
                    hist_w[count, 1] = xs[11]
                    hist_w[count, 2] = xs[12]
                    count += 1
                if record:
                    rec_t[idx] = t_end
                    rec_x[idx, :] = xs
                    rec_u[idx, :] = cmd1
                    idx += 1
        for j in range(n):
            out[b, j] = xs[j]
    return idx


@nb.njit(cache=True, fastmath=True, error_model="numpy", nogil=True)
def run_continuous_lagged(x0, bp, coeffs, nseg, plant, ctrl, delays, max_step, out, rows, rec_t, rec_x,
                          rec_u):  # pragma: no cover - compiled
    """:func:`run_continuous` for vehicles with rate-loop latency ``delays[b]`` [s] per axis."""
    return run_continuous(x0, bp, coeffs, nseg, plant, ctrl, delays, max_step, out, rows, rec_t, rec_x, rec_u, True)


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def rk4_after_first_stage(deriv, t, x, ft, plant, consts, h, k1, k2, k3, k4, tmp):  # pragma: no cover - compiled
    """The RK4 step from ``t`` by ``h`` of ``x`` with ``k1 = deriv(t, x)`` already taken, motor commands ``ft`` held.

    ``deriv(t, x, ft, plant, consts, dx)``: the plant's derivative (:func:`~.dynamics.derivative`,
    or a plant's own with its extra terms); ``consts`` is what it takes after the plant vector.
    The one RK4 step with held commands: :func:`rk4_plant_step` and the Betaflight plant's
    physics (which looks at ``k1`` first, for the floor) both take it.
    """
    n = N_STATE
    for j in range(n):
        tmp[j] = x[j] + 0.5 * h * k1[j]
    deriv(t + 0.5 * h, tmp, ft, plant, consts, k2)
    for j in range(n):
        tmp[j] = x[j] + 0.5 * h * k2[j]
    deriv(t + 0.5 * h, tmp, ft, plant, consts, k3)
    for j in range(n):
        tmp[j] = x[j] + h * k3[j]
    deriv(t + h, tmp, ft, plant, consts, k4)
    for j in range(n):
        x[j] += h / 6.0 * (k1[j] + 2.0 * (k2[j] + k3[j]) + k4[j])
    normalize_quaternion(x)


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def rk4_plant_step(t, x, ft, plant, pc, h, k1, k2, k3, k4, tmp):  # pragma: no cover - compiled
    """One RK4 step of the plant with motor commands ``ft`` held constant (``pc``: plant_constants)."""
    derivative(t, x, ft, plant, pc, k1)
    rk4_after_first_stage(derivative, t, x, ft, plant, pc, h, k1, k2, k3, k4, tmp)


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def run_sampled(x, bp, coeffs, nseg, plant, ctrl, tick, substeps, rec_t, rec_x, rec_u, delay):  # pragma: no cover
    """Onboard playback: sample the program and run the controller every ``tick``; ZOH between.

    With latency the controller acts on the rates ``delay`` ago, interpolated in the tick history.
    """
    delayed = delay[0] > 0.0 or delay[1] > 0.0 or delay[2] > 0.0
    ticks = int(math.ceil(bp[nseg] / tick - 1e-9)) + 2 if delayed else 0
    hist_t = np.empty(ticks)
    hist_w = np.empty((ticks, 3))
    count = 0
    rates = np.empty(3)
    n = N_STATE
    k1 = np.empty(n)
    k2 = np.empty(n)
    k3 = np.empty(n)
    k4 = np.empty(n)
    tmp = np.empty(n)
    cmd = np.empty(4)
    pc = plant_constants(plant)
    cc = controller_constants(ctrl)
    end = bp[nseg]
    record = rec_t.shape[0] > 0
    idx = 0
    seg = 0
    tick_index = 0
    t = 0.0
    while t < end - 1e-12:
        while seg < nseg - 1 and bp[seg + 1] <= t + 1e-12:
            seg += 1
        _command(coeffs[seg], t - bp[seg], cmd)
        if record:
            rec_t[idx] = t
            rec_x[idx, :] = x
            rec_u[idx, :] = cmd
            idx += 1
        if delayed:
            hist_t[count] = t
            hist_w[count, 0] = x[10]
            hist_w[count, 1] = x[11]
            hist_w[count, 2] = x[12]
            count += 1
            _delayed_rates(hist_t, hist_w, count, t, x, delay, rates)
            ft = thrust_commands(cmd, rates[0], rates[1], rates[2], ctrl, cc)  # held until the next tick
        else:
            ft = thrust_commands(cmd, x[10], x[11], x[12], ctrl, cc)
        t_next = min((tick_index + 1) * tick, end)
        h = (t_next - t) / substeps
        for s in range(substeps):
            rk4_plant_step(t + s * h, x, ft, plant, pc, h, k1, k2, k3, k4, tmp)
        tick_index += 1
        t = t_next
    if record:
        rec_t[idx] = end
        rec_x[idx, :] = x
        rec_u[idx, :] = cmd
        idx += 1
    return idx
