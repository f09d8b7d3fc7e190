"""Figures of an identification: every trial measured against the fitted model."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from aerobat.plotting.files import new_figure

if TYPE_CHECKING:
    from aerobat.quadrotor.identification import VehicleFit

__all__ = ["plot_identification"]

_AXES = ("x", "y", "z")
_ANGLES = ("roll", "pitch", "yaw")


def plot_identification(fit: VehicleFit, *, title: str = "") -> Any:
    """One row per trial: positions (left) and body rotations (right), measured (dots) and fitted (lines).

    Returns the figure; the caller saves it (:func:`aerobat.plotting.save_figure`).
    """
    rows = max(len(fit.trials), 1)
    fig = new_figure(figsize=(11.0, 1.6 * rows + 0.9))
    grid = fig.add_gridspec(rows, 2)
    for k, trial in enumerate(fit.trials):
        ax_p = fig.add_subplot(grid[k, 0])
        ax_a = fig.add_subplot(grid[k, 1], sharex=ax_p)
        t = trial.times_s
        for i, name in enumerate(_AXES):
            ax_p.plot(t, trial.measured_position_m[:, i] * 100.0, ".", ms=2.0, color=f"C{i}", alpha=0.6)
            ax_p.plot(t, trial.fitted_position_m[:, i] * 100.0, "-", lw=1.0, color=f"C{i}", label=name)
        measured = np.degrees(trial.measured_angles_rad)
        fitted = np.degrees(trial.fitted_angles_rad)
        for i, name in enumerate(_ANGLES):
            ax_a.plot(t, measured[:, i], ".", ms=2.0, color=f"C{i}", alpha=0.6)
            ax_a.plot(t, fitted[:, i], "-", lw=1.0, color=f"C{i}", label=name)
        ax_p.set_ylabel("position [cm]", fontsize=8)
        ax_a.set_ylabel("body rotation [°]", fontsize=8)
        ax_p.set_title(f"{trial.trial.name}: {trial.position_rms_m * 1e3:.1f} mm RMS", fontsize=9, loc="left")
        ax_a.set_title(f"{math.degrees(trial.angle_rms_rad):.2f}° RMS", fontsize=9, loc="left")
        for ax in (ax_p, ax_a):
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
        if k == 0:
            ax_p.legend(loc="upper right", fontsize=7, ncol=3)
            ax_a.legend(loc="upper right", fontsize=7, ncol=3)
        if k == rows - 1:
            ax_p.set_xlabel("time from the trigger [s]", fontsize=8)
            ax_a.set_xlabel("time from the trigger [s]", fontsize=8)
    verdict = "accepted" if fit.acceptable else "refused: " + "; ".join(fit.problems)
    fig.suptitle(title or f"identification of {fit.config.name} — measured (dots) and fitted (lines): "
                 f"{fit.position_rms_m * 1e3:.2f} mm, {math.degrees(fit.angle_rms_rad):.2f}° RMS; {verdict}",
                 fontsize=10)
    return fig
