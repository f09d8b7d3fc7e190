"""Figures of a learning session held in memory (a :class:`~aerobat.core.learning.Session` from ``learn``).

A stored session is drawn from the store instead (:func:`aerobat.experiments.reports.session_figures`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from aerobat.core.learning import Session
from aerobat.plotting.learning import plot_learning
from aerobat.plotting.vehicle import plot_side_views
from aerobat.quadrotor.simulate import simulate
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["plot_session_learning", "plot_session_side_views", "session_flights"]


def session_flights(session: Session, model: VehicleConfig) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(label, times [s], states) of the nominal flight on ``model``, the first measured attempt and the last one."""
    nominal = simulate(session.maneuver.program(session.design.p_nominal), model)
    flights = [("nominal (model)", nominal.times_s, nominal.states)]
    measured = [it for it in session.measured if it.trial is not None]
    if measured:
        first, last = measured[0], measured[-1]
        assert first.trial is not None and last.trial is not None
        flights += [(f"first attempt (iteration {first.index})", first.trial.times_s, first.trial.states),
                     (f"learned (iteration {last.index})", last.trial.times_s, last.trial.states)]
    return flights


def plot_session_side_views(session: Session, model: VehicleConfig, *, title: str | None = None) -> Any:
    """Figs. 9/11/12 for ``session``: the nominal flight, the first attempt and the learned one, side by side."""
    target = tuple(getattr(session.maneuver, "target_yz", (0.0, 0.0)))
    return plot_side_views(session_flights(session, model), title=session.maneuver.name if title is None else title,
                           target=target)


def plot_session_learning(session: Session, *, title: str | None = None) -> Any:
    """Fig. 10 for ``session``: its errors (with their scales) and parameters over the iterations."""
    data = session.to_json_dict()
    maneuver = session.maneuver
    return plot_learning(data["iterations"], data["error_names"], data["error_units"], data["parameter_names"],
                         data["parameter_units"],
                         title=f"{maneuver.name} on {session.plant_name}" if title is None else title,
                         error_scales=[e.scale for e in maneuver.errors],
                         parameter_descriptions=[p.description for p in maneuver.parameters])
