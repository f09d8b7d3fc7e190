"""Stage 1: direct transcription (RK4, free final time) solved with CasADi/IPOPT from several starts."""

from __future__ import annotations

import functools
import math
import signal
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from aerobat.quadrotor.timeoptimal.solution import BenchmarkLimits, StageFailure

_COARSE_INTERVALS = 30


def run_solver(solver: Any, **kwargs: Any) -> Any:
    """``solver(**kwargs)``, where Ctrl-C (and SIGTERM, when its handler raises) stops the program.

    CasADi checks for signals during an IPOPT solve, but turns the resulting KeyboardInterrupt
    into a failed solve (``NonIpopt_Exception_Thrown``): the benchmark would go on and report a
    failure. Here the interrupt is noted as it happens and raised again once IPOPT returns.
    """
    if threading.current_thread() is not threading.main_thread():
        return solver(**kwargs)
    previous: dict[int, Any] = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        current = signal.getsignal(signum)
        if callable(current):
            previous[signum] = current
    if not previous:
        return solver(**kwargs)
    interrupted: list[BaseException] = []

    def handler(signum: int, frame: Any) -> None:
        try:
            previous[signum](signum, frame)
        except KeyboardInterrupt as exc:
            interrupted.append(exc)
            raise

    for number in previous:
        signal.signal(number, handler)
    try:
        result = solver(**kwargs)
    finally:
        for number, old in previous.items():
            signal.signal(number, old)
    if interrupted:
        raise interrupted[0]
    return result


@functools.lru_cache(maxsize=16)
def transcription_solver(intervals: int, limits_key: tuple[float, ...], max_iter: int) -> Any:
    """Build (and cache) the IPOPT solver of the RK4 transcription.

    Decision vector: ``[T, X (5 x (N+1), node-major), U (2 x N, interval-major)]``.
    Boundary conditions and input bounds are imposed as variable bounds so
    the same solver serves every target.
    """
    import casadi as ca

    g = limits_key[3]
    n = intervals
    x = ca.SX.sym("x", 5)
    u = ca.SX.sym("u", 2)
    h = ca.SX.sym("h")

    def rhs(xx: Any, uu: Any) -> Any:
        return ca.vertcat(xx[2], xx[3], uu[0] * ca.sin(xx[4]), uu[0] * ca.cos(xx[4]) - g, uu[1])

    k1 = rhs(x, u)
    k2 = rhs(x + h / 2 * k1, u)
    k3 = rhs(x + h / 2 * k2, u)
    k4 = rhs(x + h * k3, u)
    step = ca.Function("rk4", [x, u, h], [x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)])
    t_final = ca.SX.sym("T")
    xs = ca.SX.sym("X", 5, n + 1)
    us = ca.SX.sym("U", 2, n)
    defects = step.map(n)(xs[:, :n], us, t_final / n) - xs[:, 1:]
    w = ca.vertcat(t_final, ca.vec(xs), ca.vec(us))
    nlp = {"x": w, "f": t_final, "g": ca.vec(defects)}
    opts: dict[str, Any] = {
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "print_time": False,
        "ipopt.tol": 1e-10,
        "ipopt.max_iter": int(max_iter),
    }
    return ca.nlpsol(f"tto_{n}", "ipopt", nlp, opts)


def _pack_bounds(
    n: int, target: tuple[float, float], final_angle: float, lim: BenchmarkLimits
) -> tuple[np.ndarray, np.ndarray]:
    nx = 1 + 5 * (n + 1) + 2 * n
    lbx = np.full(nx, -np.inf)
    ubx = np.full(nx, np.inf)
    lbx[0], ubx[0] = 1e-3, 1e3
    xl = np.full((n + 1, 5), -np.inf)
    xu = np.full((n + 1, 5), np.inf)
    xl[0] = xu[0] = 0.0
    xl[-1] = xu[-1] = [target[0], target[1], 0.0, 0.0, final_angle]
    lbx[1 : 1 + 5 * (n + 1)] = xl.ravel()
    ubx[1 : 1 + 5 * (n + 1)] = xu.ravel()
    lbx[1 + 5 * (n + 1) :] = np.tile([lim.f_min_m_s2, -lim.max_rate_rad_s], n)
    ubx[1 + 5 * (n + 1) :] = np.tile([lim.f_max_m_s2, lim.max_rate_rad_s], n)
    return lbx, ubx


def _theta_guesses(final_angle: float) -> list[Callable[[np.ndarray], np.ndarray]]:
    """Attitude profiles used as multi-start guesses (functions of s in [0, 1])."""
    pi = math.pi

    def make(base: Callable[[np.ndarray], np.ndarray], amp: float, harmonic: int):
        return lambda s: base(s) + amp * pi * np.sin(harmonic * pi * s)

    def lin(s: np.ndarray) -> np.ndarray:
        return final_angle * s

    def smooth(s: np.ndarray) -> np.ndarray:
        return final_angle * (3 * s**2 - 2 * s**3)

    if final_angle == 0.0:
        # theta == 0 is a stationary point for vertical moves but rarely the
        # optimum; tilted/flipping guesses find the better basins.
        specs = [(0.25, 1), (-0.25, 1), (0.75, 1), (-0.75, 1), (1.0, 1), (-1.0, 1), (0.5, 2), (-0.5, 2)]
        return [make(lin, a, k) for a, k in specs]
    out = [make(lin, a, 1) for a in (0.0, 0.25, -0.25, 0.75, -0.75)]
    out += [make(smooth, a, 2) for a in (0.0, 0.25, -0.25, 0.5, -0.5)]
    return out


def _initial_point(
    n: int,
    target: tuple[float, float],
    final_angle: float,
    theta_fn: Callable[[np.ndarray], np.ndarray],
    lim: BenchmarkLimits,
) -> np.ndarray:
    dist = math.hypot(*target)
    t_guess = (
        2.0 * math.sqrt(dist / (lim.f_max_m_s2 - lim.gravity_m_s2)) + 0.5 * abs(final_angle) / lim.max_rate_rad_s + 0.3
    )
    s = np.linspace(0.0, 1.0, n + 1)
    prof = 3 * s**2 - 2 * s**3
    dprof = 6 * s * (1 - s) / t_guess
    xs = np.zeros((n + 1, 5))
    xs[:, 0] = target[0] * prof
    xs[:, 1] = target[1] * prof
    xs[:, 2] = target[0] * dprof
    xs[:, 3] = target[1] * dprof
    xs[:, 4] = theta_fn(s)
    xs[0, 4], xs[-1, 4] = 0.0, final_angle
    us = np.zeros((n, 2))
    us[:, 0] = np.clip(lim.gravity_m_s2, lim.f_min_m_s2, lim.f_max_m_s2)
    us[:, 1] = np.clip(np.diff(xs[:, 4]) / (t_guess / n), -lim.max_rate_rad_s, lim.max_rate_rad_s)
    return np.concatenate([[t_guess], xs.ravel(), us.ravel()])


def _run_transcription(
    n: int,
    w0: np.ndarray,
    target: tuple[float, float],
    final_angle: float,
    lim: BenchmarkLimits,
    max_iter: int,
) -> tuple[bool, str, float, np.ndarray, np.ndarray, np.ndarray]:
    solver = transcription_solver(n, lim._key(), max_iter)
    lbx, ubx = _pack_bounds(n, target, final_angle, lim)
    w0 = np.clip(w0, lbx, ubx)
    try:
        res = run_solver(solver, x0=w0, lbx=lbx, ubx=ubx, lbg=0.0, ubg=0.0)
    except RuntimeError as exc:  # pragma: no cover - CasADi evaluation errors
        return False, f"IPOPT raised {exc}", math.nan, np.empty((0, 5)), np.empty((0, 2)), np.empty((0, 5))
    stats = solver.stats()
    w = np.asarray(res["x"], dtype=float).ravel()
    xs = w[1 : 1 + 5 * (n + 1)].reshape(n + 1, 5)
    us = w[1 + 5 * (n + 1) :].reshape(n, 2)
    # defect multipliers: discrete adjoint at the end of each interval
    lam = np.asarray(res["lam_g"], dtype=float).ravel().reshape(n, 5)
    return bool(stats["success"]), str(stats["return_status"]), float(w[0]), xs, us, lam


def _resample(w: np.ndarray, n_from: int, n_to: int) -> np.ndarray:
    t_final = w[0]
    xs = w[1 : 1 + 5 * (n_from + 1)].reshape(n_from + 1, 5)
    us = w[1 + 5 * (n_from + 1) :].reshape(n_from, 2)
    s_from = np.linspace(0.0, 1.0, n_from + 1)
    s_to = np.linspace(0.0, 1.0, n_to + 1)
    xs_to = np.column_stack([np.interp(s_to, s_from, xs[:, i]) for i in range(5)])
    mid = (np.arange(n_to) + 0.5) / n_to
    idx = np.minimum((mid * n_from).astype(int), n_from - 1)
    return np.concatenate([[t_final], xs_to.ravel(), us[idx].ravel()])


def best_transcription(
    target: tuple[float, float],
    final_angle: float,
    lim: BenchmarkLimits,
    intervals: int,
    max_iter: int,
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Multi-start coarse solves, then the best basin(s) on the fine grid.

    Returns ``T``, node states ``(N+1, 5)``, interval inputs ``(N, 2)`` and the
    defect multipliers ``(N, 5)`` of the best fine solution.
    """
    n_coarse = min(_COARSE_INTERVALS, intervals)
    coarse: list[tuple[float, np.ndarray]] = []
    statuses: list[str] = []
    for theta_fn in _theta_guesses(final_angle):
        w0 = _initial_point(n_coarse, target, final_angle, theta_fn, lim)
        ok, status, t_final, xs, us, _ = _run_transcription(n_coarse, w0, target, final_angle, lim, max_iter)
        statuses.append(status)
        if ok:
            coarse.append((t_final, np.concatenate([[t_final], xs.ravel(), us.ravel()])))
    if coarse:
        coarse.sort(key=lambda c: c[0])
        starts = [coarse[0]]
        for cand in coarse[1:]:
            if cand[0] <= coarse[0][0] * 1.01 and all(abs(cand[0] - s[0]) > 1e-3 for s in starts):
                starts.append(cand)
            if len(starts) == 2:
                break
        inits = [_resample(w, n_coarse, intervals) for _, w in starts]
    else:
        inits = [_initial_point(intervals, target, final_angle, _theta_guesses(final_angle)[0], lim)]
    best: tuple[float, np.ndarray, np.ndarray, np.ndarray] | None = None
    fine_status = []
    for w0 in inits:
        ok, status, t_final, xs, us, lam = _run_transcription(intervals, w0, target, final_angle, lim, max_iter)
        fine_status.append(status)
        if ok and (best is None or t_final < best[0]):
            best = (t_final, xs, us, lam)
    if best is None:
        raise StageFailure(
            "direct transcription did not converge (IPOPT status: "
            f"coarse {sorted(set(statuses))}, fine {sorted(set(fine_status))})"
        )
    return best[0], best[1], best[2], best[3]
