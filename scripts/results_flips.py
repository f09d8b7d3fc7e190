"""Regenerate the flip and translation numbers and figures of docs/results.md (about three minutes).

Sections "Nominal designs", "Learning the 3D triple flip", "The 2D single flip" and the learnable
translation's tables under "Time-optimal translation"; every learning run is the paper's open loop
(``feedback="none"``) on the default arena.

Run: .venv/bin/python scripts/results_flips.py
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from aerobat import hummingbird, translation_maneuver
from aerobat.core.design import design
from aerobat.core.learning import learn
from aerobat.core.rules import RuleChoice
from aerobat.experiments.setup import build_rule
from aerobat.plants import Arena
from aerobat.plotting import save_figure
from aerobat.plotting.session import plot_session_learning, plot_session_side_views
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


def figures(session, name: str) -> None:
    """``{name}_side_views.png`` (model, first attempt, learned) and ``{name}_learning.png`` into docs/figures."""
    save_figure(plot_session_side_views(session, CONFIG), OUT / f"{name}_side_views.png", dpi=130)
    learning = plot_session_learning(session, title=f"{session.maneuver.name} on the arena")
    save_figure(learning, OUT / f"{name}_learning.png")


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
                figures(s, "triple_flip_3d")
                errs = np.array([it.error for it in s.measured])
                print(f"(tsvd, seed 1: first {first:.3f} m, iterations 21-30 mean {late:.3f} m = "
                      f"{100 * late / first:.0f} % of the first, mean |angle errors| there "
                      f"{np.array2string(np.degrees(np.abs(errs[-10:][:, [4, 7, 8]]).mean(axis=0)), precision=2)}°, "
                      f"p8 {s.final_params[8]:+.3f} rad)")
        lates = np.array([r[2] for r in rows])
        print(f"| {kind} | " + " | ".join(f"{r[2]:.3f}" for r in rows) +
              f" | {lates.mean():.3f} | first {np.mean([r[1] for r in rows]):.2f} m (seed 1 {rows[0][1]:.2f}); "
              f"max angle {max(r[3] for r in rows):.1f}°; p8 {np.mean([r[4] for r in rows]):+.3f}; "
              f"pinned {sum(r[5] for r in rows)} |")
    print("\n## 2D single flip at 800°/s on the arena (Fig. 11)")
    m1 = MultiFlip(vehicle=CONFIG.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
    d1 = design(m1, MODEL)
    s1 = learn(m1, d1, Arena(CONFIG, seed=1, feedback="none"), iterations=20)
    first, late, ang = summarize(s1, [0, 2], [4])
    print(f"first {first:.3f} m, mean last 10 {late:.3f} m, angle {ang:.2f}°")
    figures(s1, "single_flip_2d")
    translation()


def translation() -> None:
    print("\n## The (5, 5) m translation as a learnable maneuver, 30 iterations")
    m = translation_maneuver(CONFIG, (5.0, 5.0))
    d = design(m, MODEL)
    print(f"nominal full-model duration {d.duration_s:.3f} s ({d.status})")
    firsts, lates = [], []
    for seed in range(7):
        s = learn(m, d, Arena(CONFIG, seed=seed, feedback="none"), iterations=30)
        pos = s.position_errors_m()
        firsts.append(pos[0])
        lates.append(pos[-10:].mean())
        print(f"seed {seed}: first {pos[0]:.2f} m, iterations 21-30 {lates[-1]:.3f} m "
              f"({100 * lates[-1] / pos[0]:.0f} % of the first), learned duration "
              f"{m.program(s.final_params).duration_s:.3f} s")
        if seed == 1:
            figures(s, "translation")
    print("| first attempt [m] | " + " | ".join(f"{v:.2f}" for v in firsts) + " |")
    print("| iterations 21–30 [m] | " + " | ".join(f"{v:.3f}" for v in lates) + " |")
    print(f"mean {np.mean(lates):.3f} m, worst {np.max(lates):.3f} m")
    for rule in ("tsvd", "kalman", "kalman+isc"):
        means = [learn(m, d, Arena(CONFIG, seed=seed, feedback="none"), iterations=30,
                       rule=build_rule(RuleChoice.parse(rule), d, CONFIG)).position_errors_m()[-10:].mean()
                 for seed in range(1, 7)]
        print(f"rule {rule}, seeds 1-6: mean {np.mean(means):.3f} m")


if __name__ == "__main__":
    main()
