"""Figures of studies: robustness over sampled vehicles, design envelopes, update rules side by side."""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from aerobat.core.figures import new_axes
from aerobat.plotting.files import new_figure

__all__ = ["plot_envelope", "plot_rules", "plot_success_by_property", "plot_trials_to_tolerance"]


def plot_trials_to_tolerance(trials_to_tolerance: Sequence[int | None], tolerance_m: float, *, ax: Any = None) -> Any:
    """Histogram of the trial at which each vehicle first met the tolerance (None: never)."""
    fig, ax = new_axes(ax, figsize=(6, 4))
    reached = [t for t in trials_to_tolerance if t is not None]
    if reached:
        ax.hist(reached, bins=[float(b) for b in np.arange(0.5, max(reached) + 1.5)], color="C0")
    never = sum(1 for t in trials_to_tolerance if t is None)
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))  # trial and vehicle counts: no half-integer ticks
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel(f"trials until the position error first falls below {tolerance_m:g} m")
    ax.set_ylabel("vehicles")
    ax.set_title(f"{len(reached)} reached the tolerance, {never} never did")
    return fig


def plot_success_by_property(properties: Sequence[Mapping[str, float]], success: Sequence[bool],
                             names: Sequence[str], trials: Sequence[float | None] | None = None) -> Any:
    """Success rate per quintile of each sampled property (one panel per property); with ``trials`` (each
    vehicle's trials to the tolerance, None if never), their median per quintile on a second axis: when
    every vehicle succeeds the success rate is flat at 100 %, and how fast it learned is what varies."""
    ok = np.asarray(success, dtype=bool)
    took = None if trials is None else np.array([np.nan if t is None else float(t) for t in trials])
    cols = 4
    rows = math.ceil(len(names) / cols)
    fig = new_figure(figsize=(3.2 * cols, 2.6 * rows + 0.4))
    axes = np.ravel(fig.subplots(rows, cols))
    for ax, name in zip(axes, names, strict=False):
        values = np.array([p[name] for p in properties], dtype=float)
        edges = np.unique(np.quantile(values, np.linspace(0, 1, 6))) if values.size else np.array([])
        if len(edges) < 2:
            ax.set_title(f"{name} (constant)", fontsize=8)
            continue
        which = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, len(edges) - 2)
        rate = [ok[which == k].mean() if np.any(which == k) else np.nan for k in range(len(edges) - 1)]
        centers = 0.5 * (edges[1:] + edges[:-1])
        ax.plot(centers, np.array(rate) * 100, "o-")
        ax.set_title(name, fontsize=8)
        ax.set_ylim(-5, 105)
        ax.set_ylabel("success [%]", fontsize=8, color="C0")
        if took is not None and np.isfinite(took).any():
            median = [np.nanmedian(took[(which == k) & np.isfinite(took)]) if np.any((which == k) & np.isfinite(took))
                      else np.nan for k in range(len(edges) - 1)]
            right = ax.twinx()
            right.plot(centers, median, "s--", color="C1", ms=4)
            right.set_ylabel("median trials to tolerance", fontsize=7, color="C1")
            right.tick_params(labelsize=7, colors="C1")
    for ax in axes[len(names):]:
        ax.axis("off")
    everyone = ok.size > 0 and bool(ok.all())
    fig.suptitle("every vehicle met the tolerance: success is 100 % in every quintile; the squares (median trials "
                 "to reach it) show what varies" if everyone and took is not None else
                 "success per quintile of each sampled property" + (" (squares: median trials to the tolerance)"
                                                                     if took is not None else ""), fontsize=9)
    return fig


_ENVELOPE_TITLES = {"feasible": "which flips the vehicle can fly (nominal design)",
                    "duration_s": "hover-to-hover duration [s]",
                    "apex_m": "apex height above the start [m]",
                    "condition_number": "condition number of J (log10)"}


def plot_envelope(name: str, flips: Sequence[int], rates_deg_s: Sequence[float], values: np.ndarray, *,
                  ax: Any = None, continued: Sequence[tuple[int, float]] = ()) -> Any:
    """One quantity of a design envelope over (flip count, max rate); each cell centred on its sample.

    ``feasible`` is drawn with two colours and a legend (and grey for a job that failed); the
    other quantities with a colour bar (the condition number on a log scale). ``continued``: the
    (flips, rate) cells whose design converged only by continuation from their neighbours, marked "c".
    """
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    fig, ax = new_axes(ax, figsize=(6.5, 3.6))
    data = np.asarray(values, dtype=float)
    rates = np.asarray(rates_deg_s, dtype=float)
    half = 0.5 * (rates[1] - rates[0]) if rates.size > 1 else 50.0
    extent = (rates[0] - half, rates[-1] + half, flips[0] - 0.5, flips[-1] + 0.5)
    if name == "feasible":
        shown = np.where(np.isnan(data), 2.0, data)
        cmap = ListedColormap(["#d62728", "#2ca02c", "#bbbbbb"])
        ax.imshow(shown, origin="lower", aspect="auto", cmap=cmap, vmin=-0.5, vmax=2.5, extent=extent,
                  interpolation="nearest")
        handles = [Patch(color="#2ca02c", label="design converged"),
                   Patch(color="#d62728", label="no design found (from the\nguess, nor by continuation)")]
        if continued:
            handles.append(Patch(color="white", label="c: converged by continuation\nfrom its neighbours in rate"))
        if np.isnan(data).any():
            handles.append(Patch(color="#bbbbbb", label="job failed (see aerobat studies)"))
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    else:
        shown = np.log10(data) if name == "condition_number" else data
        image = ax.imshow(shown, origin="lower", aspect="auto", cmap="viridis", extent=extent,
                          interpolation="nearest")
        fig.colorbar(image, ax=ax)
    for n, rate in continued:
        ax.text(rate, n, "c", ha="center", va="center", fontsize=9, color="white" if name == "feasible" else "k")
    ax.set_xticks(rates)
    ax.set_xticklabels([f"{r:g}" for r in rates], rotation=45, fontsize=7)
    ax.set_yticks(list(flips))
    ax.set_xlabel("max rate [deg/s] (cells centred on the sampled rates)")
    ax.set_ylabel("flips")
    ax.set_title(_ENVELOPE_TITLES.get(name, name))
    return fig


def plot_rules(curves: Mapping[str, Sequence[Sequence[float]]], trials: int, tolerance_m: float, *,
               ax: Any = None) -> Any:
    """Median and quartiles of the position error per trial, one line per method."""
    fig, ax = new_axes(ax, figsize=(8, 5))
    x = np.arange(1, trials + 1)
    for k, (method, runs) in enumerate(curves.items()):
        if not runs:
            continue
        data = np.full((len(runs), trials), np.nan)
        for i, c in enumerate(runs):
            data[i, : min(trials, len(c))] = c[:trials]
        if np.all(np.isnan(data)):  # listed in the legend all the same, so legend and table agree
            ax.plot([], [], color=f"C{k}", ls="none", marker="x", label=f"{method}: no trial measured")
            continue
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a trial no run reached is a gap in the line
            med = np.nanmedian(data, axis=0)
            q1, q3 = np.nanpercentile(data, 25, axis=0), np.nanpercentile(data, 75, axis=0)
        # markers too: a median with gaps (trials some runs lost) is isolated points, which a bare line hides
        ax.plot(x, med, ".-", color=f"C{k}", ms=3, label=method)
        ax.fill_between(x, q1, q3, color=f"C{k}", alpha=0.15)
    ax.axhline(tolerance_m, color="k", lw=0.8, ls="--", label=f"tolerance {tolerance_m:g} m")
    ax.set_yscale("log")
    from matplotlib.ticker import MaxNLocator, NullFormatter

    ax.yaxis.set_minor_formatter(NullFormatter())  # one set of labels on the log axis, the decades
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("trial")
    ax.set_ylabel("position error [m], median and quartiles")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8)
    else:  # every run failed before measuring a trial: say so rather than draw an empty panel
        ax.text(0.5, 0.5, "no run measured a trial (see the table's failures)", transform=ax.transAxes,
                ha="center", va="center", color="C3")
    return fig


def plot_feedback(curves: Mapping[str, Mapping[str, Sequence[Sequence[float]]]], trials: int,
                  tolerance_m: float) -> Any:
    """One panel per scenario: median and quartiles of the position error per trial, one line per scheme."""
    import matplotlib.pyplot as plt

    n = max(1, len(curves))
    cols = min(n, 2)
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(6.5 * cols, 4.2 * rows), squeeze=False, sharey=True)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    for k, (ax, (scenario, by_scheme)) in enumerate(zip(axes.flat, curves.items(), strict=False)):
        plot_rules(by_scheme, trials, tolerance_m, ax=ax)
        ax.set_title(f"scenario {scenario}")
        if k % cols:
            ax.set_ylabel("")  # the shared axis is labelled once, on the left
    fig.suptitle(f"position error per trial with each onboard feedback scheme, {trials} trials; "
                 f"dashed: the {tolerance_m:g} m tolerance")
    fig.tight_layout()
    return fig
