"""``solve_translation``: the three stages end to end, with caches."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from aerobat.errors import ConfigError
from aerobat.quadrotor.timeoptimal.refinement import piece_functions, refine_solver
from aerobat.quadrotor.timeoptimal.repair import refine_with_structure_search, vertical_candidate
from aerobat.quadrotor.timeoptimal.solution import (
    ArcKind,
    BenchmarkLimits,
    SolveStatus,
    StageFailure,
    TimeOptimalSolution,
)
from aerobat.quadrotor.timeoptimal.structure import detect_structure
from aerobat.quadrotor.timeoptimal.transcription import best_transcription, transcription_solver


def _validate_number(name: str, value: Any, allowed: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(f"{name}={value!r} is invalid: must be a real number ({allowed})") from None
    if isinstance(value, bool) or not math.isfinite(v):
        raise ConfigError(f"{name}={value!r} is invalid: allowed range is {allowed}")
    return v


def _failed(
    message: str,
    target: tuple[float, float],
    final_angle: float,
    lim: BenchmarkLimits,
    t_trans: float = math.nan,
) -> TimeOptimalSolution:
    return TimeOptimalSolution(
        status=SolveStatus.FAILED,
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
    ConfigError
        For non-finite targets/angles, ``intervals < 10``,
        ``ipopt_max_iter < 1`` or a ``limits`` of the wrong type.
    """
    y_t = _validate_number("target_y_m", target_y_m, "(-inf, inf), finite")
    z_t = _validate_number("target_z_m", target_z_m, "(-inf, inf), finite")
    angle = _validate_number("final_angle_rad", final_angle_rad, "(-inf, inf), finite")
    if isinstance(intervals, bool) or not isinstance(intervals, (int, np.integer)) or not 10 <= intervals <= 10_000:
        raise ConfigError(f"intervals={intervals!r} is invalid: allowed range is integers 10 … 10000")
    if (isinstance(ipopt_max_iter, bool) or not isinstance(ipopt_max_iter, (int, np.integer))
            or not 1 <= ipopt_max_iter <= 10**7):
        raise ConfigError(f"ipopt_max_iter={ipopt_max_iter!r} is invalid: allowed range is integers 1 … 10^7")
    if limits is None:
        limits = BenchmarkLimits()
    elif not isinstance(limits, BenchmarkLimits):
        raise ConfigError(f"limits={limits!r} is invalid: must be a BenchmarkLimits instance or None")
    target = (y_t, z_t)
    if y_t == 0.0 and z_t == 0.0 and angle == 0.0:
        return TimeOptimalSolution(
            status=SolveStatus.OPTIMAL,
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
        t_trans, xs, us, lam = best_transcription(target, angle, limits, int(intervals), int(ipopt_max_iter))
        thrust, rate, line = detect_structure(t_trans, xs, us, limits, lam)
    except StageFailure as exc:
        return _failed(str(exc), target, angle, limits, t_trans)
    dt = t_trans / int(intervals)
    # one singular rate arc over the whole horizon: its rate has one sign, so
    # theta(0) = theta(T) = 0 forces theta == 0, i.e. a vertical move
    vertical = y_t == 0.0 and angle == 0.0 and [a[0] for a in rate] == [ArcKind.SINGULAR]
    if vertical:
        try:
            cand = vertical_candidate(thrust, target, limits, np.array([y_t, z_t, 0.0, 0.0, angle]))
        except StageFailure as exc:
            return _failed(str(exc), target, angle, limits, t_trans)
        issues = cand.problems(t_trans, limits)
        best, reasons = (None, issues) if issues else (cand, [])
    else:
        best, reasons = refine_with_structure_search(thrust, rate, line, target, angle, limits, t_trans, dt)
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
    n_sing = sum(a.kind == ArcKind.SINGULAR for a in rate_arcs)
    msg = (
        f"T*={duration:.6f} s, transcription {t_trans:.6f} s on {intervals} intervals; "
        f"{len(thrust_arcs)} thrust arcs, {len(rate_arcs)} rate arcs of which {n_sing} singular; "
        f"boundary error {err:.1e}; PMP residual {pmp:.1e}; refinement rounds {rounds}"
    )
    if vertical:
        msg = (
            f"T*={duration:.6f} s, transcription {t_trans:.6f} s on {intervals} intervals; "
            "vertical bang-bang with theta == 0 (closed form; the transcription's multi-start found no "
            f"faster tilted motion; minimum-principle certificate not evaluated); boundary error {err:.1e}"
        )
    return TimeOptimalSolution(
        status=SolveStatus.OPTIMAL,
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
    transcription_solver.cache_clear()
    refine_solver.cache_clear()
    piece_functions.cache_clear()


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
