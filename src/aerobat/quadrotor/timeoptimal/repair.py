"""Stage 3b: certification and repair — independent re-integration, arc insertion and structure search."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from aerobat.quadrotor.timeoptimal.optimality import pmp_residual
from aerobat.quadrotor.timeoptimal.refinement import line_from_adjoint, refine
from aerobat.quadrotor.timeoptimal.solution import ArcKind, BenchmarkLimits, InputArc, StageFailure

_REFINE_T_TOL_S = 1e-9  # refined T may exceed the transcription's T by at most this
_BOUNDARY_TOL = 1e-6
_PMP_TOL = 1e-6  # allowed violation of the minimum principle (adjoint scaled so lambda_0 = 1)
_MAX_STRUCTURE_TRIALS = 6


def _make_arcs(
    raw: list[list[Any]], is_rate: bool, lim: BenchmarkLimits, line: np.ndarray | None = None
) -> tuple[InputArc, ...]:
    out = []
    for kind, t0, t1, _ in raw:
        if kind == ArcKind.SINGULAR:
            if line is None:  # pragma: no cover - guarded by _Structure
                raise StageFailure("singular arc without costate line")
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
                value = lim.max_rate_rad_s if kind == ArcKind.MAX else -lim.max_rate_rad_s
            else:
                value = lim.f_max_m_s2 if kind == ArcKind.MAX else lim.f_min_m_s2
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
            raise StageFailure(f"verification integration failed: {sol.message}")
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
    thrust, rate, line, nu, rounds = refine(thrust, rate, line, target, angle, limits)
    thrust_arcs = _make_arcs(thrust, False, limits)
    rate_arcs = _make_arcs(rate, True, limits, line)
    times, states = _simulate(thrust_arcs, rate_arcs, limits)
    err = float(np.max(np.abs(states[-1] - final)))
    pmp, needle = pmp_residual(thrust_arcs, rate_arcs, nu, limits)
    wmax = limits.max_rate_rad_s
    for arc in rate_arcs:
        if arc.tangent_law is not None and pmp > _PMP_TOL:
            tt = np.linspace(arc.start_s, arc.end_s, 4001)
            rates = arc.evaluate(tt)
            k = int(np.argmax(np.abs(rates)))
            if abs(rates[k]) >= wmax * (1 - 1e-4) and 0 < k < tt.size - 1:
                # the singular rate saturates inside the arc: it must be split
                # by a bang arc there (singular -> bang -> singular)
                needle = ("rate", float(tt[k]), ArcKind.MAX if rates[k] > 0 else ArcKind.MIN)
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
        if merged and merged[-1][0] == a[0] and a[0] != ArcKind.SINGULAR:
            merged[-1][2] = a[2]
        else:
            merged.append(a)
    return merged


def _nearby_bang_bang_switch(arcs: list[list[Any]], t: float, radius: float) -> int | None:
    """Index k of a switch between opposite bang arcs k-1 -> k within ``radius`` of ``t``."""
    best, best_dist = None, radius
    for k in range(1, len(arcs)):
        if {arcs[k - 1][0], arcs[k][0]} == {ArcKind.MAX, ArcKind.MIN}:
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
    out.insert(k, [ArcKind.SINGULAR, t_sw - half, t_sw + half, None])
    return out


def _edge_variants(rate: list[list[Any]], dt: float) -> list[list[list[Any]]]:
    """Rate structures with one short bang arc next to a singular arc.

    Short bang fragments next to a singular arc are easily absorbed into the
    singular run of the transcription (they share an interval with the
    junction and are followed by ringing).  Used only when the refinement of
    the identified structure fails outright (no multipliers to guide it).
    """
    out = []
    other = {ArcKind.MAX: ArcKind.MIN, ArcKind.MIN: ArcKind.MAX}
    delta = 0.25 * dt
    for idx, arc in enumerate(rate):
        if arc[0] != ArcKind.SINGULAR or arc[2] - arc[1] <= 4 * delta:
            continue
        for side in ("start", "end"):
            nb = idx - 1 if side == "start" else idx + 1
            kinds = [ArcKind.MAX, ArcKind.MIN] if not 0 <= nb < len(rate) else [other[rate[nb][0]]]
            for kind in kinds:
                t = arc[1] + delta / 2 if side == "start" else arc[2] - delta / 2
                out.append(_insert_arc(rate, t, kind, delta))
    return out


def vertical_candidate(
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
    kinds = [ArcKind.MAX, ArcKind.MIN] if z > 0 else [ArcKind.MIN, ArcKind.MAX]
    if [a[0] for a in thrust] != kinds:
        raise StageFailure(f"vertical move: unexpected thrust structure {[a[0] for a in thrust]}")
    raw_thrust = [[kinds[0], 0.0, t1, None], [kinds[1], t1, t1 + t2, None]]
    raw_rate = [[ArcKind.SINGULAR, 0.0, t1 + t2, None]]
    thrust_arcs = _make_arcs(raw_thrust, False, limits)
    rate_arcs = (InputArc(kind=ArcKind.SINGULAR, start_s=0.0, end_s=t1 + t2, value=0.0, tangent_law=(0.0, 0.0)),)
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


def refine_with_structure_search(
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
        except StageFailure as exc:
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
            has_sing = ArcKind.SINGULAR in [a[0] for a in new_ra]
            adj_line = line_from_adjoint(cand.nu, cand.duration)
            # start from the transcription's costate line (or, without one,
            # the rejected candidate's adjoint line); the other is the fallback
            first = line if line is not None else (cand.line if cand.line is not None else adj_line)
            second = cand.line if cand.line is not None else adj_line
            alt = (new_th, new_ra, second, None) if has_sing else None
            queue.insert(0, (new_th, new_ra, first if has_sing else None, alt))
    return None, reasons
