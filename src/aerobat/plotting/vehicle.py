"""Figures of flights: side views with the vehicle drawn (Figs. 9, 11, 12) and one trajectory's inputs."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.patches import Polygon

from aerobat.core.figures import new_axes
from aerobat.plotting.files import new_figure
from aerobat.quadrotor.dynamics import POS, rotation_angles, rotation_matrices

__all__ = ["draw_side_view", "plot_side_views", "plot_trajectory"]


def draw_side_view(
    ax: Any,
    times_s: np.ndarray,
    states: np.ndarray,
    *,
    plane: str = "yz",
    every_s: float = 0.01,
    arm_m: float = 0.17,
    offset_m: float = 0.0,
    color: str = "C0",
    label: str | None = None,
    target: Sequence[float] | None = None,
) -> None:
    """Side view with the vehicle drawn as triangles (the paper's Figs. 9, 11, 12).

    Each triangle's base is the rotor plane (width ≈ the vehicle), its apex points
    along the thrust axis, sampled every ``every_s`` seconds (100 Hz like the paper).
    """
    h_axis = 1 if plane == "yz" else 0
    pos = states[:, POS]
    R = rotation_matrices(states)
    ax.plot(pos[:, h_axis] + offset_m, pos[:, 2], color=color, lw=0.8, label=label)
    if len(times_s) > 1:
        picks = np.searchsorted(times_s, np.arange(times_s[0], times_s[-1] + 1e-9, every_s))
        picks = np.unique(np.clip(picks, 0, len(times_s) - 1))
    else:
        picks = np.array([0])
    side = R[:, :, h_axis] if plane == "xz" else R[:, :, 1]
    for i in picks:
        c = np.array([pos[i, h_axis] + offset_m, pos[i, 2]])
        lateral = np.array([side[i, h_axis], side[i, 2]])
        up = np.array([R[i, h_axis, 2], R[i, 2, 2]])
        a = c + arm_m * lateral
        b = c - arm_m * lateral
        tip = c + 0.6 * arm_m * up
        ax.add_patch(Polygon([a, b, tip], closed=True, fill=False, edgecolor=color, lw=0.5, alpha=0.8))
    if target is not None:
        ax.plot([target[0] + offset_m], [target[1]], "o", mfc="none", mec="tab:blue", ms=10)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"{'Y' if plane == 'yz' else 'X'} [m]")
    ax.set_ylabel("Z [m]")


def plot_trajectory(times_s: np.ndarray, states: np.ndarray, commands: np.ndarray, *, title: str = "") -> Any:
    """Side view, commands and attitude of one trajectory; returns the figure."""
    fig = new_figure(figsize=(11, 6.5))
    grid = fig.add_gridspec(3, 2, width_ratios=[1.2, 1])
    ax_side = fig.add_subplot(grid[:, 0])
    draw_side_view(ax_side, times_s, states, every_s=0.02)
    ax_side.set_title("Y–Z side view (vehicle every 20 ms)")
    ax_c = fig.add_subplot(grid[0, 1])
    ax_c.plot(times_s, commands[:, 0], color="k")
    ax_c.set_ylabel("collective [m/s²]")
    ax_r = fig.add_subplot(grid[1, 1], sharex=ax_c)
    for i, name in enumerate("pqr"):
        ax_r.plot(times_s, np.degrees(commands[:, 1 + i]), label=f"{name}̂")
    ax_r.set_ylabel("rate cmd [°/s]")
    ax_r.legend(loc="upper right", fontsize=8)
    ax_a = fig.add_subplot(grid[2, 1], sharex=ax_c)
    angles = np.degrees(rotation_angles(states))
    for i, name in enumerate(("roll", "pitch", "yaw")):
        ax_a.plot(times_s, angles[:, i], label=name)
    ax_a.set_ylabel("rotation [°]")
    ax_a.set_xlabel("time [s]")
    ax_a.legend(loc="upper left", fontsize=8)
    if title:
        fig.suptitle(title)
    return fig


def plot_side_views(panels: Sequence[tuple[str, np.ndarray, np.ndarray]], *, ax: Any = None,
                    plane: str = "yz", title: str = "", spacing_m: float | None = None,
                    target: Sequence[float] = (0.0, 0.0)) -> Any:
    """Figs. 9/11/12: side views of several trajectories (label, times, states), offset for clarity.

    ``spacing_m`` defaults to the horizontal extent of the widest trajectory plus a margin.
    """
    h = 1 if plane == "yz" else 0
    if spacing_m is None:
        widths = [float(np.ptp(s[:, h])) for _, _, s in panels if s.shape[0]]
        spacing_m = max(1.2, 1.25 * max(widths, default=0.0) + 0.5)
    fig, ax = new_axes(ax, figsize=(4.0 * len(panels), 4.5))
    for k, (label, times, states) in enumerate(panels):
        if states.shape[0] == 0:
            continue
        draw_side_view(ax, times, states, plane=plane, every_s=0.01, offset_m=k * spacing_m, color=f"C{k}",
                       label=label, target=target)
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title or "side views (vehicle every 10 ms; circles: desired final position)")
    ax.grid(alpha=0.3)
    return fig
