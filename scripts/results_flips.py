"""Regenerate the flip numbers and figures of docs/results.md (about a minute).

Run: .venv/bin/python scripts/results_flips.py
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from aerobat import hummingbird
from aerobat.cli import _learning_figures
from aerobat.core.design import design
from aerobat.core.learning import learn
from aerobat.plants import Arena
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel

OUT = Path(__file__).resolve().parents[1] / "docs" / "figures"
CONFIG = hummingbird()
MODEL = NominalModel(CONFIG)


def position_errors(session, idx):
    return np.array([np.linalg.norm(it.error[idx]) for it in session.measured])


def summarize(session, idx, angles):
    pos = position_errors(session, idx)
    errs = np.array([it.error for it in session.measured])
    late = slice(len(pos) - 10, len(pos))
    return pos[0], pos[late].mean(), np.degrees(np.abs(errs[late][:, angles]).mean(axis=0)).max()


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    print("## Designs (nominal model)")
    for flips, rate, dims, ramp in [(3, 1800, 2, 0.0), (3, 1800, 2, 0.1), (1, 800, 2, 0.1), (3, 1800, 3, 0.1)]:
        m = MultiFlip(vehicle=CONFIG.vehicle, flips=flips, max_rate_rad_s=math.radians(rate), dims=dims,
                      ramp_collective_s=ramp)
        d = design(m, MODEL)
        print(f"| {dims}D {flips}x {rate}°/s, ramp {ramp} s | {d.status} | {d.residual_norm:.1e} | "
              f"{np.array2string(d.p_nominal[:5], precision=4)} | {d.duration_s:.3f} s | {d.condition_number:.3g} |")
    print("\n## 3D triple flip on the arena: correction matrices, 30 iterations")
    m = MultiFlip(vehicle=CONFIG.vehicle, flips=3, dims=3)
    for kind in ("inverse", "damped", "tsvd"):
        d = design(m, MODEL, correction=kind)
        rows = []
        for seed in range(1, 7):
            s = learn(m, d, Arena(CONFIG, seed=seed, feedback="none"), iterations=30)
            first, late, ang = summarize(s, [0, 2, 5], [4, 7, 8])
            pinned = int(np.sum(np.isclose(s.final_params, [p.lower for p in m.parameters]) |
                                np.isclose(s.final_params, [p.upper for p in m.parameters])))
            rows.append((seed, first, late, ang, s.final_params[8], pinned))
            if kind == "tsvd" and seed == 1:
                _learning_figures(s, CONFIG, OUT)
                (OUT / "side_views.png").rename(OUT / "triple_flip_3d_side_views.png")
                (OUT / "learning.png").rename(OUT / "triple_flip_3d_learning.png")
        lates = np.array([r[2] for r in rows])
        print(f"| {kind} | " + " | ".join(f"{r[2]:.3f}" for r in rows) +
              f" | {lates.mean():.3f} | first {np.mean([r[1] for r in rows]):.2f} m; "
              f"max angle {max(r[3] for r in rows):.1f}°; p8 {np.mean([r[4] for r in rows]):+.3f}; "
              f"pinned {sum(r[5] for r in rows)} |")
    print("\n## 2D single flip at 800°/s on the arena (Fig. 11)")
    m1 = MultiFlip(vehicle=CONFIG.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
    d1 = design(m1, MODEL)
    s1 = learn(m1, d1, Arena(CONFIG, seed=1, feedback="none"), iterations=20)
    first, late, ang = summarize(s1, [0, 2], [4])
    print(f"first {first:.3f} m, mean last 10 {late:.3f} m, angle {ang:.2f}°")
    _learning_figures(s1, CONFIG, OUT)
    (OUT / "side_views.png").rename(OUT / "single_flip_2d_side_views.png")
    (OUT / "learning.png").rename(OUT / "single_flip_2d_learning.png")


if __name__ == "__main__":
    main()
