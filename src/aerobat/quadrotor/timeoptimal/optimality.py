"""Stage 3a: the minimum-principle (PMP) check of a refined solution."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from aerobat.quadrotor.timeoptimal.solution import ArcKind, BenchmarkLimits, InputArc, eval_arcs


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


def pmp_residual(
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
        f = eval_arcs(thrust_arcs, np.full(tq.shape, 0.5 * (t0 + t1)))
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
        sign = 1.0 if arc.kind == ArcKind.MAX else -1.0
        if m.size and float(np.max(sign * sigma_f[m])) > viol:
            k = m[np.argmax(sign * sigma_f[m])]
            viol = float(sign * sigma_f[k])
            where = ("thrust", float(t_all[k]), ArcKind.MIN if arc.kind == ArcKind.MAX else ArcKind.MAX)
    for arc in rate_arcs:
        m = np.nonzero((t_all >= arc.start_s) & (t_all <= arc.end_s))[0]
        if not m.size:
            continue
        if arc.kind == ArcKind.SINGULAR:
            k = m[np.argmax(np.abs(lam_th[m]))]
            v = abs(float(lam_th[k]))
        else:
            sign = 1.0 if arc.kind == ArcKind.MAX else -1.0
            k = m[np.argmax(sign * lam_th[m])]
            v = float(sign * lam_th[k])
        if v > viol:
            viol = v
            where = ("rate", float(t_all[k]), ArcKind.MIN if lam_th[k] > 0 else ArcKind.MAX)
    return viol, where
