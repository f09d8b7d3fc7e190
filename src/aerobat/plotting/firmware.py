"""One program, several flights of it: the paper's model, the firmware model, the Betaflight plant.

A side view (y, z) of each flight, the rotation about the flip axis and the roll rate over time,
overlaid, so a reader sees where the models part ways with the firmware and where they agree.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from aerobat.plotting.files import new_figure

__all__ = ["plot_model_comparison"]


def plot_model_comparison(flights: Sequence[tuple[str, np.ndarray, np.ndarray]], *, title: str = "") -> Any:
    """Flights ``(label, times [s], states (n, N_STATE))`` of the same program, overlaid: y–z path, ∫p dt, p.

    Times start at the program's start; states use :mod:`aerobat.quadrotor.dynamics`' layout (the
    integrated body rates give the rotation unwrapped).
    """
    flights = [(label, np.asarray(t, dtype=float), np.asarray(x, dtype=float)) for label, t, x in flights]
    flights = [(label, t, x) for label, t, x in flights if x.shape[0]]
    if not flights:
        raise ValueError("no flight to draw")
    fig = new_figure(figsize=(12.0, 4.2))
    path, rotation, rate = fig.subplots(1, 3, gridspec_kw={"width_ratios": [1.1, 1.0, 1.0]})
    for label, t, x in flights:
        line = path.plot(x[:, 1], x[:, 2], label=label)[0]
        path.plot(x[-1, 1], x[-1, 2], "o", color=line.get_color())
        rotation.plot(t, np.degrees(x[:, 17] - x[0, 17]), color=line.get_color(), label=label)
        rate.plot(t, np.degrees(x[:, 10]), color=line.get_color(), label=label)
    path.plot(0.0, 0.0, "k+", markersize=12, label="start and target")
    path.set_xlabel("y [m]")
    path.set_ylabel("z [m]")
    path.set_aspect("equal", adjustable="datalim")
    path.set_title("path (side view)")
    path.legend(fontsize=8, loc="best")
    turns = max(float(np.max(np.abs(x[:, 17] - x[0, 17]))) for _, _, x in flights) / (2.0 * math.pi)
    rotation.set_yticks([360.0 * k * (1 if turns >= 0 else -1) for k in range(int(math.ceil(turns)) + 1)])
    rotation.set_xlabel("time [s]")
    rotation.set_ylabel("rotation ∫p dt [deg]")
    rotation.set_title("rotation about the flip axis")
    rate.set_xlabel("time [s]")
    rate.set_ylabel("roll rate p [deg/s]")
    rate.set_title("roll rate")
    for ax in (path, rotation, rate):
        ax.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    return fig
