"""Fig. 10: final-state errors and parameters over the iterations of a learning session."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from aerobat.core.learning import IterationStatus
from aerobat.plotting.files import new_figure

__all__ = ["plot_learning"]


def plot_learning(iterations: Sequence[dict], error_names: Sequence[str], error_units: Sequence[str],
                  parameter_names: Sequence[str], parameter_units: Sequence[str], *, title: str = "",
                  error_scales: Sequence[float] | None = None,
                  parameter_descriptions: Sequence[str] | None = None) -> Any:
    """Fig. 10: final-state errors and parameters over iterations (lost trials marked).

    ``error_scales`` draws each error's band ±scale (the size of an error that matters);
    ``parameter_descriptions`` labels each parameter by its meaning as well as its name.
    """
    ok = [it for it in iterations if IterationStatus(it["status"]).measured]
    lost = [it for it in iterations if not IterationStatus(it["status"]).measured]
    idx = np.array([it["i"] for it in ok])
    errors = np.array([[np.nan if v is None else v for v in it["error"]] for it in ok]) if ok else np.empty((0, 0))
    params = np.array([it["params"] for it in iterations])
    all_idx = np.array([it["i"] for it in iterations])
    n_e, n_p = len(error_names), len(parameter_names)
    rows = max(n_e, n_p)
    fig = new_figure(figsize=(10, 1.5 * rows + 1))
    axes = np.atleast_2d(fig.subplots(rows, 2, sharex=True))
    for k in range(rows):
        if k < n_e and errors.size:
            ax = axes[k, 0]
            angle = error_units[k] == "rad"
            values = np.degrees(errors[:, k]) if angle else errors[:, k]
            if error_scales is not None:
                band = float(np.degrees(error_scales[k]) if angle else error_scales[k])
                ax.axhspan(-band, band, color="C2", alpha=0.15, lw=0, label="± error scale" if k == 0 else None)
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
            meaning = f"\n{parameter_descriptions[k]}" if parameter_descriptions else ""
            ax.set_ylabel(f"{parameter_names[k]} [{parameter_units[k]}]{meaning}", fontsize=7)
        else:
            axes[k, 1].axis("off")
    axes[0, 0].set_title("final-state errors" + (" (green: ± the error's scale)" if error_scales is not None
                                                  else ""))
    axes[0, 1].set_title("parameters (red lines: lost/rejected trials)")
    # each column's lowest panel in use carries the iteration ticks (the rows below it are switched off);
    # iterations are whole numbers: no tick at 1.5
    from matplotlib.ticker import MaxNLocator

    for col, used in ((0, n_e if errors.size else 0), (1, n_p)):
        if used:
            axes[used - 1, col].xaxis.set_major_locator(MaxNLocator(integer=True))
            axes[used - 1, col].tick_params(labelbottom=True)
            axes[used - 1, col].set_xlabel("iteration")
    if title:
        fig.suptitle(title)
    return fig
