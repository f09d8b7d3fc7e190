"""Regenerate the table of shipped maneuver files in docs/maneuvers.md.

Each example is designed on the nominal model and learned on the default arena (seed 1, 30
measured iterations), exactly as `aerobat learn --maneuver FILE --plant arena --seed 1
--trials 30` does. Prints a markdown table: first and last-10-mean position errors [m].

    .venv/bin/python scripts/results_maneuvers.py
"""

from __future__ import annotations

from pathlib import Path

from aerobat import Arena, NominalModel, design, hummingbird, learn
from aerobat.quadrotor.maneuvers import load_maneuver_file

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    config = hummingbird()
    print("| file | first / last-10 mean position error on the arena [m] |")
    print("|---|---|")
    for path in sorted((ROOT / "examples" / "maneuvers").glob("*.toml")):
        maneuver = load_maneuver_file(path, config.vehicle)
        plant = Arena(config, seed=1, feedback="none")
        session = learn(maneuver, design(maneuver, NominalModel(config)), plant, iterations=30)
        errors = session.position_errors_m()
        print(f"| `{path.name}` | {errors[0]:.3f} / {errors[-10:].mean():.3f} |")


if __name__ == "__main__":
    main()
