"""3D replay: one self-contained HTML file that animates flights in the browser.

The vehicle is drawn as it flies — its two arms and four rotor discs — along each
trajectory, with a time slider, play and pause, and the browser's own camera controls
(rotate, zoom, pan). The file holds plotly.js itself (the copy the ``plotly`` package ships,
``pip install 'aerobat[replay]'``): it opens offline, without a server. A small script in the
page records any JavaScript error and sets ``#aerobat-replay-status`` to ``ok`` once the
scene has been drawn, so a headless browser can check it.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from aerobat.errors import require
from aerobat.quadrotor.dynamics import POS, rotation_matrices

__all__ = ["replay_figure", "write_replay_html"]

_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b")
_STATUS_SCRIPT = """
<div id="aerobat-replay-status" style="display:none">loading</div>
<script>
(function () {
  var status = document.getElementById("aerobat-replay-status");
  var errors = [];
  window.addEventListener("error", function (event) { errors.push(String(event.message)); });
  var original = console.error;
  console.error = function () {
    errors.push(Array.prototype.join.call(arguments, " "));
    original.apply(console, arguments);
  };
  function check(tries) {
    var plot = document.querySelector(".js-plotly-plot");
    var drawn = plot && plot.querySelector("canvas, .gl-container, .main-svg");
    if (errors.length) { status.textContent = "error: " + errors.join(" | "); return; }
    if (drawn && plot._fullData && plot._fullData.length) { status.textContent = "ok"; return; }
    if (tries > 200) { status.textContent = "error: nothing was drawn"; return; }
    setTimeout(function () { check(tries + 1); }, 50);
  }
  window.addEventListener("load", function () { check(0); });
})();
</script>
"""


def _vehicle_lines(states: np.ndarray, arm_m: float) -> tuple[list[float | None], ...]:
    """x, y, z of the arms (a cross) and rotor discs of each state, as polylines separated by None."""
    R = rotation_matrices(states)
    angles = np.linspace(0.0, 2.0 * np.pi, 13)
    radius = 0.35 * arm_m
    xs: list[float | None] = []
    ys: list[float | None] = []
    zs: list[float | None] = []
    for k in range(states.shape[0]):
        c = states[k, POS]
        body_x, body_y = R[k, :, 0], R[k, :, 1]
        for a, b in ((c + arm_m * body_x, c - arm_m * body_x), (c + arm_m * body_y, c - arm_m * body_y)):
            xs += [a[0], b[0], None]
            ys += [a[1], b[1], None]
            zs += [a[2], b[2], None]
        for hub in (c + arm_m * body_x, c - arm_m * body_x, c + arm_m * body_y, c - arm_m * body_y):
            ring = hub[None, :] + radius * (np.cos(angles)[:, None] * body_x + np.sin(angles)[:, None] * body_y)
            xs += [*ring[:, 0].tolist(), None]
            ys += [*ring[:, 1].tolist(), None]
            zs += [*ring[:, 2].tolist(), None]
    return xs, ys, zs


def _at(times_s: np.ndarray, states: np.ndarray, t: float) -> np.ndarray:
    k = int(np.clip(np.searchsorted(times_s, t), 0, len(times_s) - 1))
    return states[k: k + 1]


def replay_figure(flights: Sequence[tuple[str, np.ndarray, np.ndarray]], *, title: str = "", arm_m: float = 0.17,
                  fps: float = 30.0, target_m: Sequence[float] | None = None) -> Any:
    """A plotly figure animating each (label, times [s], states) flight; returns the figure."""
    go = require("plotly.graph_objects", extra="replay", purpose="the 3D replay")
    flights = [(label, np.asarray(t, dtype=float), np.asarray(s, dtype=float)) for label, t, s in flights
               if len(t) > 1]
    if not flights:
        raise ValueError("nothing to replay: no flight has a trajectory")
    end = max(float(t[-1]) for _, t, _ in flights)
    start = min(float(t[0]) for _, t, _ in flights)
    frame_times = np.arange(start, end + 1e-9, 1.0 / fps)
    paths, vehicles = [], []
    for k, (label, times, states) in enumerate(flights):
        color = _COLORS[k % len(_COLORS)]
        pos = states[:, POS]
        paths.append(go.Scatter3d(x=pos[:, 0], y=pos[:, 1], z=pos[:, 2], mode="lines", name=f"{label} (path)",
                                  line={"color": color, "width": 3}, opacity=0.6))
        x, y, z = _vehicle_lines(_at(times, states, start), arm_m)
        vehicles.append(go.Scatter3d(x=x, y=y, z=z, mode="lines", name=label, line={"color": color, "width": 6}))
    static = list(paths)
    if target_m is not None:
        static.append(go.Scatter3d(x=[target_m[0]], y=[target_m[1]], z=[target_m[2]], mode="markers",
                                   name="desired final position", marker={"size": 5, "color": "black",
                                                                          "symbol": "x"}))
    n_static = len(static)
    frames = []
    for t in frame_times:
        data = []
        for _, times, states in flights:
            x, y, z = _vehicle_lines(_at(times, states, float(t)), arm_m)
            data.append(go.Scatter3d(x=x, y=y, z=z))
        frames.append(go.Frame(data=data, name=f"{t:.3f}", traces=list(range(n_static, n_static + len(flights)))))
    every = [np.concatenate([s[:, POS] for _, _, s in flights])]
    low, high = every[0].min(axis=0) - arm_m, every[0].max(axis=0) + arm_m
    span = float(np.max(high - low))
    centre = 0.5 * (low + high)
    axes = {name: {"range": [centre[i] - 0.55 * span, centre[i] + 0.55 * span], "title": f"{name} [m]"}
            for i, name in enumerate("xyz")}
    steps = [{"method": "animate", "label": f"{t:.2f}",
              "args": [[f"{t:.3f}"], {"mode": "immediate", "frame": {"duration": 0, "redraw": True},
                                      "transition": {"duration": 0}}]} for t in frame_times]
    fig = go.Figure(data=[*static, *vehicles], frames=frames)
    fig.update_layout(
        title=title or "aerobat replay",
        scene={"xaxis": axes["x"], "yaxis": axes["y"], "zaxis": axes["z"], "aspectmode": "cube"},
        legend={"x": 0.0, "y": 1.0},
        updatemenus=[{"type": "buttons", "direction": "left", "x": 0.1, "y": 0.02, "showactive": False,
                      "buttons": [
                          {"label": "play", "method": "animate",
                           "args": [None, {"frame": {"duration": int(1000 / fps), "redraw": True},
                                           "fromcurrent": True, "transition": {"duration": 0}}]},
                          {"label": "pause", "method": "animate",
                           "args": [[None], {"mode": "immediate", "frame": {"duration": 0, "redraw": False}}]}]}],
        sliders=[{"active": 0, "x": 0.25, "len": 0.7, "y": 0.02, "currentvalue": {"prefix": "t = ", "suffix": " s"},
                  "steps": steps}],
        margin={"l": 0, "r": 0, "t": 40, "b": 0},
    )
    return fig


def write_replay_html(fig: Any, path: str | Path) -> Path:
    """Write ``fig`` as one self-contained HTML file (plotly.js inside, no network); returns the path."""
    from aerobat.plotting.files import write_text

    html = fig.to_html(include_plotlyjs=True, full_html=True, auto_play=False,
                       config={"displaylogo": False, "responsive": True})
    html = html.replace("</body>", _STATUS_SCRIPT + "</body>", 1)
    return write_text(path, html)
