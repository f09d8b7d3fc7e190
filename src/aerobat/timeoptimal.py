"""Time-optimal hover-to-hover motions of a planar quadrocopter.

This module reproduces the time-optimal benchmark of Ritz et al. (2011) and
Hehn, Ritz & D'Andrea (2012): a mass-normalised vehicle in the vertical
plane with state ``(y, z, vy, vz, theta)`` and dynamics

.. math::

    \\ddot y = f \\sin\\theta, \\qquad \\ddot z = f \\cos\\theta - g,
    \\qquad \\dot\\theta = \\omega,

with collective thrust ``f in [f_min, f_max]`` and body rate
``|omega| <= omega_max``, starts in hover at the origin and must reach hover
at ``(Y, Z)`` with attitude ``final_angle_rad`` in minimum time.

The solution proceeds in three stages:

1. **Structure.**  A direct transcription (piecewise-constant inputs, one
   classical Runge-Kutta step per interval, free final time) is solved with
   CasADi/IPOPT.  Coarse (30-interval) multi-starts with different attitude
   guesses select the basin of the best local optimum (for vertical moves
   ``theta == 0`` is only a stationary point; tilting/flipping is faster),
   which is then re-solved on the requested grid.
2. **Refinement.**  The arc structure of both inputs is read off the
   transcription (thrust: bang-bang; rate: bang-singular) and the arc
   durations are optimised directly (switching-time optimisation, IPOPT,
   tolerance 1e-13).  Pieces on which both inputs are constant are
   integrated in closed form.  On a singular rate arc Pontryagin's principle
   gives ``lambda_theta = 0`` and hence ``tan(theta) = lambda_vy / lambda_vz``
   with ``lambda_v`` affine in time: the attitude follows a *bilinear
   tangent law* along one costate line ``n(t) = (a + b t, c + d t)`` shared
   by all singular arcs.  Per arc this reads

   .. math::

       \\theta(t_a + s) = \\theta(t_a) + \\operatorname{atan2}(\\beta s, 1 + \\alpha s),

   whose rate ``beta / ((1 + alpha s)^2 + (beta s)^2)`` is in general *not*
   constant (it is below 0.03 rad/s for the (5, 5) benchmark but varies
   between -0.3 and -4 rad/s for the (5, 0) move).  The line ``(a, b, c, d)``
   is therefore a decision variable (initialised from the transcription's
   multipliers, i.e. its discrete adjoint); the translational integrals of
   singular pieces use composite Gauss-Legendre quadrature (4 x 32 nodes).
3. **Certification and repair.**  The multipliers of the final-state
   constraints are the adjoint ``lambda(T)``; propagating it backwards gives
   the switching functions, and the minimum principle is checked on every
   arc (thrust sign, rate sign, ``lambda_theta = 0`` on singular arcs).  If
   it is violated, the refinement is restarted from the multipliers' costate
   line and/or the arc that the needle variation asks for is inserted (a
   bang arc, or a short singular arc between opposite rate bangs) and the
   refinement repeated.

A result is ``'optimal'`` only if IPOPT converged, the refined program,
re-integrated independently with an adaptive high-order ODE solver, meets
the boundary conditions to 1e-6, the inputs respect their bounds, the
refined time does not exceed the transcription's and the minimum principle
holds to 1e-6 (typically 1e-12).  Otherwise a solution with
``status == 'failed'`` and an explanatory message is returned instead of a
plausible-looking wrong answer.
"""

from __future__ import annotations

import csv
import functools
import math
import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "BenchmarkLimits",
    "InputArc",
    "TimeOptimalSolution",
    "solve_translation",
    "switch_times",
    "benchmark_map",
    "write_map_csv",
    "plot_solution",
    "plot_map",
    "clear_caches",
]

_F_LOW_RAW = 3.92
_F_HIGH_RAW = 21.58
_MARGIN = 0.05

_BANG_TOL_REL = 1e-4  # interval counts as "at the bound" within this fraction of the range
_MIN_SINGULAR_INTERVALS = 3  # shorter non-bang runs are treated as switches inside an interval
_EDGE_DEVIATION = 0.3  # edge interval of a singular run deviating by this * omega_max hides a bang arc
_PRUNE_TOL_S = 1e-7  # arcs shorter than this are removed and the refinement re-solved
_REFINE_T_TOL_S = 1e-9  # refined T may exceed the transcription's T by at most this
_BOUNDARY_TOL = 1e-6
_PMP_TOL = 1e-6  # allowed violation of the minimum principle (adjoint scaled so lambda_0 = 1)
_MAX_STRUCTURE_TRIALS = 6
_COARSE_INTERVALS = 30
_GL_PANELS = 4  # composite Gauss-Legendre on singular pieces: worst-case error
_GL_NODES = 32  # ~1e-14 for admissible arcs up to 2 s (|omega| <= 10 rad/s)


# --------------------------------------------------------------------------
# data classes
# --------------------------------------------------------------------------
def _check_positive_finite(name: str, value: float) -> None:
    if not isinstance(value, (int, float, np.floating, np.integer)) or isinstance(value, bool):
        raise ValueError(f"{name} must be a real number, got {value!r}")
    if not math.isfinite(float(value)) or float(value) <= 0.0:
        raise ValueError(f"{name}={value!r} is invalid: allowed range is (0, inf), finite")


@dataclass(frozen=True, kw_only=True)
class BenchmarkLimits:
    """Input limits and gravity of the benchmark vehicle (mass-normalised).

    Parameters
    ----------
    f_min_m_s2 : float
        Minimum collective thrust per unit mass, m/s^2.  Default
        ``3.92 + 0.05 * (21.58 - 3.92)`` (5 % margin above the motor minimum).
    f_max_m_s2 : float
        Maximum collective thrust per unit mass, m/s^2.  Default
        ``21.58 - 0.05 * (21.58 - 3.92)``.  Must exceed gravity.
    max_rate_rad_s : float
        Maximum magnitude of the body rate, rad/s.
    gravity_m_s2 : float
        Gravitational acceleration, m/s^2.

    Raises
    ------
    ValueError
        If a field is not finite, not positive, ``f_min_m_s2 >= f_max_m_s2``
        or ``f_max_m_s2 <= gravity_m_s2``.  The message names the field, its
        value and the allowed range.
    """

    f_min_m_s2: float = _F_LOW_RAW + _MARGIN * (_F_HIGH_RAW - _F_LOW_RAW)
    f_max_m_s2: float = _F_HIGH_RAW - _MARGIN * (_F_HIGH_RAW - _F_LOW_RAW)
    max_rate_rad_s: float = 10.0
    gravity_m_s2: float = 9.81

    def __post_init__(self) -> None:
        for name in ("f_min_m_s2", "f_max_m_s2", "max_rate_rad_s", "gravity_m_s2"):
            _check_positive_finite(name, getattr(self, name))
        if self.f_min_m_s2 >= self.f_max_m_s2:
            raise ValueError(
                f"f_min_m_s2={self.f_min_m_s2!r} is invalid: allowed range is (0, f_max_m_s2={self.f_max_m_s2!r})"
            )
        if self.f_max_m_s2 <= self.gravity_m_s2:
            raise ValueError(
                f"f_max_m_s2={self.f_max_m_s2!r} is invalid: must exceed "
                f"gravity_m_s2={self.gravity_m_s2!r} (allowed range is "
                f"(max(f_min_m_s2, gravity_m_s2), inf)) for hover to be possible"
            )

    def _key(self) -> tuple[float, float, float, float]:
        return (
            float(self.f_min_m_s2),
            float(self.f_max_m_s2),
            float(self.max_rate_rad_s),
            float(self.gravity_m_s2),
        )


@dataclass(frozen=True, kw_only=True)
class InputArc:
    """One arc of an input program.

    Parameters
    ----------
    kind : str
        ``'max'`` (input at its upper bound), ``'min'`` (lower bound) or
        ``'singular'`` (interior value).
    start_s, end_s : float
        Arc start and end time, s.
    value : float
        The input on the arc (m/s^2 for thrust, rad/s for rate).  For a
        singular rate arc whose rate varies, this is the mean rate
        ``(theta(end) - theta(start)) / (end - start)``; the exact rate is
        given by ``tangent_law`` (see :meth:`evaluate`).
    tangent_law : tuple of float or None
        For singular rate arcs only: ``(alpha, beta)`` of the bilinear
        tangent law ``theta(start + s) = theta(start) + atan2(beta*s, 1 + alpha*s)``,
        i.e. ``omega(start + s) = beta / ((1 + alpha*s)**2 + (beta*s)**2)``.
        ``None`` for arcs on which the input is constant.
    """

    kind: str
    start_s: float
    end_s: float
    value: float
    tangent_law: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.kind not in ("max", "min", "singular"):
            raise ValueError(f"kind={self.kind!r} is invalid: allowed 'max', 'min', 'singular'")
        if not self.end_s >= self.start_s:
            raise ValueError(f"end_s={self.end_s!r} is invalid: must be >= start_s={self.start_s!r}")

    @property
    def duration_s(self) -> float:
        """Length of the arc, s."""
        return self.end_s - self.start_s

    def evaluate(self, t_s: np.ndarray | float) -> np.ndarray:
        """Input value at absolute time(s) ``t_s`` (assumed inside the arc).

        Parameters
        ----------
        t_s : array_like
            Absolute times, s.

        Returns
        -------
        numpy.ndarray
            Input values with the shape of ``t_s``.
        """
        t = np.asarray(t_s, dtype=float)
        if self.tangent_law is None:
            return np.full_like(t, self.value)
        alpha, beta = self.tangent_law
        s = t - self.start_s
        return beta / ((1.0 + alpha * s) ** 2 + (beta * s) ** 2)

    def to_json_dict(self) -> dict[str, Any]:
        """JSON-serialisable dictionary of the arc."""
        return {
            "kind": self.kind,
            "start_s": float(self.start_s),
            "end_s": float(self.end_s),
            "value": float(self.value),
            "tangent_law": None if self.tangent_law is None else [float(v) for v in self.tangent_law],
        }


def _json_float(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


@dataclass(frozen=True, kw_only=True, eq=False)
class TimeOptimalSolution:
    """Result of :func:`solve_translation`.

    Attributes
    ----------
    status : str
        ``'optimal'`` (converged local optimum satisfying all checks) or
        ``'failed'``.
    message : str
        Human-readable summary or the reason for failure.
    target_m : tuple of float
        Target position ``(Y, Z)``, m.
    final_angle_rad : float
        Required final attitude, rad.
    limits : BenchmarkLimits
        Limits used.
    duration_s : float
        Refined minimum time ``T*`` (nan if failed).
    transcription_duration_s : float
        Final time of the direct transcription (nan if it failed).
    thrust_arcs, rate_arcs : tuple of InputArc
        Arc programs of the refined solution (empty if failed).  Together
        they fully define the input programs (see :meth:`inputs`).
    times_s : numpy.ndarray
        ``(N,)`` dense sample times of the refined trajectory (includes the
        switch times).
    states : numpy.ndarray
        ``(N, 5)`` states at ``times_s``; columns y, z, vy, vz, theta.
    boundary_error : float
        Max abs final-state residual of the refined input program,
        re-integrated independently with an adaptive ODE solver.
    """

    status: str
    message: str
    target_m: tuple[float, float]
    final_angle_rad: float
    limits: BenchmarkLimits
    duration_s: float
    transcription_duration_s: float
    thrust_arcs: tuple[InputArc, ...]
    rate_arcs: tuple[InputArc, ...]
    times_s: np.ndarray
    states: np.ndarray
    boundary_error: float

    @property
    def ok(self) -> bool:
        """True if the solution is a verified optimum (``status == 'optimal'``)."""
        return self.status == "optimal"

    def inputs(self, t_s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Thrust and rate of the refined program at times ``t_s``.

        Parameters
        ----------
        t_s : array_like
            Times in ``[0, duration_s]``, s.  At a switch the arc starting
            there is used.

        Returns
        -------
        thrust, rate : numpy.ndarray
            Input values with the shape of ``t_s``.
        """
        t = np.asarray(t_s, dtype=float)
        return _eval_arcs(self.thrust_arcs, t), _eval_arcs(self.rate_arcs, t)

    def to_json_dict(self) -> dict[str, Any]:
        """JSON-serialisable summary (non-finite numbers become ``None``)."""
        return {
            "status": self.status,
            "message": self.message,
            "target_m": [float(self.target_m[0]), float(self.target_m[1])],
            "final_angle_rad": float(self.final_angle_rad),
            "duration_s": _json_float(self.duration_s),
            "transcription_duration_s": _json_float(self.transcription_duration_s),
            "boundary_error": _json_float(self.boundary_error),
            "thrust_arcs": [a.to_json_dict() for a in self.thrust_arcs],
            "rate_arcs": [a.to_json_dict() for a in self.rate_arcs],
        }


def _eval_arcs(arcs: Sequence[InputArc], t: np.ndarray) -> np.ndarray:
    out = np.full(t.shape, np.nan)
    if not arcs:
        return out
    starts = np.array([a.start_s for a in arcs])
    idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(arcs) - 1)
    for k, arc in enumerate(arcs):
        m = idx == k
        if np.any(m):
            out[m] = arc.evaluate(t[m])
    return out


class _SolveFailure(Exception):
    """Internal: an ordinary solver failure, turned into status 'failed'."""


# --------------------------------------------------------------------------
# direct transcription
# --------------------------------------------------------------------------
@functools.lru_cache(maxsize=16)
def _transcription_solver(intervals: int, limits_key: tuple[float, ...], max_iter: int) -> Any:
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
    solver = _transcription_solver(n, lim._key(), max_iter)
    lbx, ubx = _pack_bounds(n, target, final_angle, lim)
    w0 = np.clip(w0, lbx, ubx)
    try:
        res = solver(x0=w0, lbx=lbx, ubx=ubx, lbg=0.0, ubg=0.0)
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


def _best_transcription(
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
        raise _SolveFailure(
            "direct transcription did not converge (IPOPT status: "
            f"coarse {sorted(set(statuses))}, fine {sorted(set(fine_status))})"
        )
    return best[0], best[1], best[2], best[3]


# --------------------------------------------------------------------------
# arc structure from the transcription
# --------------------------------------------------------------------------
def _runs(labels: Sequence[str]) -> list[tuple[str, int, int]]:
    runs: list[tuple[str, int, int]] = []
    start = 0
    for i in range(1, len(labels) + 1):
        if i == len(labels) or labels[i] != labels[start]:
            runs.append((labels[start], start, i))
            start = i
    return runs


def _label(u: np.ndarray, lo: float, hi: float) -> list[str]:
    tol = _BANG_TOL_REL * (hi - lo)
    return ["max" if v >= hi - tol else "min" if v <= lo + tol else "mid" for v in u]


def _bang_segments(
    u: np.ndarray, lo: float, hi: float, dt: float, runs: list[tuple[str, int, int]], k: int
) -> list[tuple[str, float]]:
    """Split a short non-bang run into bang pieces ((kind, duration) list)."""
    label, i0, i1 = runs[k]
    t_max = float(np.sum((u[i0:i1] - lo) / (hi - lo))) * dt
    t_max = min(max(t_max, 0.0), (i1 - i0) * dt)
    t_min = (i1 - i0) * dt - t_max
    prev = runs[k - 1][0] if k > 0 else None
    nxt = runs[k + 1][0] if k + 1 < len(runs) else None
    amount = {"max": t_max, "min": t_min}
    other = {"max": "min", "min": "max"}
    if prev in amount and nxt in amount and prev != nxt:
        return [(prev, amount[prev]), (nxt, amount[nxt])]
    if prev in amount and nxt in amount:  # same bang on both sides: short opposite arc
        half = amount[prev] / 2
        return [(prev, half), (other[prev], amount[other[prev]]), (prev, half)]
    if prev in amount:  # at the end of the horizon
        return [(prev, amount[prev]), (other[prev], amount[other[prev]])]
    if nxt in amount:  # at the start of the horizon
        return [(other[nxt], amount[other[nxt]]), (nxt, amount[nxt])]
    raise _SolveFailure("input never reaches a bound; cannot identify a bang structure")


def _merge_segments(segs: list[tuple[str, float, Any]]) -> list[list[Any]]:
    """Merge consecutive segments of equal bang kind; returns [kind, t0, t1, extra]."""
    out: list[list[Any]] = []
    t = 0.0
    for kind, dur, extra in segs:
        if dur <= 0.0:
            continue
        if out and kind == out[-1][0] and kind != "singular":
            out[-1][2] = t + dur
        else:
            out.append([kind, t, t + dur, extra])
        t += dur
    return out


def _fit_costate_line(t: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Fit the common bilinear tangent law of all singular rate arcs.

    Finds the unit vector ``(a, b, c, d)`` minimising the residuals of
    ``sin(theta) (c + d t) - cos(theta) (a + b t) = 0``, i.e. the direction
    ``(a + b t, c + d t)`` parallel to ``(sin theta, cos theta)``.
    """
    mat = np.column_stack([-np.cos(theta), -t * np.cos(theta), np.sin(theta), t * np.sin(theta)])
    _, _, vt = np.linalg.svd(mat)
    return vt[-1].copy()


def _detect_structure(
    t_final: float, xs: np.ndarray, us: np.ndarray, lim: BenchmarkLimits, lam: np.ndarray | None = None
) -> tuple[list[list[Any]], list[list[Any]], np.ndarray | None]:
    """Arc structure of both inputs from a transcription.

    Returns
    -------
    thrust, rate : list of [kind, t0, t1, None]
        Arc lists of the two inputs.
    line : numpy.ndarray or None
        Initial guess ``(a, b, c, d)`` of the costate line shared by all
        singular rate arcs (``None`` if there are none): an affine fit of the
        transcription's velocity multipliers (its discrete adjoint), or, if
        those are unavailable, a fit of the attitude on the singular runs.
    """
    n = us.shape[0]
    dt = t_final / n
    # thrust: bang-bang expected
    f = us[:, 0]
    lo, hi = lim.f_min_m_s2, lim.f_max_m_s2
    runs = _runs(_label(f, lo, hi))
    segs: list[tuple[str, float, Any]] = []
    for k, (lab, i0, i1) in enumerate(runs):
        if lab != "mid":
            segs.append((lab, (i1 - i0) * dt, None))
        elif i1 - i0 >= _MIN_SINGULAR_INTERVALS:
            raise _SolveFailure(
                f"singular thrust arc detected on t in [{i0 * dt:.3f}, {i1 * dt:.3f}] s; "
                "switching-time refinement supports bang-bang thrust only"
            )
        else:
            segs.extend((kind, dur, None) for kind, dur in _bang_segments(f, lo, hi, dt, runs, k))
    thrust = _merge_segments(segs)
    # rate: bang-singular expected
    w = us[:, 1]
    wmax = lim.max_rate_rad_s
    runs = _runs(_label(w, -wmax, wmax))
    segs = []
    fit_t: list[np.ndarray] = []
    fit_theta: list[np.ndarray] = []
    for k, (lab, i0, i1) in enumerate(runs):
        if lab != "mid":
            segs.append((lab, (i1 - i0) * dt, None))
        elif i1 - i0 >= _MIN_SINGULAR_INTERVALS:
            # A singular run touching the start/end of the horizon may hide a
            # short bang arc there: its edge interval then deviates strongly
            # from the run's core (interior intervals ring around the
            # singular rate next to junctions, so use the median).
            core = float(np.median(w[i0:i1]))
            head = tail = None
            if i0 == 0 and abs(w[0] - core) > _EDGE_DEVIATION * wmax:
                kind = "max" if w[0] > core else "min"
                bound = wmax if kind == "max" else -wmax
                head = (kind, dt * min(1.0, abs((w[0] - core) / (bound - core))))
            if i1 == n and abs(w[-1] - core) > _EDGE_DEVIATION * wmax:
                kind = "max" if w[-1] > core else "min"
                bound = wmax if kind == "max" else -wmax
                tail = (kind, dt * min(1.0, abs((w[-1] - core) / (bound - core))))
            length = (i1 - i0) * dt
            if head is not None:
                segs.append((head[0], head[1], None))
                length -= head[1]
            segs.append(("singular", length - (tail[1] if tail else 0.0), None))
            if tail is not None:
                segs.append((tail[0], tail[1], None))
            # interior nodes only: the transcription rings next to junctions
            cut = 2 if i1 - i0 >= 7 else 0
            nodes = np.arange(i0 + cut, i1 + 1 - cut)
            fit_t.append(nodes * dt)
            fit_theta.append(xs[nodes, 4])
        else:
            segs.extend((kind, dur, None) for kind, dur in _bang_segments(w, -wmax, wmax, dt, runs, k))
    rate = _merge_segments(segs)
    line = None
    if fit_t:
        line = _line_from_multipliers(lam, t_final) if lam is not None else None
        if line is None:
            line = _fit_costate_line(np.concatenate(fit_t), np.concatenate(fit_theta))
    return thrust, rate, line


def _line_from_multipliers(lam: np.ndarray, t_final: float) -> np.ndarray | None:
    """Affine fit ``(a + b t, c + d t)`` of the transcription's velocity multipliers."""
    n = lam.shape[0]
    t = np.arange(1, n + 1) * t_final / n
    mat = np.column_stack([np.ones(n), t])
    cy = np.linalg.lstsq(mat, lam[:, 2], rcond=None)[0]
    cz = np.linalg.lstsq(mat, lam[:, 3], rcond=None)[0]
    v = np.array([cy[0], cy[1], cz[0], cz[1]])
    norm = float(np.linalg.norm(v))
    if not math.isfinite(norm) or norm < 1e-12:
        return None
    return v / norm


# --------------------------------------------------------------------------
# switching-time refinement
# --------------------------------------------------------------------------
def _series_or_exact(ca: Any, a: Any) -> tuple[Any, Any, Any, Any]:
    """S1=sin(a)/a, C1=(1-cos a)/a, S2=(1-cos a)/a^2, C2=(a-sin a)/a^2, safe at a=0."""
    small = ca.fabs(a) < 1e-2
    a_safe = ca.if_else(small, 1.0, a)
    a2 = a * a
    s1 = ca.if_else(small, 1 - a2 / 6 + a2 * a2 / 120 - a2**3 / 5040, ca.sin(a_safe) / a_safe)
    c1 = ca.if_else(
        small,
        a / 2 - a * a2 / 24 + a * a2 * a2 / 720 - a * a2**3 / 40320,
        (1 - ca.cos(a_safe)) / a_safe,
    )
    s2 = ca.if_else(
        small,
        0.5 - a2 / 24 + a2 * a2 / 720 - a2**3 / 40320,
        (1 - ca.cos(a_safe)) / (a_safe * a_safe),
    )
    c2 = ca.if_else(
        small,
        a / 6 - a * a2 / 120 + a * a2 * a2 / 5040 - a * a2**3 / 362880,
        (a_safe - ca.sin(a_safe)) / (a_safe * a_safe),
    )
    return s1, c1, s2, c2


@functools.lru_cache(maxsize=1)
def _gauss_nodes() -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(_GL_NODES)
    nodes, weights = [], []
    for p in range(_GL_PANELS):
        nodes.append((p + (x + 1) / 2) / _GL_PANELS)
        weights.append(w / 2 / _GL_PANELS)
    return np.concatenate(nodes), np.concatenate(weights)


class _Structure:
    """Merged timeline of both inputs for the switching-time optimisation."""

    def __init__(
        self,
        thrust: list[list[Any]],
        rate: list[list[Any]],
        line: np.ndarray | None,
        lim: BenchmarkLimits,
    ):
        self.lim = lim
        self.thrust_kinds = [a[0] for a in thrust]
        self.rate_kinds = [a[0] for a in rate]
        self.has_singular = "singular" in self.rate_kinds
        if self.has_singular and line is None:
            raise _SolveFailure("singular rate arc without a costate-line guess")
        self.line0 = None if not self.has_singular else np.asarray(line, dtype=float)
        t_end = max(thrust[-1][2], rate[-1][2])
        cuts = sorted({0.0, t_end} | {a[2] for a in thrust[:-1]} | {a[2] for a in rate[:-1]})
        self.pieces: list[tuple[int, int]] = []
        d0 = []
        for t0, t1 in zip(cuts[:-1], cuts[1:], strict=True):
            tm = 0.5 * (t0 + t1)
            i = next(k for k, a in enumerate(thrust) if tm <= a[2] or k == len(thrust) - 1)
            j = next(k for k, a in enumerate(rate) if tm <= a[2] or k == len(rate) - 1)
            self.pieces.append((i, j))
            d0.append(t1 - t0)
        self.d0 = np.array(d0)

    def thrust_value(self, i: int) -> float:
        return self.lim.f_max_m_s2 if self.thrust_kinds[i] == "max" else self.lim.f_min_m_s2

    def rate_value(self, j: int) -> float:
        return self.lim.max_rate_rad_s if self.rate_kinds[j] == "max" else -self.lim.max_rate_rad_s


@functools.lru_cache(maxsize=1)
def _piece_functions() -> tuple[Any, Any]:
    """CasADi functions propagating one piece (built once, reused by every refinement).

    ``bang(x, f, w, d, g) -> x_end``: closed-form propagation with constant
    thrust ``f`` and rate ``w`` over duration ``d``.

    ``sing(x, f, d, g, v, t0, th_e, t_e) -> (x_end, Q)``: propagation on a
    singular rate arc that follows the costate line ``v = (a, b, c, d)``,
    entered at time ``t_e`` with attitude ``th_e``; the piece starts at
    absolute time ``t0``.  ``Q`` is the minimum of ``|n(t)|^2`` over the
    piece, so ``|b c - a d| <= omega_max * Q`` bounds the rate exactly.
    """
    import casadi as ca

    x = ca.SX.sym("x", 5)
    f = ca.SX.sym("f")
    w = ca.SX.sym("w")
    d = ca.SX.sym("d")
    g = ca.SX.sym("g")
    y, z, vy, vz, th = x[0], x[1], x[2], x[3], x[4]
    a = w * d
    s1, c1, s2, c2 = _series_or_exact(ca, a)
    sn, cs = ca.sin(th), ca.cos(th)
    x_end = ca.vertcat(
        y + vy * d + f * d * d * (sn * s2 + cs * c2),
        z + vz * d + f * d * d * (cs * s2 - sn * c2) - 0.5 * g * d * d,
        vy + f * d * (sn * s1 + cs * c1),
        vz + f * d * (cs * s1 - sn * c1) - g * d,
        th + a,
    )
    bang = ca.Function("bang", [x, f, w, d, g], [x_end])

    v = ca.SX.sym("v", 4)
    t0 = ca.SX.sym("t0")
    th_e = ca.SX.sym("th_e")
    t_e = ca.SX.sym("t_e")
    nodes, weights = _gauss_nodes()
    xn = ca.DM(nodes)
    wn = ca.DM(weights)
    pe, qe = v[0] + v[1] * t_e, v[2] + v[3] * t_e
    tq = t0 + xn * d
    p = v[0] + v[1] * tq
    q = v[2] + v[3] * tq
    r = ca.sqrt(pe * pe + qe * qe) * ca.sqrt(p * p + q * q)
    sin_rel = (qe * p - pe * q) / r
    cos_rel = (pe * p + qe * q) / r
    se, ce = ca.sin(th_e), ca.cos(th_e)
    ey = se * cos_rel + ce * sin_rel
    ez = ce * cos_rel - se * sin_rel
    wp = wn * (1 - xn)
    p1, q1 = v[0] + v[1] * (t0 + d), v[2] + v[3] * (t0 + d)
    x_end = ca.vertcat(
        y + vy * d + f * d * d * ca.dot(wp, ey),
        z + vz * d + f * d * d * ca.dot(wp, ez) - 0.5 * g * d * d,
        vy + f * d * ca.dot(wn, ey),
        vz + f * d * ca.dot(wn, ez) - g * d,
        th_e + ca.atan2(qe * p1 - pe * q1, pe * p1 + qe * q1),
    )
    # exact minimum of |n(t)|^2 over the piece (the rate peaks where the
    # costate line passes closest to the origin)
    big_a = v[1] * v[1] + v[3] * v[3]
    t_star = -(v[0] * v[1] + v[2] * v[3]) / ca.fmax(big_a, 1e-300)
    t_c = ca.fmin(ca.fmax(t_star, t0), t0 + d)
    p_c, q_c = v[0] + v[1] * t_c, v[2] + v[3] * t_c
    qq = p_c * p_c + q_c * q_c
    sing = ca.Function("sing", [x, f, d, g, v, t0, th_e, t_e], [x_end, qq])
    return bang, sing


@functools.lru_cache(maxsize=128)
def _refine_solver(signature: tuple[tuple[str, str, int], ...], limits_key: tuple[float, ...]) -> tuple[Any, int, int]:
    """Build (and cache) the switching-time NLP of one arc structure.

    ``signature`` lists the merged pieces as ``(thrust kind, rate kind,
    singular arc id or -1)``.  The target and final angle are NLP
    parameters, so one solver serves every target with this structure.

    Decision variables: the piece durations and, if there are singular rate
    arcs, the unit vector ``v = (a, b, c, d)`` of the costate line
    ``n(t) = (a + b t, c + d t)``.  On a singular arc entered at ``t_e`` the
    attitude is ``theta(t) = theta(t_e) + angle(n(t_e) -> n(t))`` and
    ``n(t_e)`` must be parallel to ``(sin theta, cos theta)`` (junction
    constraint); the rate ``(b c - a d) / |n(t)|^2`` is bounded on each piece
    through the minimum of ``|n(t)|^2``.  Objective: ``T = sum(d)``.
    """
    import casadi as ca

    f_min, f_max, wmax, g = limits_key
    bang, sing = _piece_functions()
    npc = len(signature)
    has_singular = any(sid >= 0 for _, _, sid in signature)
    d = ca.MX.sym("d", npc)
    nl = 4 if has_singular else 0
    v = ca.MX.sym("v", nl)
    par = ca.MX.sym("p", 3)  # target y, target z, final angle
    xk = ca.MX.zeros(5)
    t_abs = ca.MX(0.0)
    entry: dict[int, tuple[Any, Any]] = {}
    eq: list[Any] = []
    ineq: list[Any] = []
    k_rate = v[1] * v[2] - v[0] * v[3] if has_singular else None
    for k, (fk, rk, sid) in enumerate(signature):
        f = f_max if fk == "max" else f_min
        if sid < 0:
            xk = bang(xk, f, wmax if rk == "max" else -wmax, d[k], g)
        else:
            if sid not in entry:
                entry[sid] = (xk[4], t_abs)
                pe, qe = v[0] + v[1] * t_abs, v[2] + v[3] * t_abs
                eq.append(ca.sin(xk[4]) * qe - ca.cos(xk[4]) * pe)  # junction: n(t_e) || e(theta)
            th_e, t_e = entry[sid]
            xk, qq = sing(xk, f, d[k], g, v, t_abs, th_e, t_e)
            ineq += [wmax * qq - k_rate, wmax * qq + k_rate]
        t_abs = t_abs + d[k]
    eq = [xk[0] - par[0], xk[1] - par[1], xk[2], xk[3], xk[4] - par[2]] + eq
    if has_singular:
        eq.append(ca.sumsqr(v) - 1.0)
    gexp = ca.vertcat(*eq, *ineq)
    nlp = {"x": ca.vertcat(d, v), "p": par, "f": ca.sum1(d), "g": gexp}
    opts: dict[str, Any] = {
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "print_time": False,
        "ipopt.tol": 1e-13,
        "ipopt.constr_viol_tol": 1e-13,
        "ipopt.acceptable_tol": 1e-10,
        "ipopt.acceptable_constr_viol_tol": 1e-11,
        "ipopt.max_iter": 400,
        "ipopt.bound_relax_factor": 0.0,
    }
    return ca.nlpsol("refine", "ipopt", nlp, opts), len(eq), int(gexp.shape[0]) - len(eq)


def _refine_once(
    st: _Structure, target: tuple[float, float], final_angle: float
) -> tuple[bool, str, np.ndarray, np.ndarray | None, np.ndarray]:
    """One switching-time optimisation for a fixed arc structure.

    Returns success flag, IPOPT status, piece durations, costate line and
    ``nu``: the multipliers of the five final-state constraints, i.e. the
    adjoint ``lambda(T)`` normalised to ``lambda_0 = 1``.
    """
    signature = tuple(
        (st.thrust_kinds[i], st.rate_kinds[j], j if st.rate_kinds[j] == "singular" else -1) for i, j in st.pieces
    )
    solver, n_eq, n_in = _refine_solver(signature, st.lim._key())
    npc = len(st.pieces)
    nl = 4 if st.has_singular else 0
    lbg = np.zeros(n_eq + n_in)
    ubg = np.concatenate([np.zeros(n_eq), np.full(n_in, np.inf)])
    lbx = np.concatenate([np.zeros(npc), np.full(nl, -1.0)])
    ubx = np.concatenate([np.full(npc, np.inf), np.full(nl, 1.0)])
    x0 = np.concatenate([st.d0, st.line0 if st.has_singular else []])
    res = solver(x0=x0, p=[target[0], target[1], final_angle], lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    stats = solver.stats()
    xopt = np.asarray(res["x"], dtype=float).ravel()
    line_opt = xopt[npc:] if st.has_singular else None
    nu = np.asarray(res["lam_g"], dtype=float).ravel()[:5].copy()
    return bool(stats["success"]), str(stats["return_status"]), xopt[:npc], line_opt, nu


def _arcs_from_pieces(st: _Structure, d: np.ndarray) -> tuple[list[list[Any]], list[list[Any]]]:
    times = np.concatenate([[0.0], np.cumsum(d)])
    thrust: list[list[Any]] = []
    rate: list[list[Any]] = []
    for k, (i, j) in enumerate(st.pieces):
        t0, t1 = float(times[k]), float(times[k + 1])
        if thrust and thrust[-1][4] == i:
            thrust[-1][2] = t1
        else:
            thrust.append([st.thrust_kinds[i], t0, t1, None, i])
        if rate and rate[-1][4] == j:
            rate[-1][2] = t1
        else:
            rate.append([st.rate_kinds[j], t0, t1, None, j])
    return [a[:4] for a in thrust], [a[:4] for a in rate]


def _prune(arcs: list[list[Any]]) -> tuple[list[list[Any]], bool]:
    kept = [a for a in arcs if a[2] - a[1] >= _PRUNE_TOL_S]
    changed = len(kept) != len(arcs)
    merged: list[list[Any]] = []
    for a in kept:
        if merged and merged[-1][0] == a[0]:
            merged[-1] = [a[0], merged[-1][1], a[2], None]
            changed = True
        else:
            merged.append(list(a))
    if not merged:
        raise _SolveFailure("refinement removed every arc of an input")
    for k in range(1, len(merged)):  # keep the timeline contiguous
        merged[k][1] = merged[k - 1][2]
    return merged, changed


def _line_from_adjoint(nu: np.ndarray, t_final: float) -> np.ndarray:
    """Costate line ``(a, b, c, d)`` of ``lambda_v(t)`` from ``lambda(T) = nu``.

    ``lambda_y, lambda_z`` are constant, so ``lambda_vy(t) = nu_vy + nu_y (T - t)``
    and ``lambda_vz(t) = nu_vz + nu_z (T - t)``.
    """
    v = np.array([nu[2] + nu[0] * t_final, -nu[0], nu[3] + nu[1] * t_final, -nu[1]])
    return v / np.linalg.norm(v)


def _line_mismatch(v: np.ndarray, w: np.ndarray) -> float:
    return float(min(np.max(np.abs(v - w)), np.max(np.abs(v + w))))


def _refine(
    thrust: list[list[Any]],
    rate: list[list[Any]],
    line: np.ndarray | None,
    target: tuple[float, float],
    final_angle: float,
    lim: BenchmarkLimits,
) -> tuple[list[list[Any]], list[list[Any]], np.ndarray | None, np.ndarray, int]:
    """Switching-time optimisation with arc pruning and costate re-initialisation.

    The NLP restricted to one costate line can stop at stationary points
    that are not Pontryagin extremals.  At a true extremal the line of
    ``lambda_v`` obtained from the multipliers coincides with the optimised
    line; if it does not, the NLP is re-solved starting from the multiplier
    line (this converges in one or two rounds in practice).
    """
    best: tuple[float, list[list[Any]], list[list[Any]], np.ndarray | None, np.ndarray] | None = None
    rounds = 0
    for attempt in range(1, 5):
        rounds = attempt
        st = _Structure(thrust, rate, line, lim)
        ok, status, d, line_opt, nu = _refine_once(st, target, final_angle)
        if not ok:
            if best is not None:
                break
            raise _SolveFailure(f"switching-time optimisation did not converge (IPOPT: {status})")
        thrust, rate = _arcs_from_pieces(st, d)
        thrust, ch1 = _prune(thrust)
        rate, ch2 = _prune(rate)
        if ch1 or ch2:
            line = line_opt if "singular" in [a[0] for a in rate] else None
            continue
        t_opt = float(np.sum(d))
        if best is not None and t_opt > best[0] - 1e-10:
            if t_opt < best[0]:
                best = (t_opt, thrust, rate, line_opt, nu)
            break  # re-initialisation did not help: keep the best
        best = (t_opt, thrust, rate, line_opt, nu)
        if line_opt is None:
            break
        line_nu = _line_from_adjoint(nu, t_opt)
        if _line_mismatch(line_opt, line_nu) < 1e-7:
            break
        line = line_nu
    if best is None:
        raise _SolveFailure("switching-time optimisation kept removing arcs (no stable structure)")
    _, thrust, rate, line, nu = best
    return thrust, rate, line, nu, rounds


def _theta_fn(rate_arcs: Sequence[InputArc]) -> Callable[[np.ndarray], np.ndarray]:
    """Exact attitude of a rate program (theta(0) = 0)."""
    starts = np.array([a.start_s for a in rate_arcs])
    th0 = [0.0]
    for a in rate_arcs[:-1]:
        th0.append(th0[-1] + float(_arc_rotation(a, a.end_s)))

    def theta(t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(rate_arcs) - 1)
        out = np.empty(t.shape)
        for k, a in enumerate(rate_arcs):
            m = idx == k
            if np.any(m):
                out[m] = th0[k] + _arc_rotation(a, t[m])
        return out

    return theta


def _arc_rotation(arc: InputArc, t: np.ndarray | float) -> np.ndarray:
    s = np.asarray(t, dtype=float) - arc.start_s
    if arc.tangent_law is None:
        return arc.value * s
    alpha, beta = arc.tangent_law
    return np.arctan2(beta * s, 1.0 + alpha * s)


def _pmp_residual(
    thrust_arcs: Sequence[InputArc],
    rate_arcs: Sequence[InputArc],
    nu: np.ndarray,
    lim: BenchmarkLimits,
) -> tuple[float, tuple[str, float, str] | None]:
    """Largest violation of Pontryagin's minimum principle, relative to lambda_0 = 1.

    With ``lambda(T) = nu`` the adjoint is ``lambda_y, lambda_z`` constant,
    ``lambda_v`` affine and ``lambda_theta' = -f (lambda_vy cos theta - lambda_vz sin theta)``.
    Checks: ``f = f_max`` where ``sigma_f = lambda_v . (sin theta, cos theta) < 0``
    and ``f_min`` where it is positive; ``omega = -omega_max sign(lambda_theta)``
    on bang rate arcs and ``lambda_theta = 0`` on singular ones.

    Returns the violation and, if positive, ``(input, time, kind)`` of the
    needle variation that would improve most: the arc to insert.
    """
    t_final = thrust_arcs[-1].end_s
    theta = _theta_fn(rate_arcs)
    cuts = sorted({a.start_s for a in thrust_arcs} | {a.start_s for a in rate_arcs} | {t_final})
    xg, wg = np.polynomial.legendre.leggauss(8)
    sub = 64
    # lambda_theta on a fine grid, integrated backwards from T (Gauss per sub-interval)
    grid_t: list[np.ndarray] = []
    incs: list[np.ndarray] = []
    for t0, t1 in zip(cuts[:-1], cuts[1:], strict=True):
        if t1 <= t0:
            continue
        edges = np.linspace(t0, t1, sub + 1)
        h = np.diff(edges)
        tq = edges[:-1, None] + (xg[None, :] + 1) / 2 * h[:, None]
        f = _eval_arcs(thrust_arcs, np.full(tq.shape, 0.5 * (t0 + t1)))
        th = theta(tq)
        lvy = nu[2] + nu[0] * (t_final - tq)
        lvz = nu[3] + nu[1] * (t_final - tq)
        integrand = f * (lvy * np.cos(th) - lvz * np.sin(th))
        incs.append((integrand * wg[None, :]).sum(axis=1) * h / 2)
        grid_t.append(edges[1:])
    t_all = np.concatenate([[0.0], *grid_t])
    inc = np.concatenate(incs)
    # lambda_theta(t_k) = nu_theta + int_{t_k}^T integrand
    tail = np.concatenate([np.cumsum(inc[::-1])[::-1], [0.0]])
    lam_th = nu[4] + tail
    th = theta(t_all)
    lvy = nu[2] + nu[0] * (t_final - t_all)
    lvz = nu[3] + nu[1] * (t_final - t_all)
    sigma_f = lvy * np.sin(th) + lvz * np.cos(th)
    viol = 0.0
    where: tuple[str, float, str] | None = None
    for arc in thrust_arcs:
        m = np.nonzero((t_all >= arc.start_s) & (t_all <= arc.end_s))[0]
        sign = 1.0 if arc.kind == "max" else -1.0
        if m.size and float(np.max(sign * sigma_f[m])) > viol:
            k = m[np.argmax(sign * sigma_f[m])]
            viol = float(sign * sigma_f[k])
            where = ("thrust", float(t_all[k]), "min" if arc.kind == "max" else "max")
    for arc in rate_arcs:
        m = np.nonzero((t_all >= arc.start_s) & (t_all <= arc.end_s))[0]
        if not m.size:
            continue
        if arc.kind == "singular":
            k = m[np.argmax(np.abs(lam_th[m]))]
            v = abs(float(lam_th[k]))
        else:
            sign = 1.0 if arc.kind == "max" else -1.0
            k = m[np.argmax(sign * lam_th[m])]
            v = float(sign * lam_th[k])
        if v > viol:
            viol = v
            where = ("rate", float(t_all[k]), "min" if lam_th[k] > 0 else "max")
    return viol, where


# --------------------------------------------------------------------------
# independent verification
# --------------------------------------------------------------------------
def _make_arcs(
    raw: list[list[Any]], is_rate: bool, lim: BenchmarkLimits, line: np.ndarray | None = None
) -> tuple[InputArc, ...]:
    out = []
    for kind, t0, t1, _ in raw:
        if kind == "singular":
            if line is None:  # pragma: no cover - guarded by _Structure
                raise _SolveFailure("singular arc without costate line")
            a, b, c, d = (float(x) for x in line)
            pe, qe = a + b * t0, c + d * t0
            ne2 = pe * pe + qe * qe
            alpha = (b * pe + d * qe) / ne2
            beta = (b * qe - d * pe) / ne2
            dur = t1 - t0
            mean = math.atan2(beta * dur, 1 + alpha * dur) / dur if dur > 0 else beta
            out.append(
                InputArc(
                    kind=kind,
                    start_s=float(t0),
                    end_s=float(t1),
                    value=float(mean),
                    tangent_law=(float(alpha), float(beta)),
                )
            )
        else:
            if is_rate:
                value = lim.max_rate_rad_s if kind == "max" else -lim.max_rate_rad_s
            else:
                value = lim.f_max_m_s2 if kind == "max" else lim.f_min_m_s2
            out.append(InputArc(kind=kind, start_s=float(t0), end_s=float(t1), value=float(value)))
    return tuple(out)


def _simulate(
    thrust_arcs: Sequence[InputArc],
    rate_arcs: Sequence[InputArc],
    lim: BenchmarkLimits,
    step_s: float = 1e-3,
) -> tuple[np.ndarray, np.ndarray]:
    """Integrate the input programs with DOP853 (rtol=atol=1e-12) piece by piece."""
    from scipy.integrate import solve_ivp

    g = lim.gravity_m_s2
    cuts = sorted({a.start_s for a in thrust_arcs} | {a.start_s for a in rate_arcs} | {thrust_arcs[-1].end_s})
    state = np.zeros(5)
    times = [np.array([0.0])]
    states = [state[None, :]]
    for t0, t1 in zip(cuts[:-1], cuts[1:], strict=True):
        if t1 <= t0:
            continue
        tm = 0.5 * (t0 + t1)
        th_arc = next(a for a in thrust_arcs if a.start_s <= tm <= a.end_s)
        r_arc = next(a for a in rate_arcs if a.start_s <= tm <= a.end_s)
        law = r_arc.tangent_law
        singular = law is not None
        al, be = (float(law[0]), float(law[1])) if law is not None else (0.0, 0.0)

        def rhs(
            t: float,
            x: np.ndarray,
            f: float = float(th_arc.value),
            w: float = float(r_arc.value),
            al: float = al,
            be: float = be,
            ts: float = float(r_arc.start_s),
            singular: bool = singular,
        ) -> np.ndarray:
            if singular:  # bilinear tangent law of the singular arc
                c = 1.0 + al * (t - ts)
                b = be * (t - ts)
                w = be / (c * c + b * b)
            th = x[4]
            return np.array([x[2], x[3], f * math.sin(th), f * math.cos(th) - g, w])

        m = max(2, int(math.ceil((t1 - t0) / step_s)) + 1)
        t_eval = np.linspace(t0, t1, m)
        sol = solve_ivp(rhs, (t0, t1), state, method="DOP853", rtol=1e-12, atol=1e-12, t_eval=t_eval)
        if not sol.success:  # pragma: no cover
            raise _SolveFailure(f"verification integration failed: {sol.message}")
        state = sol.y[:, -1].copy()
        times.append(t_eval[1:])
        states.append(sol.y.T[1:])
    return np.concatenate(times), np.vstack(states)


@dataclass
class _Candidate:
    thrust: list[list[Any]]
    rate: list[list[Any]]
    line: np.ndarray | None
    thrust_arcs: tuple[InputArc, ...]
    rate_arcs: tuple[InputArc, ...]
    times: np.ndarray
    states: np.ndarray
    error: float
    duration: float
    rounds: int
    pmp_residual: float
    needle: tuple[str, float, str] | None
    nu: np.ndarray

    def problems(self, t_trans: float, lim: BenchmarkLimits) -> list[str]:
        out = []
        if not self.error <= _BOUNDARY_TOL:
            out.append(f"boundary error {self.error:.3e} exceeds {_BOUNDARY_TOL:.0e}")
        wmax = lim.max_rate_rad_s
        for arc in self.rate_arcs:
            if arc.tangent_law is not None:
                tt = np.linspace(arc.start_s, arc.end_s, 2001)
                peak = float(np.max(np.abs(arc.evaluate(tt))))
                if peak > wmax * (1 + 1e-9):
                    out.append(f"singular rate arc reaches |omega|={peak:.6g} > {wmax:g} rad/s")
        if self.duration > t_trans + _REFINE_T_TOL_S:
            out.append(f"refined T={self.duration:.10f} s exceeds transcription T={t_trans:.10f} s")
        if not self.pmp_residual <= _PMP_TOL:
            out.append(
                f"minimum principle violated (residual {self.pmp_residual:.1e} > {_PMP_TOL:.0e}): "
                "not an extremal, arc structure incomplete"
            )
        return out


def _refine_candidate(
    thrust: list[list[Any]],
    rate: list[list[Any]],
    line: np.ndarray | None,
    target: tuple[float, float],
    angle: float,
    limits: BenchmarkLimits,
    final: np.ndarray,
) -> _Candidate:
    thrust, rate, line, nu, rounds = _refine(thrust, rate, line, target, angle, limits)
    thrust_arcs = _make_arcs(thrust, False, limits)
    rate_arcs = _make_arcs(rate, True, limits, line)
    times, states = _simulate(thrust_arcs, rate_arcs, limits)
    err = float(np.max(np.abs(states[-1] - final)))
    pmp, needle = _pmp_residual(thrust_arcs, rate_arcs, nu, limits)
    wmax = limits.max_rate_rad_s
    for arc in rate_arcs:
        if arc.tangent_law is not None and pmp > _PMP_TOL:
            tt = np.linspace(arc.start_s, arc.end_s, 4001)
            rates = arc.evaluate(tt)
            k = int(np.argmax(np.abs(rates)))
            if abs(rates[k]) >= wmax * (1 - 1e-4) and 0 < k < tt.size - 1:
                # the singular rate saturates inside the arc: it must be split
                # by a bang arc there (singular -> bang -> singular)
                needle = ("rate", float(tt[k]), "max" if rates[k] > 0 else "min")
                break
    return _Candidate(
        thrust=thrust,
        rate=rate,
        line=line,
        thrust_arcs=thrust_arcs,
        rate_arcs=rate_arcs,
        times=times,
        states=states,
        error=err,
        duration=float(thrust_arcs[-1].end_s),
        rounds=rounds,
        pmp_residual=pmp,
        needle=needle,
        nu=nu,
    )


def _insert_arc(arcs: list[list[Any]], t: float, kind: str, width: float) -> list[list[Any]]:
    """Insert a short arc of ``kind`` centred at ``t`` (clipped into its host arc)."""
    out = [list(a) for a in arcs]
    k = next((i for i, a in enumerate(out) if a[1] <= t <= a[2]), len(out) - 1)
    t0, t1 = out[k][1], out[k][2]
    width = min(width, 0.5 * (t1 - t0))
    lo = min(max(t - width / 2, t0), t1 - width)
    hi = lo + width
    host = out[k]
    pieces = []
    if lo > t0:
        pieces.append([host[0], t0, lo, None])
    pieces.append([kind, lo, hi, None])
    if hi < t1:
        pieces.append([host[0], hi, t1, None])
    out[k : k + 1] = pieces
    merged: list[list[Any]] = []
    for a in out:
        if merged and merged[-1][0] == a[0] and a[0] != "singular":
            merged[-1][2] = a[2]
        else:
            merged.append(a)
    return merged


def _nearby_bang_bang_switch(arcs: list[list[Any]], t: float, radius: float) -> int | None:
    """Index k of a switch between opposite bang arcs k-1 -> k within ``radius`` of ``t``."""
    best, best_dist = None, radius
    for k in range(1, len(arcs)):
        if {arcs[k - 1][0], arcs[k][0]} == {"max", "min"}:
            dist = abs(arcs[k][1] - t)
            if dist <= best_dist:
                best, best_dist = k, dist
    return best


def _insert_singular_at_switch(arcs: list[list[Any]], k: int, width: float) -> list[list[Any]]:
    out = [list(a) for a in arcs]
    t_sw = out[k][1]
    half = min(width / 2, 0.5 * (out[k - 1][2] - out[k - 1][1]), 0.5 * (out[k][2] - out[k][1]))
    out[k - 1][2] = t_sw - half
    out[k][1] = t_sw + half
    out.insert(k, ["singular", t_sw - half, t_sw + half, None])
    return out


def _edge_variants(rate: list[list[Any]], dt: float) -> list[list[list[Any]]]:
    """Rate structures with one short bang arc next to a singular arc.

    Short bang fragments next to a singular arc are easily absorbed into the
    singular run of the transcription (they share an interval with the
    junction and are followed by ringing).  Used only when the refinement of
    the identified structure fails outright (no multipliers to guide it).
    """
    out = []
    other = {"max": "min", "min": "max"}
    delta = 0.25 * dt
    for idx, arc in enumerate(rate):
        if arc[0] != "singular" or arc[2] - arc[1] <= 4 * delta:
            continue
        for side in ("start", "end"):
            nb = idx - 1 if side == "start" else idx + 1
            kinds = ["max", "min"] if not 0 <= nb < len(rate) else [other[rate[nb][0]]]
            for kind in kinds:
                t = arc[1] + delta / 2 if side == "start" else arc[2] - delta / 2
                out.append(_insert_arc(rate, t, kind, delta))
    return out


def _vertical_candidate(
    thrust: list[list[Any]],
    target: tuple[float, float],
    limits: BenchmarkLimits,
    final: np.ndarray,
) -> _Candidate:
    """Closed-form vertical bang-bang move with ``theta == 0`` throughout.

    This is the degenerate case of a single singular rate arc with zero
    rate, where the switching-time NLP has redundant constraints.
    """
    g, f_min, f_max = limits.gravity_m_s2, limits.f_min_m_s2, limits.f_max_m_s2
    z = target[1]
    a_up, a_down = f_max - g, g - f_min
    a1, a2 = (a_up, a_down) if z > 0 else (a_down, a_up)  # accelerate, then brake
    t1 = math.sqrt(2.0 * abs(z) * a2 / (a1 * (a1 + a2)))
    t2 = a1 * t1 / a2
    kinds = ["max", "min"] if z > 0 else ["min", "max"]
    if [a[0] for a in thrust] != kinds:
        raise _SolveFailure(f"vertical move: unexpected thrust structure {[a[0] for a in thrust]}")
    raw_thrust = [[kinds[0], 0.0, t1, None], [kinds[1], t1, t1 + t2, None]]
    raw_rate = [["singular", 0.0, t1 + t2, None]]
    thrust_arcs = _make_arcs(raw_thrust, False, limits)
    rate_arcs = (InputArc(kind="singular", start_s=0.0, end_s=t1 + t2, value=0.0, tangent_law=(0.0, 0.0)),)
    times, states = _simulate(thrust_arcs, rate_arcs, limits)
    return _Candidate(
        thrust=raw_thrust,
        rate=raw_rate,
        line=None,
        thrust_arcs=thrust_arcs,
        rate_arcs=rate_arcs,
        times=times,
        states=states,
        error=float(np.max(np.abs(states[-1] - final))),
        duration=t1 + t2,
        rounds=0,
        pmp_residual=0.0,  # not evaluated: degenerate singular arc (see message)
        needle=None,
        nu=np.zeros(5),
    )


def _refine_with_structure_search(
    thrust: list[list[Any]],
    rate: list[list[Any]],
    line: np.ndarray | None,
    target: tuple[float, float],
    angle: float,
    limits: BenchmarkLimits,
    t_trans: float,
    dt: float,
) -> tuple[_Candidate | None, list[str]]:
    """Refine the identified structure; repair it by needle insertion if needed.

    If the refined candidate violates the minimum principle (or is slower
    than the transcription), the arc that Pontryagin's principle asks for at
    the point of largest violation is inserted and the refinement repeated
    (at most ``_MAX_STRUCTURE_TRIALS`` refinements in total).  If the first
    refinement fails outright, single short bang arcs next to singular arcs
    are tried instead.
    """
    final = np.array([target[0], target[1], 0.0, 0.0, angle])
    queue: list[tuple[list[list[Any]], list[list[Any]], np.ndarray | None, Any]] = [(thrust, rate, line, None)]
    reasons: list[str] = []
    trials = 0
    seen: set[tuple[tuple[str, ...], tuple[str, ...]]] = set()
    edges_queued = False
    while queue and trials < _MAX_STRUCTURE_TRIALS:
        th_k, ra_k, ln_k, fallback = queue.pop(0)
        trials += 1
        try:
            cand = _refine_candidate(th_k, ra_k, ln_k, target, angle, limits, final)
        except _SolveFailure as exc:
            reasons.append(str(exc))
            if fallback is not None:
                queue.insert(0, fallback)
            elif not edges_queued:
                edges_queued = True
                queue.extend((thrust, r, line, None) for r in _edge_variants(rate, dt))
            continue
        issues = cand.problems(t_trans, limits)
        if not issues:
            return cand, reasons
        reasons.append("; ".join(issues))
        key = (tuple(a[0] for a in cand.thrust), tuple(a[0] for a in cand.rate))
        if key in seen:
            # the inserted arc was pruned again: needle repair is stuck here
            if not edges_queued:
                edges_queued = True
                queue.extend((thrust, r, line, None) for r in _edge_variants(rate, dt))
            continue
        seen.add(key)
        if cand.needle is not None:
            which, t, kind = cand.needle
            width = 0.25 * dt
            # insert into this trial's starting structure (transcription
            # timing): the refined timing sits on active constraints and is a
            # poor starting point for the enlarged problem
            new_th, new_ra = th_k, ra_k
            if which == "thrust":
                new_th = _insert_arc(th_k, t, kind, width)
            else:
                sw = _nearby_bang_bang_switch(ra_k, t, 2.0 * dt)
                if sw is not None:
                    # violations next to a bang-bang rate switch: the bang
                    # arcs would start chattering; a short singular arc fits
                    new_ra = _insert_singular_at_switch(ra_k, sw, 2.0 * width)
                else:
                    new_ra = _insert_arc(ra_k, t, kind, width)
            has_sing = "singular" in [a[0] for a in new_ra]
            adj_line = _line_from_adjoint(cand.nu, cand.duration)
            # start from the transcription's costate line (or, without one,
            # the rejected candidate's adjoint line); the other is the fallback
            first = line if line is not None else (cand.line if cand.line is not None else adj_line)
            second = cand.line if cand.line is not None else adj_line
            alt = (new_th, new_ra, second, None) if has_sing else None
            queue.insert(0, (new_th, new_ra, first if has_sing else None, alt))
    return None, reasons


# --------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------
def _validate_number(name: str, value: Any, allowed: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={value!r} is invalid: must be a real number ({allowed})") from None
    if isinstance(value, bool) or not math.isfinite(v):
        raise ValueError(f"{name}={value!r} is invalid: allowed range is {allowed}")
    return v


def _failed(
    message: str,
    target: tuple[float, float],
    final_angle: float,
    lim: BenchmarkLimits,
    t_trans: float = math.nan,
) -> TimeOptimalSolution:
    return TimeOptimalSolution(
        status="failed",
        message=message,
        target_m=target,
        final_angle_rad=final_angle,
        limits=lim,
        duration_s=math.nan,
        transcription_duration_s=t_trans,
        thrust_arcs=(),
        rate_arcs=(),
        times_s=np.empty(0),
        states=np.empty((0, 5)),
        boundary_error=math.nan,
    )


def solve_translation(
    target_y_m: float,
    target_z_m: float,
    *,
    final_angle_rad: float = 0.0,
    limits: BenchmarkLimits | None = None,
    intervals: int = 100,
    ipopt_max_iter: int = 3000,
) -> TimeOptimalSolution:
    """Time-optimal hover-to-hover motion from the origin to ``(Y, Z)``.

    Parameters
    ----------
    target_y_m, target_z_m : float
        Target position, m (finite).
    final_angle_rad : float, optional
        Final attitude, rad (finite); e.g. ``2*pi`` for a translation with
        one flip.  Default 0.
    limits : BenchmarkLimits, optional
        Input limits; defaults to :class:`BenchmarkLimits()`.
    intervals : int, optional
        Number of intervals of the fine direct transcription (>= 10).
    ipopt_max_iter : int, optional
        Iteration limit of every transcription IPOPT solve (>= 1).  Mainly
        useful to provoke/inspect the failure path (e.g. ``ipopt_max_iter=2``
        yields ``status == 'failed'``).

    Returns
    -------
    TimeOptimalSolution
        ``status == 'optimal'`` only if IPOPT converged, the switching-time
        refinement converged, the independently re-integrated program meets
        the boundary conditions to 1e-6, all inputs are within bounds, the
        refined time does not exceed the transcription time (+1e-9 s) and
        Pontryagin's minimum principle holds to 1e-6 (the residual is quoted
        in ``message``; for the degenerate pure-vertical ``theta == 0`` move
        the closed-form solution is used and the certificate is skipped).
        Otherwise ``status == 'failed'`` with the reason in ``message``.
        The solution is a local optimum: the transcription is multi-started
        over attitude guesses, which finds the best basin in all tested
        cases but is not a proof of global optimality.

    Raises
    ------
    ValueError
        For non-finite targets/angles, ``intervals < 10``,
        ``ipopt_max_iter < 1`` or a ``limits`` of the wrong type.
    """
    y_t = _validate_number("target_y_m", target_y_m, "(-inf, inf), finite")
    z_t = _validate_number("target_z_m", target_z_m, "(-inf, inf), finite")
    angle = _validate_number("final_angle_rad", final_angle_rad, "(-inf, inf), finite")
    if isinstance(intervals, bool) or not isinstance(intervals, (int, np.integer)) or intervals < 10:
        raise ValueError(f"intervals={intervals!r} is invalid: allowed range is integers >= 10")
    if isinstance(ipopt_max_iter, bool) or not isinstance(ipopt_max_iter, (int, np.integer)) or ipopt_max_iter < 1:
        raise ValueError(f"ipopt_max_iter={ipopt_max_iter!r} is invalid: allowed range is integers >= 1")
    if limits is None:
        limits = BenchmarkLimits()
    elif not isinstance(limits, BenchmarkLimits):
        raise ValueError(f"limits={limits!r} is invalid: must be a BenchmarkLimits instance or None")
    target = (y_t, z_t)
    if y_t == 0.0 and z_t == 0.0 and angle == 0.0:
        return TimeOptimalSolution(
            status="optimal",
            message="target equals the start state: zero-duration solution",
            target_m=target,
            final_angle_rad=angle,
            limits=limits,
            duration_s=0.0,
            transcription_duration_s=0.0,
            thrust_arcs=(),
            rate_arcs=(),
            times_s=np.zeros(1),
            states=np.zeros((1, 5)),
            boundary_error=0.0,
        )
    t_trans = math.nan
    try:
        t_trans, xs, us, lam = _best_transcription(target, angle, limits, int(intervals), int(ipopt_max_iter))
        thrust, rate, line = _detect_structure(t_trans, xs, us, limits, lam)
    except _SolveFailure as exc:
        return _failed(str(exc), target, angle, limits, t_trans)
    dt = t_trans / int(intervals)
    # one singular rate arc over the whole horizon: its rate has one sign, so
    # theta(0) = theta(T) = 0 forces theta == 0, i.e. a vertical move
    vertical = y_t == 0.0 and angle == 0.0 and [a[0] for a in rate] == ["singular"]
    if vertical:
        try:
            cand = _vertical_candidate(thrust, target, limits, np.array([y_t, z_t, 0.0, 0.0, angle]))
        except _SolveFailure as exc:
            return _failed(str(exc), target, angle, limits, t_trans)
        issues = cand.problems(t_trans, limits)
        best, reasons = (None, issues) if issues else (cand, [])
    else:
        best, reasons = _refine_with_structure_search(thrust, rate, line, target, angle, limits, t_trans, dt)
    if best is None:
        return _failed(
            "refinement rejected: "
            + reasons[-1]
            + (f" (after {len(reasons)} structure trials)" if len(reasons) > 1 else ""),
            target,
            angle,
            limits,
            t_trans,
        )
    thrust_arcs, rate_arcs = best.thrust_arcs, best.rate_arcs
    times, states, err, duration, rounds = best.times, best.states, best.error, best.duration, best.rounds
    pmp = best.pmp_residual
    times.setflags(write=False)
    states.setflags(write=False)
    n_sing = sum(a.kind == "singular" for a in rate_arcs)
    msg = (
        f"optimal: T*={duration:.6f} s (transcription {t_trans:.6f} s, {intervals} intervals); "
        f"{len(thrust_arcs)} thrust arcs, {len(rate_arcs)} rate arcs ({n_sing} singular); "
        f"boundary error {err:.1e}; PMP residual {pmp:.1e}; refinement rounds {rounds}"
    )
    if vertical:
        msg = (
            f"optimal: T*={duration:.6f} s (transcription {t_trans:.6f} s, {intervals} intervals); "
            "vertical bang-bang with theta == 0 (closed form; the transcription's multi-start found no "
            f"faster tilted motion; minimum-principle certificate not evaluated); boundary error {err:.1e}"
        )
    return TimeOptimalSolution(
        status="optimal",
        message=msg,
        target_m=target,
        final_angle_rad=angle,
        limits=limits,
        duration_s=float(duration),
        transcription_duration_s=float(t_trans),
        thrust_arcs=thrust_arcs,
        rate_arcs=rate_arcs,
        times_s=times,
        states=states,
        boundary_error=err,
    )


def clear_caches() -> None:
    """Drop every cached CasADi graph/solver (the next solve rebuilds them).

    Solvers are cached per transcription size and limits, and per arc
    structure for the refinement; mainly useful for benchmarking cold starts.
    """
    _transcription_solver.cache_clear()
    _refine_solver.cache_clear()
    _piece_functions.cache_clear()


def switch_times(solution: TimeOptimalSolution) -> np.ndarray:
    """Sorted unique interior switch times of both inputs.

    Parameters
    ----------
    solution : TimeOptimalSolution
        A solved benchmark (a failed one yields an empty array).

    Returns
    -------
    numpy.ndarray
        Switch times strictly inside ``(0, T*)``, s; times of the two inputs
        closer than 1e-12 s are reported once.
    """
    t = sorted(a.start_s for a in (*solution.thrust_arcs, *solution.rate_arcs) if a.start_s > 0.0)
    out: list[float] = []
    for v in t:
        if not out or v - out[-1] > 1e-12:
            out.append(v)
    return np.array(out, dtype=float)


def _map_worker(args: tuple[int, int, float, float, BenchmarkLimits | None]) -> tuple[int, int, float]:
    i, j, y, z, limits = args
    sol = solve_translation(y, z, limits=limits)
    return i, j, sol.duration_s if sol.ok else math.nan


def benchmark_map(
    ys_m: np.ndarray,
    zs_m: np.ndarray,
    *,
    limits: BenchmarkLimits | None = None,
    workers: int = 2,
    progress: Callable[[int, int], None] | None = None,
) -> np.ndarray:
    """Minimum times over a grid of targets.

    Parameters
    ----------
    ys_m, zs_m : array_like
        1-D target coordinates, m.
    limits : BenchmarkLimits, optional
        Input limits (default benchmark limits).
    workers : int, optional
        Number of worker processes (spawn context); ``1`` runs in-process.
    progress : callable, optional
        ``progress(done, total)`` called each time a target completes.

    Returns
    -------
    numpy.ndarray
        ``(len(zs), len(ys))`` array of ``T*`` (nan where the solve failed).
    """
    ys = np.asarray(ys_m, dtype=float).ravel()
    zs = np.asarray(zs_m, dtype=float).ravel()
    if not (np.all(np.isfinite(ys)) and np.all(np.isfinite(zs))):
        raise ValueError("ys_m and zs_m must be finite")
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise ValueError(f"workers={workers!r} is invalid: allowed range is integers >= 1")
    out = np.full((zs.size, ys.size), np.nan)
    jobs = [(i, j, float(ys[j]), float(zs[i]), limits) for i in range(zs.size) for j in range(ys.size)]
    total = len(jobs)
    done = 0
    if workers == 1:
        for job in jobs:
            i, j, t = _map_worker(job)
            out[i, j] = t
            done += 1
            if progress is not None:
                progress(done, total)
        return out
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=int(workers), mp_context=ctx) as pool:
        futures = [pool.submit(_map_worker, job) for job in jobs]
        for fut in as_completed(futures):
            i, j, t = fut.result()
            out[i, j] = t
            done += 1
            if progress is not None:
                progress(done, total)
    return out


def write_map_csv(path: str | os.PathLike[str], ys: np.ndarray, zs: np.ndarray, durations: np.ndarray) -> None:
    """Write a benchmark map as CSV with columns ``y_m, z_m, duration_s``.

    Parameters
    ----------
    path : path-like
        Output file.
    ys, zs : array_like
        Grid coordinates, m.
    durations : array_like
        ``(len(zs), len(ys))`` minimum times (nan written as ``nan``).
    """
    ys = np.asarray(ys, dtype=float).ravel()
    zs = np.asarray(zs, dtype=float).ravel()
    dur = np.asarray(durations, dtype=float)
    if dur.shape != (zs.size, ys.size):
        raise ValueError(f"durations shape {dur.shape} is invalid: expected (len(zs), len(ys)) = {(zs.size, ys.size)}")
    with open(path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["y_m", "z_m", "duration_s"])
        for i, z in enumerate(zs):
            for j, y in enumerate(ys):
                writer.writerow([repr(float(y)), repr(float(z)), repr(float(dur[i, j]))])


def plot_solution(solution: TimeOptimalSolution, path: str | os.PathLike[str]) -> None:
    """Plot input programs and the path with attitude snapshots.

    Parameters
    ----------
    solution : TimeOptimalSolution
        A successful solution.
    path : path-like
        Image file to write (format from the extension).

    Raises
    ------
    ValueError
        If the solution is not ``ok``.
    """
    if not solution.ok or solution.duration_s <= 0:
        raise ValueError(f"solution is invalid for plotting: status={solution.status!r}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lim = solution.limits
    t_final = solution.duration_s
    tt = np.linspace(0.0, t_final, 2001)
    f, w = solution.inputs(tt)
    fig = plt.figure(figsize=(11, 6))
    ax_f = fig.add_subplot(2, 2, 1)
    ax_w = fig.add_subplot(2, 2, 3, sharex=ax_f)
    ax_p = fig.add_subplot(1, 2, 2)
    ax_f.plot(tt, f, drawstyle="steps-post")
    ax_f.axhline(lim.f_max_m_s2, ls=":", c="gray")
    ax_f.axhline(lim.f_min_m_s2, ls=":", c="gray")
    ax_f.set_ylabel("thrust f [m/s²]")
    ax_f.set_title(f"T* = {t_final:.4f} s")
    ax_w.plot(tt, w, drawstyle="steps-post")
    ax_w.axhline(lim.max_rate_rad_s, ls=":", c="gray")
    ax_w.axhline(-lim.max_rate_rad_s, ls=":", c="gray")
    ax_w.set_ylabel("rate ω [rad/s]")
    ax_w.set_xlabel("time [s]")
    for ts in switch_times(solution):
        ax_f.axvline(ts, c="k", lw=0.5, alpha=0.3)
        ax_w.axvline(ts, c="k", lw=0.5, alpha=0.3)
    st = solution.states
    ax_p.plot(st[:, 0], st[:, 1], c="C0", lw=1)
    span = max(np.ptp(st[:, 0]), np.ptp(st[:, 1]), 1.0)
    arm = 0.04 * span
    for tk in np.arange(0.0, t_final + 1e-12, 0.05):
        k = int(np.argmin(np.abs(solution.times_s - tk)))
        y, z, th = st[k, 0], st[k, 1], st[k, 4]
        ey, ez = math.cos(th), -math.sin(th)  # body arm direction (perpendicular to thrust)
        ax_p.plot([y - arm * ey, y + arm * ey], [z - arm * ez, z + arm * ez], c="k", lw=1.5)
        ax_p.plot([y, y + 0.6 * arm * math.sin(th)], [z, z + 0.6 * arm * math.cos(th)], c="C3", lw=1)
    ax_p.plot([0.0], [0.0], "go")
    ax_p.plot([solution.target_m[0]], [solution.target_m[1]], "r*", ms=10)
    ax_p.set_aspect("equal", adjustable="datalim")
    ax_p.set_xlabel("y [m]")
    ax_p.set_ylabel("z [m]")
    ax_p.set_title("path (vehicle every 0.05 s, red: thrust direction)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_map(path: str | os.PathLike[str], ys: np.ndarray, zs: np.ndarray, durations: np.ndarray) -> None:
    """Contour plot of minimum time over target positions.

    Parameters
    ----------
    path : path-like
        Image file to write.
    ys, zs : array_like
        Grid coordinates, m.
    durations : array_like
        ``(len(zs), len(ys))`` minimum times (nan cells are left blank).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ys = np.asarray(ys, dtype=float).ravel()
    zs = np.asarray(zs, dtype=float).ravel()
    dur = np.ma.masked_invalid(np.asarray(durations, dtype=float))
    if dur.shape != (zs.size, ys.size):
        raise ValueError(f"durations shape {dur.shape} is invalid: expected (len(zs), len(ys)) = {(zs.size, ys.size)}")
    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    cs = ax.contourf(ys, zs, dur, levels=20, cmap="viridis")
    ax.contour(ys, zs, dur, levels=list(cs.levels)[::2], colors="k", linewidths=0.4)
    fig.colorbar(cs, ax=ax, label="T* [s]")
    ax.set_xlabel("target y [m]")
    ax.set_ylabel("target z [m]")
    ax.set_aspect("equal")
    ax.set_title("time-optimal hover-to-hover duration")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
