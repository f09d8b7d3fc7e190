"""Figures of flights: side views with the vehicle drawn (Figs. 9, 11, 12) and one trajectory's inputs."""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.patches import Polygon

from aerobat.plotting.files import new_figure
from aerobat.quadrotor.dynamics import POS, RATE_INT, rotation_matrices

__all__ = ["draw_side_view", "maneuver_plane", "plot_side_views", "plot_trajectory", "side_view_planes"]


def maneuver_plane(states: np.ndarray) -> str:
    """``"yz"`` or ``"xz"``: the vertical plane the flight happens in (its larger horizontal rotation or motion)."""
    turns = np.abs(states[-1, RATE_INT] - states[0, RATE_INT]) if states.shape[0] else np.zeros(3)
    if max(turns[0], turns[1]) > 0.5:  # a flip: the plane normal to the flip axis
        return "xz" if turns[1] > turns[0] else "yz"
    travel = np.ptp(states[:, POS], axis=0) if states.shape[0] else np.zeros(3)
    return "xz" if travel[0] > travel[1] else "yz"


def side_view_planes(flights: Sequence[np.ndarray]) -> tuple[str, ...]:
    """The vertical plane(s) that show these flights: ``("yz",)``, ``("xz",)`` or both.

    A flip is seen along its axis; any other motion in the plane it travels in. When the flights
    turn or travel about as much along x as along y (both at least a third of the larger, and
    more than 10 cm or a quarter turn), both planes are drawn: a motion along x is never
    squashed into a pile of markers at Y = 0.
    """
    flights = [s for s in flights if s.shape[0]]
    if not flights:
        return ("yz",)
    turns = np.max([np.abs(s[-1, RATE_INT] - s[0, RATE_INT])[:2] for s in flights], axis=0)
    travel = np.max([np.ptp(s[:, POS], axis=0)[:2] for s in flights], axis=0)
    for amount, least in ((turns, 0.5), (travel, 0.1)):
        if amount.max() > least:
            if amount.min() >= amount.max() / 3 and amount.min() > least:
                return ("yz", "xz")
            # a turn about x is seen in the y-z plane; travel along x in the x-z plane
            about_x = amount[0] >= amount[1]
            return ("yz",) if (about_x if amount is turns else not about_x) else ("xz",)
    return ("yz",)


def _target_in(plane: str, target: Sequence[float] | None) -> tuple[float, float] | None:
    """The target in a plane: a 3D (X, Y, Z) target, or a (Y, Z) pair (which has X = 0)."""
    if target is None:
        return None
    values = [float(v) for v in target]
    x, y, z = values if len(values) == 3 else (0.0, values[0], values[1])
    return (y, z) if plane == "yz" else (x, z)


def draw_side_view(
    ax: Any,
    times_s: np.ndarray,
    states: np.ndarray,
    *,
    plane: str = "yz",
    every_s: float = 0.05,
    arm_m: float = 0.17,
    color: str = "C0",
    label: str | None = None,
    target: Sequence[float] | None = None,
    start: bool = True,
) -> None:
    """Side view: the path as a line and the vehicle as triangles every ``every_s`` (Figs. 9, 11, 12).

    Each triangle's base is the rotor plane, its apex points along the thrust; the glyph is at
    most 7 % of the path's extent (so the path stays visible), the vehicle's size at most.
    Positions are true positions in the plane (no offsets). ``target`` is the desired final
    position (a black cross), the start a black circle; both labelled for the legend.
    """
    h_axis = 1 if plane == "yz" else 0
    pos = states[:, POS]
    R = rotation_matrices(states)
    extent = float(max(np.ptp(pos[:, h_axis]), np.ptp(pos[:, 2]), 0.5)) if pos.shape[0] else 1.0
    arm_m = min(arm_m, 0.07 * extent)  # a glyph small enough to see the path through (not to scale)
    ax.plot(pos[:, h_axis], pos[:, 2], color=color, lw=1.6, label=label)
    if len(times_s) > 1:
        picks = np.searchsorted(times_s, np.arange(times_s[0], times_s[-1] + 1e-9, every_s))
        picks = np.unique(np.clip(np.append(picks, len(times_s) - 1), 0, len(times_s) - 1))
    else:
        picks = np.array([0])
    side = R[:, :, h_axis] if plane == "xz" else R[:, :, 1]
    for i in picks:
        c = np.array([pos[i, h_axis], pos[i, 2]])
        lateral = np.array([side[i, h_axis], side[i, 2]])
        up = np.array([R[i, h_axis, 2], R[i, 2, 2]])
        tip = c + 0.6 * arm_m * up
        ax.add_patch(Polygon([c + arm_m * lateral, c - arm_m * lateral, tip], closed=True, fill=False,
                             edgecolor=color, lw=0.6, alpha=0.6))
    if start and pos.shape[0]:
        ax.plot([pos[0, h_axis]], [pos[0, 2]], "o", color="k", ms=4, label="start")
    if target is not None:
        ax.plot([target[0]], [target[1]], "x", color="k", ms=9, mew=2, label="desired final position")
    ax.set_aspect("equal", adjustable="box" if ax.get_shared_x_axes().get_siblings(ax)[1:] else "datalim")
    ax.set_xlabel(f"{'Y' if plane == 'yz' else 'X'} [m]")
    ax.set_ylabel("Z [m] (up)")
    ax.grid(alpha=0.3)


def plot_trajectory(times_s: np.ndarray, states: np.ndarray, commands: np.ndarray, *, title: str = "") -> Any:
    """Side view in the maneuver's own plane, commands and unwrapped rotation of one trajectory."""
    fig = new_figure(figsize=(11, 6.5))
    grid = fig.add_gridspec(3, 2, width_ratios=[1.2, 1])
    ax_side = fig.add_subplot(grid[:, 0])
    plane = maneuver_plane(states)
    draw_side_view(ax_side, times_s, states, plane=plane)
    ax_side.legend(loc="best", fontsize=8)
    ax_side.set_title(f"{plane[0].upper()}–Z side view (vehicle every 50 ms; triangle apex = thrust)")
    ax_c = fig.add_subplot(grid[0, 1])
    ax_c.plot(times_s, commands[:, 0], color="k")
    ax_c.set_ylabel("collective [m/s²]")
    ax_r = fig.add_subplot(grid[1, 1], sharex=ax_c)
    for i, name in enumerate("pqr"):
        ax_r.plot(times_s, np.degrees(commands[:, 1 + i]), label=f"{name}̂")
    ax_r.set_ylabel("rate cmd [°/s]")
    ax_r.legend(loc="upper right", fontsize=8)
    ax_a = fig.add_subplot(grid[2, 1], sharex=ax_c)
    angles = np.degrees(states[:, RATE_INT] - states[0, RATE_INT])  # ∫ω dt: unwrapped, no Euler singularity
    for i, name in enumerate(("about body x (roll)", "about body y (pitch)", "about body z (yaw)")):
        ax_a.plot(times_s, angles[:, i], label=name)
    ax_a.set_ylabel("rotation ∫ω dt [°]")
    ax_a.set_xlabel("time [s]")
    ax_a.legend(loc="upper left", fontsize=8)
    if title:
        fig.suptitle(title)
    return fig


def plot_side_views(panels: Sequence[tuple[str, np.ndarray, np.ndarray]], *,
                    plane: str | Sequence[str] | None = None, title: str = "",
                    target: Sequence[float] | None = (0.0, 0.0), arm_m: float = 0.17) -> Any:
    """Figs. 9/11/12: one panel per trajectory (label, times, states), each at true positions, same scale.

    ``plane`` (``"yz"``, ``"xz"`` or both) defaults to the plane(s) the flights move in
    (:func:`side_view_planes`); with two planes, one row each. ``target`` is (Y, Z) or (X, Y, Z),
    or None when the maneuver names no final position (then none is drawn).
    """
    panels = [(label, t, s) for label, t, s in panels if s.shape[0]]
    if not panels:
        raise ValueError("no trajectory to draw")
    planes = side_view_planes([s for _, _, s in panels]) if plane is None else (
        (plane,) if isinstance(plane, str) else tuple(plane))
    lows, highs = [], []
    for p in planes:
        h = 1 if p == "yz" else 0
        every = np.concatenate([s[:, [h, 2]] for _, _, s in panels])
        low, high = every.min(axis=0) - 2 * arm_m, every.max(axis=0) + 2 * arm_m
        goal = _target_in(p, target)
        if goal is not None:
            low, high = np.minimum(low, np.asarray(goal) - 2 * arm_m), np.maximum(high, np.asarray(goal) + 2 * arm_m)
        lows.append(low)
        highs.append(high)
    ratio = max(float((hi[0] - lo[0]) / max(hi[1] - lo[1], 1e-9)) for lo, hi in zip(lows, highs, strict=True))
    panel_in = max(1.6, min(6.0, 4.0 * ratio))
    fig = new_figure(figsize=(len(panels) * (panel_in + 0.7) + 0.4, 0.4 + 4.5 * len(planes)))
    axes = np.atleast_2d(fig.subplots(len(planes), len(panels), squeeze=False, sharex="row", sharey="row"))
    from matplotlib.ticker import MaxNLocator

    # a narrow box (a tall flight: the equal aspect makes it about 4 in × ratio wide) gets fewer horizontal
    # ticks, their labels upright: labels such as "-0.25 0.00 0.25" ran together
    x_bins = max(2, int(panel_in * 1.4))
    narrow = 4.0 * ratio < 2.0
    for row, p in enumerate(planes):
        for k, (label, times, states) in enumerate(panels):
            ax = axes[row, k]
            draw_side_view(ax, times, states, plane=p, color=f"C{k}", target=_target_in(p, target), arm_m=arm_m)
            ax.set_title(label if len(planes) == 1 else f"{label}, {p[0].upper()}–Z", fontsize=9)
            ax.set_xlim(lows[row][0], highs[row][0])
            ax.set_ylim(lows[row][1], highs[row][1])
            ax.set_aspect("equal", adjustable="box")  # the limits are fixed: the box adjusts, not the data
            ax.xaxis.set_major_locator(MaxNLocator(nbins=x_bins, steps=[1, 2, 2.5, 5, 10]))
            if narrow:
                ax.tick_params(axis="x", labelrotation=90)
            if k:
                ax.set_ylabel("")
    axes[0, 0].legend(loc="best", fontsize=7)
    marks = ("× desired final position, ● start" if target is not None
             else "● start; the maneuver names no final position")
    # wrapped to the figure's width (about 13 characters per inch at 9 pt): a narrow figure clipped the title
    width = max(int(fig.get_figwidth() * 13), 30)
    text = "\n".join(textwrap.fill(line, width) for line in
                     [*(title.splitlines() if title else []), f"vehicle every 50 ms, triangle apex = thrust; {marks}"])
    fig.suptitle(text, fontsize=9)
    return fig
