"""Figures of flights: side views with the vehicle drawn (Figs. 9, 11, 12) and one trajectory's inputs."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.patches import Polygon

from aerobat.plotting.files import new_figure
from aerobat.quadrotor.dynamics import POS, RATE_INT, rotation_matrices

__all__ = ["draw_side_view", "maneuver_plane", "plot_side_views", "plot_trajectory"]


def maneuver_plane(states: np.ndarray) -> str:
    """``"yz"`` or ``"xz"``: the vertical plane the flight happens in (its larger horizontal rotation or motion)."""
    turns = np.abs(states[-1, RATE_INT] - states[0, RATE_INT]) if states.shape[0] else np.zeros(3)
    if max(turns[0], turns[1]) > 0.5:  # a flip: the plane normal to the flip axis
        return "xz" if turns[1] > turns[0] else "yz"
    travel = np.ptp(states[:, POS], axis=0) if states.shape[0] else np.zeros(3)
    return "xz" if travel[0] > travel[1] else "yz"


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


def plot_side_views(panels: Sequence[tuple[str, np.ndarray, np.ndarray]], *, plane: str | None = None,
                    title: str = "", target: Sequence[float] = (0.0, 0.0), arm_m: float = 0.17) -> Any:
    """Figs. 9/11/12: one panel per trajectory (label, times, states), each at true positions, same scale.

    ``plane`` defaults to the first trajectory's own plane (:func:`maneuver_plane`).
    """
    panels = [(label, t, s) for label, t, s in panels if s.shape[0]]
    if not panels:
        raise ValueError("no trajectory to draw")
    plane = plane or maneuver_plane(panels[0][2])
    h = 1 if plane == "yz" else 0
    every = np.concatenate([s[:, [h, 2]] for _, _, s in panels])
    low, high = every.min(axis=0) - 2 * arm_m, every.max(axis=0) + 2 * arm_m
    low = np.minimum(low, np.asarray(target) - 2 * arm_m)
    high = np.maximum(high, np.asarray(target) + 2 * arm_m)
    ratio = float((high[0] - low[0]) / max(high[1] - low[1], 1e-9))
    fig = new_figure(figsize=(len(panels) * (max(1.6, min(6.0, 4.0 * ratio)) + 0.7) + 0.4, 4.9))
    axes = np.atleast_1d(fig.subplots(1, len(panels), sharex=True, sharey=True))
    for k, (ax, (label, times, states)) in enumerate(zip(axes, panels, strict=True)):
        draw_side_view(ax, times, states, plane=plane, color=f"C{k}", target=target, arm_m=arm_m)
        ax.set_title(label, fontsize=9)
        ax.set_xlim(low[0], high[0])
        ax.set_ylim(low[1], high[1])
        if k:
            ax.set_ylabel("")
    axes[0].legend(loc="best", fontsize=7)
    fig.suptitle(title + ("\n" if title else "") + "vehicle every 50 ms (triangle apex = thrust); "
                 "× desired final position, ● start", fontsize=9)
    return fig
