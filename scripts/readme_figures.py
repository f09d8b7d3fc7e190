"""Regenerate the README's figures: the demo's side views and learning curves, and an animated flip.

    .venv/bin/python scripts/readme_figures.py            # writes docs/figures/readme/

It learns the 3D triple flip at 1800 deg/s on the arena as `make demo` does (seed 1, 30 measured
iterations) but in the paper's pure open loop (`--feedback none`; the demo adds the onboard
tracking feedback, whose first attempt misses far less), draws the figures `aerobat plot` draws,
and animates the nominal flight, the first attempt and the learned one side by side (a GIF, 25
frames per second of maneuver time shown at 10 frames per second: 2.5× slower than flown).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aerobat import Arena, MultiFlip, NominalModel, design, hummingbird, learn
from aerobat.plotting import new_figure, save_figure
from aerobat.plotting.session import plot_session_learning, plot_session_side_views, session_flights
from aerobat.plotting.vehicle import draw_side_view

OUT = Path(__file__).resolve().parents[1] / "docs" / "figures" / "readme"


def main() -> None:
    from matplotlib.animation import FuncAnimation, PillowWriter

    OUT.mkdir(parents=True, exist_ok=True)
    config = hummingbird()
    flip = MultiFlip(vehicle=config.vehicle, flips=3, max_rate_rad_s=np.radians(1800), dims=3)
    nominal = design(flip, NominalModel(config))
    session = learn(flip, nominal, Arena(config, seed=1, feedback="none"), iterations=30)
    flights = session_flights(session, config)
    save_figure(plot_session_side_views(session, config), OUT / "side_views.png", dpi=110)
    save_figure(plot_session_learning(session, title=f"{flip.name} on the arena"), OUT / "learning.png", dpi=90)
    fig = new_figure(figsize=(9.0, 4.2))
    axes = fig.subplots(1, 3, sharex=True, sharey=True)
    end = max(float(t[-1]) for _, t, _ in flights)
    frames = np.arange(0.0, end + 1e-9, 0.04)

    def draw(t: float) -> None:
        for k, (ax, (label, times, states)) in enumerate(zip(axes, flights, strict=True)):
            ax.clear()
            shown = times <= t + 1e-9
            if shown.sum() >= 2:
                draw_side_view(ax, times[shown], states[shown], plane="yz", every_s=10.0, color=f"C{k}",
                               target=(0.0, 0.0), start=False)
            ax.set_xlim(-0.8, 0.8)
            ax.set_ylim(-0.8, 1.6)
            ax.set_title(label, fontsize=8)
        fig.suptitle(f"{flip.name}: t = {t:.2f} s (× desired final position)", fontsize=9)

    animation = FuncAnimation(fig, draw, frames=frames)
    animation.save(OUT / "triple_flip.gif", writer=PillowWriter(fps=10), dpi=70)
    errors = session.position_errors_m()
    print(f"first attempt {errors[0]:.3f} m, last-10 mean {errors[-10:].mean():.3f} m; figures in {OUT}")


if __name__ == "__main__":
    main()
