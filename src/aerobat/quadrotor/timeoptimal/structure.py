"""Reading the arc structure (bang, singular) of both inputs off a transcription."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from aerobat.quadrotor.timeoptimal.solution import ArcKind, BenchmarkLimits, StageFailure

_BANG_TOL_REL = 1e-4  # interval counts as "at the bound" within this fraction of the range
_MIN_SINGULAR_INTERVALS = 3  # shorter non-bang runs are treated as switches inside an interval
_EDGE_DEVIATION = 0.3  # edge interval of a singular run deviating by this * omega_max hides a bang arc


def _runs(labels: Sequence[ArcKind | None]) -> list[tuple[ArcKind | None, int, int]]:
    runs: list[tuple[ArcKind | None, int, int]] = []
    start = 0
    for i in range(1, len(labels) + 1):
        if i == len(labels) or labels[i] != labels[start]:
            runs.append((labels[start], start, i))
            start = i
    return runs


def _label(u: np.ndarray, lo: float, hi: float) -> list[ArcKind | None]:
    """Each sample at its upper bound (MAX), lower bound (MIN) or inside (None)."""
    tol = _BANG_TOL_REL * (hi - lo)
    return [ArcKind.MAX if v >= hi - tol else ArcKind.MIN if v <= lo + tol else None for v in u]


def _bang_segments(
    u: np.ndarray, lo: float, hi: float, dt: float, runs: list[tuple[ArcKind | None, int, int]], k: int
) -> list[tuple[ArcKind, float]]:
    """Split a short non-bang run into bang pieces ((kind, duration) list)."""
    label, i0, i1 = runs[k]
    t_max = float(np.sum((u[i0:i1] - lo) / (hi - lo))) * dt
    t_max = min(max(t_max, 0.0), (i1 - i0) * dt)
    t_min = (i1 - i0) * dt - t_max
    prev = runs[k - 1][0] if k > 0 else None
    nxt = runs[k + 1][0] if k + 1 < len(runs) else None
    amount = {ArcKind.MAX: t_max, ArcKind.MIN: t_min}
    other = {ArcKind.MAX: ArcKind.MIN, ArcKind.MIN: ArcKind.MAX}
    if prev in amount and nxt in amount and prev != nxt:
        return [(prev, amount[prev]), (nxt, amount[nxt])]
    if prev in amount and nxt in amount:  # same bang on both sides: short opposite arc
        half = amount[prev] / 2
        return [(prev, half), (other[prev], amount[other[prev]]), (prev, half)]
    if prev in amount:  # at the end of the horizon
        return [(prev, amount[prev]), (other[prev], amount[other[prev]])]
    if nxt in amount:  # at the start of the horizon
        return [(other[nxt], amount[other[nxt]]), (nxt, amount[nxt])]
    raise StageFailure("input never reaches a bound; cannot identify a bang structure")


def _merge_segments(segs: list[tuple[ArcKind, float, Any]]) -> list[list[Any]]:
    """Merge consecutive segments of equal bang kind; returns [kind, t0, t1, extra]."""
    out: list[list[Any]] = []
    t = 0.0
    for kind, dur, extra in segs:
        if dur <= 0.0:
            continue
        if out and kind == out[-1][0] and kind != ArcKind.SINGULAR:
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


def detect_structure(
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
    segs: list[tuple[ArcKind, float, Any]] = []
    for k, (lab, i0, i1) in enumerate(runs):
        if lab is not None:
            segs.append((lab, (i1 - i0) * dt, None))
        elif i1 - i0 >= _MIN_SINGULAR_INTERVALS:
            raise StageFailure(
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
        if lab is not None:
            segs.append((lab, (i1 - i0) * dt, None))
        elif i1 - i0 >= _MIN_SINGULAR_INTERVALS:
            # A singular run touching the start/end of the horizon may hide a
            # short bang arc there: its edge interval then deviates strongly
            # from the run's core (interior intervals ring around the
            # singular rate next to junctions, so use the median).
            core = float(np.median(w[i0:i1]))
            head = tail = None
            if i0 == 0 and abs(w[0] - core) > _EDGE_DEVIATION * wmax:
                kind = ArcKind.MAX if w[0] > core else ArcKind.MIN
                bound = wmax if kind == ArcKind.MAX else -wmax
                head = (kind, dt * min(1.0, abs((w[0] - core) / (bound - core))))
            if i1 == n and abs(w[-1] - core) > _EDGE_DEVIATION * wmax:
                kind = ArcKind.MAX if w[-1] > core else ArcKind.MIN
                bound = wmax if kind == ArcKind.MAX else -wmax
                tail = (kind, dt * min(1.0, abs((w[-1] - core) / (bound - core))))
            length = (i1 - i0) * dt
            if head is not None:
                segs.append((head[0], head[1], None))
                length -= head[1]
            segs.append((ArcKind.SINGULAR, length - (tail[1] if tail else 0.0), None))
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
