"""Figures of the time-optimal benchmark (Sect. 9): one solution, and minimum time over a grid of targets."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from aerobat.core.figures import new_axes
from aerobat.errors import ConfigError
from aerobat.plotting.files import new_figure
from aerobat.quadrotor.timeoptimal import TimeOptimalSolution, switch_times

__all__ = ["plot_map", "plot_solution"]


def plot_solution(solution: TimeOptimalSolution) -> Any:
    """Input programs and the path with attitude snapshots of a solved benchmark; returns the figure.

    Raises
    ------
    ConfigError
        If the solution is not ``ok`` (nothing to draw).
    """
    if not solution.ok or solution.duration_s <= 0:
        raise ConfigError(f"solution is invalid for plotting: status={solution.status.value!r}")
    lim = solution.limits
    t_final = solution.duration_s
    tt = np.linspace(0.0, t_final, 2001)
    f, w = solution.inputs(tt)
    fig = new_figure(figsize=(11, 6))
    grid = fig.add_gridspec(2, 2)  # one grid: the layout keeps the path panel off the input panels
    ax_f = fig.add_subplot(grid[0, 0])
    ax_w = fig.add_subplot(grid[1, 0], sharex=ax_f)
    ax_p = fig.add_subplot(grid[:, 1])
    ax_f.plot(tt, f, drawstyle="steps-post")
    ax_f.axhline(lim.f_max_m_s2, ls=":", c="gray")
    ax_f.axhline(lim.f_min_m_s2, ls=":", c="gray")
    ax_f.set_ylabel("thrust f [m/s²]")
    ax_f.set_title(f"T* = {t_final:.4f} s")
    ax_w.plot(tt, np.degrees(w), drawstyle="steps-post")  # degrees, as --body-rate-deg-s
    ax_w.axhline(math.degrees(lim.max_rate_rad_s), ls=":", c="gray")
    ax_w.axhline(-math.degrees(lim.max_rate_rad_s), ls=":", c="gray")
    ax_w.set_ylabel("rate ω [°/s]")
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
    ax_p.set_aspect("equal", adjustable="box")  # "datalim" let the panel grow over the left column
    ax_p.margins(0.08)  # the vehicle glyphs at the ends stay inside, and no tick label is clipped
    ax_p.set_xlabel("y [m]")
    # the path's labels on its outer side: between the columns, "z [m]" ran into the tick labels
    ax_p.yaxis.tick_right()
    ax_p.yaxis.set_label_position("right")
    ax_p.set_ylabel("z [m]")
    ax_p.set_title("path (vehicle every 0.05 s, red: thrust direction)")
    return fig


def plot_map(ys: np.ndarray, zs: np.ndarray, durations: np.ndarray, *, ax: Any = None) -> Any:
    """Contour plot of minimum time over target positions; returns the figure.

    A grid with one row or column (or fewer than two finite cells) is drawn as points
    coloured by time: a contour needs a 2-D grid.

    Parameters
    ----------
    ys, zs : array_like
        Grid coordinates, m.
    durations : array_like
        ``(len(zs), len(ys))`` minimum times (nan cells are left blank).
    """
    ys = np.asarray(ys, dtype=float).ravel()
    zs = np.asarray(zs, dtype=float).ravel()
    dur = np.ma.masked_invalid(np.asarray(durations, dtype=float))
    if dur.shape != (zs.size, ys.size):
        raise ConfigError(f"durations shape {dur.shape} is invalid: expected (len(zs), len(ys)) = "
                          f"{(zs.size, ys.size)}")
    fig, ax = new_axes(ax, figsize=(6.5, 5.5))
    if ys.size >= 2 and zs.size >= 2 and int(dur.count()) >= 4 and np.ptp(dur.compressed()) > 0:
        cs = ax.contourf(ys, zs, dur, levels=20, cmap="viridis")
        ax.contour(ys, zs, dur, levels=list(cs.levels)[::2], colors="k", linewidths=0.4)
        fig.colorbar(cs, ax=ax, label="T* [s]")
    else:
        yy, zz = np.meshgrid(ys, zs)
        ok = ~np.ma.getmaskarray(dur)
        points = ax.scatter(yy[ok], zz[ok], c=dur.compressed(), cmap="viridis", s=60)
        if ok.any():
            fig.colorbar(points, ax=ax, label="T* [s]")
        ax.plot(yy[~ok], zz[~ok], "rx", label="solve failed")
    ax.set_xlabel("target y [m]")
    ax.set_ylabel("target z [m]")
    ax.set_aspect("equal")
    ax.set_title("time-optimal hover-to-hover duration")
    return fig
