"""Figures of the method's own results (no vehicle): matplotlib is imported only when one is drawn.

Every function takes ``ax=`` (draws a new figure when None), returns the figure, and never
chooses a matplotlib backend: that is the application's business.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["new_axes", "plot_position_errors"]


def new_axes(ax: Any = None, *, figsize: tuple[float, float] = (6.0, 3.5)) -> tuple[Any, Any]:
    """``(figure, axes)``: the given axes and their figure, or a new figure with one axes."""
    if ax is not None:
        return ax.figure, ax
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, constrained_layout=True)
    return fig, fig.add_subplot()


def plot_position_errors(errors_m: np.ndarray, *, ax: Any = None, tolerance_m: float | None = None,
                         title: str = "") -> Any:
    """Position error norm per measured iteration, on a log scale; returns the figure."""
    fig, ax = new_axes(ax)
    errors = np.asarray(errors_m, dtype=float)
    ax.semilogy(np.arange(1, errors.size + 1), errors, "o-", ms=3, label="position error")
    if tolerance_m is not None:
        ax.axhline(tolerance_m, color="k", lw=0.8, ls="--", label=f"tolerance {tolerance_m:g} m")
    ax.set_xlabel("measured iteration")
    ax.set_ylabel("position error [m]")
    if title:
        ax.set_title(title)
    ax.legend(fontsize=8)
    return fig
