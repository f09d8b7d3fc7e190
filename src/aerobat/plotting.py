"""Figures (matplotlib, Agg backend; imported lazily by the CLI)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Polygon  # noqa: E402

from .dynamics import POS, rotation_matrices  # noqa: E402

__all__ = ["draw_side_view", "plot_trajectory"]


def draw_side_view(
    ax: plt.Axes,
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


def plot_trajectory(times_s: np.ndarray, states: np.ndarray, commands: np.ndarray, path: str | Path,
                    *, title: str = "") -> None:
    """Side view, commands and attitude of one trajectory, written to ``path``."""
    from .dynamics import rotation_angles

    fig = plt.figure(figsize=(11, 6.5), constrained_layout=True)
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
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_side_views(panels: Sequence[tuple[str, np.ndarray, np.ndarray]], path: str | Path, *,
                    plane: str = "yz", title: str = "", spacing_m: float | None = None,
                    target: Sequence[float] = (0.0, 0.0)) -> None:
    """Figs. 9/11/12: side views of several trajectories (label, times, states), offset for clarity.

    ``spacing_m`` defaults to the horizontal extent of the widest trajectory plus a margin.
    """
    h = 1 if plane == "yz" else 0
    if spacing_m is None:
        widths = [float(np.ptp(s[:, h])) for _, _, s in panels if s.shape[0]]
        spacing_m = max(1.2, 1.25 * max(widths, default=0.0) + 0.5)
    fig, ax = plt.subplots(figsize=(4.0 * len(panels), 4.5), constrained_layout=True)
    for k, (label, times, states) in enumerate(panels):
        if states.shape[0] == 0:
            continue
        draw_side_view(ax, times, states, plane=plane, every_s=0.01, offset_m=k * spacing_m, color=f"C{k}",
                       label=label, target=target)
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title or "side views (vehicle every 10 ms; circles: desired final position)")
    ax.grid(alpha=0.3)
    fig.savefig(path, dpi=130)
    plt.close(fig)


def plot_learning(iterations: Sequence[dict], error_names: Sequence[str], error_units: Sequence[str],
                  parameter_names: Sequence[str], parameter_units: Sequence[str], path: str | Path, *,
                  title: str = "") -> None:
    """Fig. 10: final-state errors and parameters over iterations (lost trials marked)."""
    ok = [it for it in iterations if it["status"] == "ok"]
    lost = [it for it in iterations if it["status"] != "ok"]
    idx = np.array([it["i"] for it in ok])
    errors = np.array([[np.nan if v is None else v for v in it["error"]] for it in ok]) if ok else np.empty((0, 0))
    params = np.array([it["params"] for it in iterations])
    all_idx = np.array([it["i"] for it in iterations])
    n_e, n_p = len(error_names), len(parameter_names)
    rows = max(n_e, n_p)
    fig, axes = plt.subplots(rows, 2, figsize=(10, 1.5 * rows + 1), sharex=True, constrained_layout=True)
    axes = np.atleast_2d(axes)
    for k in range(rows):
        if k < n_e and errors.size:
            ax = axes[k, 0]
            angle = error_units[k] == "rad"
            values = np.degrees(errors[:, k]) if angle else errors[:, k]
            ax.plot(idx, values, ".-", lw=0.8, ms=3)
            ax.axhline(0, color="k", lw=0.5)
            ax.set_ylabel(f"{error_names[k]} [{'°' if angle else error_units[k]}]", fontsize=8)
        else:
            axes[k, 0].axis("off")
        if k < n_p:
            ax = axes[k, 1]
            ax.plot(all_idx, params[:, k], ".-", lw=0.8, ms=3, color="C1")
            for it in lost:
                ax.axvline(it["i"], color="r", lw=0.5, alpha=0.4)
            ax.set_ylabel(f"{parameter_names[k]} [{parameter_units[k]}]", fontsize=8)
        else:
            axes[k, 1].axis("off")
    axes[0, 0].set_title("final-state errors")
    axes[0, 1].set_title("parameters (red lines: lost/rejected trials)")
    axes[-1, 0].set_xlabel("iteration")
    axes[-1, 1].set_xlabel("iteration")
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=120)
    plt.close(fig)
