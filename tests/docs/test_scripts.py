"""The scripts that regenerate the docs' numbers (scripts/*.py) at least load.

They run for minutes to an hour, so the suite does not run them; it checks that each one
imports against the current package (a script that no longer imports cannot have produced
the numbers the docs quote) and has a ``main``.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = sorted((ROOT / "scripts").glob("*.py"))


def test_there_are_scripts():
    assert len(SCRIPTS) >= 7


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: p.name)
def test_script_imports_and_has_main(path, monkeypatch):
    name = f"_aerobat_script_{path.stem}"
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, name, module)  # dataclasses look their module up by name
    spec.loader.exec_module(module)
    assert callable(getattr(module, "main", None)), f"{path.name} has no main()"


def test_an_in_memory_session_draws_its_side_views_and_learning_figure(tmp_path):
    """What results_flips.py and readme_figures.py draw: aerobat.plotting.session."""
    from aerobat import Arena, MultiFlip, NominalModel, design, hummingbird, learn, translation_maneuver
    from aerobat.plotting import save_figure
    from aerobat.plotting.session import plot_session_learning, plot_session_side_views, session_flights

    config = hummingbird()
    flip = MultiFlip(vehicle=config.vehicle, flips=1, dims=2)
    session = learn(flip, design(flip, NominalModel(config)), Arena(config, seed=1), iterations=2)
    flights = session_flights(session, config)
    assert [label.split(" (")[0] for label, _, _ in flights] == ["nominal", "first attempt", "learned"]
    assert all(states.shape[1] == 20 and len(times) == len(states) for _, times, states in flights)
    save_figure(plot_session_side_views(session, config), tmp_path / "side.png")
    save_figure(plot_session_learning(session), tmp_path / "learning.png")
    assert (tmp_path / "side.png").stat().st_size > 10_000 and (tmp_path / "learning.png").stat().st_size > 10_000
    move = translation_maneuver(config, (1.0, 0.0))  # a target away from the start is drawn where it is
    nominal_only = learn(move, design(move, NominalModel(config)), Arena(config, seed=1), iterations=1,
                         should_stop=lambda: True)
    assert [label for label, _, _ in session_flights(nominal_only, config)] == ["nominal (model)"]
