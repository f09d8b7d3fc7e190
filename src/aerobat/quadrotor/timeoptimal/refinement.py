"""Stage 2: switching-time refinement with bilinear-tangent singular arcs (IPOPT, closed-form pieces)."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from aerobat.quadrotor.timeoptimal.solution import ArcKind, BenchmarkLimits, StageFailure
from aerobat.quadrotor.timeoptimal.transcription import run_solver

_PRUNE_TOL_S = 1e-7  # arcs shorter than this are removed and the refinement re-solved
_GL_PANELS = 4  # composite Gauss-Legendre on singular pieces: worst-case error
_GL_NODES = 32  # ~1e-14 for admissible arcs up to 2 s (|omega| <= 10 rad/s)


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
        self.has_singular = ArcKind.SINGULAR in self.rate_kinds
        if self.has_singular and line is None:
            raise StageFailure("singular rate arc without a costate-line guess")
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
        return self.lim.f_max_m_s2 if self.thrust_kinds[i] == ArcKind.MAX else self.lim.f_min_m_s2

    def rate_value(self, j: int) -> float:
        return self.lim.max_rate_rad_s if self.rate_kinds[j] == ArcKind.MAX else -self.lim.max_rate_rad_s


@functools.lru_cache(maxsize=1)
def piece_functions() -> tuple[Any, Any]:
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
def refine_solver(signature: tuple[tuple[str, str, int], ...], limits_key: tuple[float, ...]) -> tuple[Any, int, int]:
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
    bang, sing = piece_functions()
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
        f = f_max if fk == ArcKind.MAX else f_min
        if sid < 0:
            xk = bang(xk, f, wmax if rk == ArcKind.MAX else -wmax, d[k], g)
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
        (st.thrust_kinds[i], st.rate_kinds[j], j if st.rate_kinds[j] == ArcKind.SINGULAR else -1) for i, j in st.pieces
    )
    solver, n_eq, n_in = refine_solver(signature, st.lim._key())
    npc = len(st.pieces)
    nl = 4 if st.has_singular else 0
    lbg = np.zeros(n_eq + n_in)
    ubg = np.concatenate([np.zeros(n_eq), np.full(n_in, np.inf)])
    lbx = np.concatenate([np.zeros(npc), np.full(nl, -1.0)])
    ubx = np.concatenate([np.full(npc, np.inf), np.full(nl, 1.0)])
    x0 = np.concatenate([st.d0, st.line0 if st.has_singular else []])
    res = run_solver(solver, x0=x0, p=[target[0], target[1], final_angle], lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
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
        raise StageFailure("refinement removed every arc of an input")
    for k in range(1, len(merged)):  # keep the timeline contiguous
        merged[k][1] = merged[k - 1][2]
    return merged, changed


def line_from_adjoint(nu: np.ndarray, t_final: float) -> np.ndarray:
    """Costate line ``(a, b, c, d)`` of ``lambda_v(t)`` from ``lambda(T) = nu``.

    ``lambda_y, lambda_z`` are constant, so ``lambda_vy(t) = nu_vy + nu_y (T - t)``
    and ``lambda_vz(t) = nu_vz + nu_z (T - t)``.
    """
    v = np.array([nu[2] + nu[0] * t_final, -nu[0], nu[3] + nu[1] * t_final, -nu[1]])
    return v / np.linalg.norm(v)


def _line_mismatch(v: np.ndarray, w: np.ndarray) -> float:
    return float(min(np.max(np.abs(v - w)), np.max(np.abs(v + w))))


def refine(
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
            raise StageFailure(f"switching-time optimisation did not converge (IPOPT: {status})")
        thrust, rate = _arcs_from_pieces(st, d)
        thrust, ch1 = _prune(thrust)
        rate, ch2 = _prune(rate)
        if ch1 or ch2:
            line = line_opt if ArcKind.SINGULAR in [a[0] for a in rate] else None
            continue
        t_opt = float(np.sum(d))
        if best is not None and t_opt > best[0] - 1e-10:
            if t_opt < best[0]:
                best = (t_opt, thrust, rate, line_opt, nu)
            break  # re-initialisation did not help: keep the best
        best = (t_opt, thrust, rate, line_opt, nu)
        if line_opt is None:
            break
        line_nu = line_from_adjoint(nu, t_opt)
        if _line_mismatch(line_opt, line_nu) < 1e-7:
            break
        line = line_nu
    if best is None:
        raise StageFailure("switching-time optimisation kept removing arcs (no stable structure)")
    _, thrust, rate, line, nu = best
    return thrust, rate, line, nu, rounds
