"""Reports of stored sessions: their JSON form, their figures, drawn from stored data alone."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from aerobat.core.codec import Form, encode
from aerobat.core.learning import IterationStatus, SessionStatus
from aerobat.core.outcomes import iteration_json, session_document
from aerobat.core.registry import from_spec
from aerobat.errors import ConfigError
from aerobat.experiments.designing import design_model_of
from aerobat.plotting.files import save_figure
from aerobat.plotting.learning import plot_learning
from aerobat.plotting.vehicle import plot_side_views
from aerobat.quadrotor.dynamics import STATE_NAMES
from aerobat.quadrotor.simulate import simulate
from aerobat.quadrotor.vehicle import vehicle_from_table
from aerobat.store import Store

if TYPE_CHECKING:
    from aerobat.core.learning import Session

__all__ = ["finite_or_none", "load_session", "session_figures", "session_from_json", "session_json",
           "replay_notes", "session_replay"]


def finite_or_none(values: Any) -> list[float | None]:
    """JSON-ready floats: non-finite values become None."""
    return [float(v) if math.isfinite(v) else None for v in values]


_NOT_EXPORTED = ("id", "maneuver_id", "vehicle_id", "converged", "compute_s", "evaluations")
"""A stored design's fields ``export --format json`` leaves out: the store's keys, what ``status`` says, and the
design's effort (its timing and simulation count, kept in the store; left out so that exports of one result
compare equal)."""


def session_json(store: Store, session_id: int, *, trajectories: bool = False, full: bool = False) -> dict[str, Any]:
    """The session as JSON: the keys of ``session.json`` (and, with ``full``, everything stored)."""
    rec = store.session(session_id)
    mrec = store.maneuver(rec.maneuver_id)
    drec = store.design(rec.design_id)
    prec = store.plant(rec.plant_id)
    iterations = []
    for it in store.iterations(session_id, trajectories=trajectories):
        entry = iteration_json(it)
        if full:
            entry["final_state"] = None if it.final_state is None else finite_or_none(it.final_state)
            entry["start_state"] = None if it.start_state is None else finite_or_none(it.start_state)
            entry["recorded_at"] = it.recorded_at
            entry["info"] = it.info
        if trajectories:
            entry["trajectory"] = None if it.times_s is None or it.states is None else {
                "columns": ["t_s", *STATE_NAMES],
                "times_s": it.times_s.tolist(), "states": [finite_or_none(row) for row in it.states]}
        iterations.append(entry)
    data = session_document(
        maneuver=mrec.spec, plant=prec.kind, error_names=list(mrec.error_names),
        error_units=list(mrec.error_units), parameter_names=list(mrec.parameter_names),
        parameter_units=list(mrec.parameter_units), p_nominal=drec.p_nominal.tolist(), iterations=iterations,
        final_params=rec.current_params.tolist(), status=rec.display_state, message=rec.message,
        session_id=session_id, db=str(store.path), maneuver_name=mrec.name, error_kinds=list(mrec.error_kinds),
        design_model=dict(zip(("kind", "description"), design_model_of(store.vehicle(drec.vehicle_id).config),
                              strict=True)),
        start_params=rec.start_params.tolist(), seed=rec.seed, rule=rec.rule, target_iterations=rec.target_iterations,
        started_at=rec.started_at, ended_at=rec.ended_at, warm_start_from=rec.warm_start_from, study_id=rec.study_id)
    if full:
        data["plant_config"] = prec.config
        data["vehicle"] = store.vehicle(prec.vehicle_id).config
        data["command"] = list(rec.command)
        data["tags"] = list(rec.tags)
        data["notes"] = [{"at": at, "text": text} for at, text in rec.notes]
        # the stored design through the codec, as the library's Design.to_json_dict keeps it (its record's
        # keys and the timings aside), with the vehicle it was designed on
        data["design"] = {**encode(drec, (f.name for f in dataclasses.fields(drec) if f.name not in _NOT_EXPORTED),
                                   form=Form.JSON), "vehicle": store.vehicle(drec.vehicle_id).config}
    return data


def session_figures(store: Store, session_id: int, out: Path) -> list[str]:
    """Write ``learning.png`` and ``side_views.png`` from stored data alone; notes on what could not be drawn."""
    rec = store.session(session_id)
    mrec = store.maneuver(rec.maneuver_id)
    drec = store.design(rec.design_id)
    notes = []
    panels = []
    target = mrec.spec.get("target_yz", (0.0, 0.0))
    descriptions: list[str] | None = None
    try:
        maneuver = from_spec(mrec.spec, source=f"session {session_id} maneuver")
        config = vehicle_from_table(store.vehicle(drec.vehicle_id).config, source=f"session {session_id} vehicle")
        nominal = simulate(maneuver.program(drec.p_nominal), config)
        panels.append(("nominal (model)", nominal.times_s, nominal.states))
        target = getattr(maneuver, "target_yz", target)
        descriptions = [p.description for p in maneuver.parameters]
    except ConfigError as exc:
        notes.append(f"note: nominal trajectory not drawn: {exc}")
    records = store.iterations(session_id)
    measured = [it.index for it in records if it.status is IterationStatus.OK and it.trajectory_rows > 0]
    if measured:
        loaded = store.iterations(session_id, trajectories=True, indices=[measured[0], measured[-1]])
        by_index = {it.index: it for it in loaded}
        first, last = by_index[measured[0]], by_index[measured[-1]]
        for label, it in ((f"first attempt (iteration {first.index})", first),
                          (f"learned (iteration {last.index})", last)):
            if it.times_s is not None and it.states is not None:
                panels.append((label, it.times_s, it.states))
    if panels:  # the plane(s) the flights move in: a maneuver along x is drawn in X–Z, not piled up at Y = 0
        save_figure(plot_side_views(panels, title=f"{mrec.name} on {rec.plant_kind}, {_loop(store, rec)}",
                                    target=_final_position(mrec.spec, target)),
                    out / "side_views.png", dpi=130)
    if records:
        iterations = [{"i": it.index, "status": it.status, "params": it.params.tolist(),
                       "error": finite_or_none(it.error)} for it in records]
        save_figure(plot_learning(iterations, mrec.error_names, mrec.error_units, mrec.parameter_names,
                                  mrec.parameter_units, title=f"{mrec.name} on {rec.plant_kind}",
                                  error_scales=mrec.error_scales, parameter_descriptions=descriptions),
                    out / "learning.png")
    else:
        notes.append(f"note: session {session_id} has no iterations: learning.png not drawn")
    return notes


IDENTIFICATION_KIND = "identification"
"""The maneuver kind of a stored identification (``aerobat identify --db``): fixed programs, no design."""


def _measured_with_trajectories(store: Store, session_id: int) -> list[int]:
    return [it.index for it in store.iterations(session_id)
            if it.status is IterationStatus.OK and it.trajectory_rows > 0]


def replay_notes(store: Store, session_id: int, iterations: list[int] | None = None) -> list[str]:
    """What :func:`session_replay` draws of a session and what it cannot (``aerobat replay`` prints them)."""
    rec = store.session(session_id)
    kind = store.maneuver(rec.maneuver_id).kind
    measured = _measured_with_trajectories(store, session_id)
    notes = []
    if rec.study_id is not None:
        notes.append(f"session {session_id} is one of study {rec.study_id}'s sessions")
    if kind == IDENTIFICATION_KIND:
        shown = len(iterations) if iterations is not None else len(measured)
        notes.append(f"session {session_id} is an identification: the replay shows {shown} of its "
                     f"{len(measured)} measured flights (fixed programs: there is no designed flight to show)")
    elif not measured:
        why = " (a study keeps no trajectories of its sessions)" if rec.study_id is not None else ""
        notes.append(f"session {session_id} has no measured trajectories{why}: the replay shows the model's "
                     f"flight only, no measured trial")
    return notes
def _loop(store: Store, rec: Any) -> str:
    """``open loop`` or ``tracking feedback``: what the onboard loop did during the measured flights."""
    scheme = (store.plant(rec.plant_id).config.get("feedback") or {}).get("scheme", "none")
    return "open loop" if scheme in (None, "none") else f"{scheme} feedback"


def _final_position(spec: dict[str, Any], target: Any) -> tuple[float, ...] | None:
    """The desired final position a side view marks: a translation's target, a flip's start, else none known."""
    kind = str(spec.get("kind", ""))
    if "target_yz" in spec or kind == "translation":
        return (0.0, float(target[0]), float(target[1]))
    if kind in ("flip", "multiflip") or "flips" in spec:
        return (0.0, 0.0, 0.0)
    return None


def session_replay(store: Store, session_id: int, path: Path, *, iterations: list[int] | None = None) -> Path:
    """Write the 3D replay of a stored session: the nominal model's flight and measured iterations.

    ``iterations`` are the iterations to show (default: the first and the last measured one;
    for an identification, every measured flight — it has no model flight). :func:`replay_notes`
    says what the replay leaves out.
    """
    from aerobat.plotting.replay import replay_figure, write_replay_html

    rec = store.session(session_id)
    mrec = store.maneuver(rec.maneuver_id)
    drec = store.design(rec.design_id)
    identification = mrec.kind == IDENTIFICATION_KIND
    config = vehicle_from_table(store.vehicle(drec.vehicle_id).config, source=f"session {session_id} vehicle")
    flights = []
    measured = _measured_with_trajectories(store, session_id)
    if iterations is None:
        iterations = measured if identification else sorted({measured[0], measured[-1]}) if measured else []
    missing = [i for i in iterations if i not in measured]
    if missing:
        raise ConfigError(f"session {session_id}: iteration(s) {', '.join(map(str, missing))} have no measured "
                          f"trajectory; measured: {', '.join(map(str, measured)) or 'none'}")
    target_m = None
    if not identification:
        maneuver = from_spec(mrec.spec, source=f"session {session_id} maneuver")
        nominal = simulate(maneuver.program(drec.p_nominal), config)
        flights.append(("nominal (model)", nominal.times_s, nominal.states))
        start = np.asarray(maneuver.initial_state())[:3]
        target = getattr(maneuver, "target_yz", None)
        target_m = (start[0], float(target[0]), float(target[1])) if target is not None else None
    elif not iterations:
        raise ConfigError(f"session {session_id} is an identification without measured flights: nothing to replay")
    for it in store.iterations(session_id, trajectories=True, indices=iterations):
        if it.times_s is not None and it.states is not None:
            label = ("flight" if identification else "first attempt" if it.index == measured[0] else
                     "learned" if it.index == measured[-1] else "iteration")
            flights.append((f"{label} (iteration {it.index})", it.times_s, it.states))
    fig = replay_figure(flights, title=f"session {session_id}: {mrec.name} on {rec.plant_kind}",
                        arm_m=config.vehicle.arm_length_m, target_m=target_m)
    return write_replay_html(fig, path)


def _ended(status: str) -> SessionStatus:
    """How an exported session stands: a ``running`` (or ``killed``) one as ``interrupted``."""
    try:
        state = SessionStatus(status)
    except ValueError:  # killed: its process is gone
        return SessionStatus.INTERRUPTED
    return SessionStatus.INTERRUPTED if state is SessionStatus.RUNNING else state


def load_session(store: Store, session_id: int) -> Session:
    """A stored session as a :class:`~aerobat.core.learning.Session` (its iterations without trials)."""
    from aerobat.config import check_type
    from aerobat.core.learning import Session

    check_type("store", store, Store, "a Store")
    rec = store.session(session_id)
    maneuver = from_spec(store.maneuver(rec.maneuver_id).spec, source=f"{store.path}: session {session_id}")
    design = store.design(rec.design_id).design(maneuver)
    iterations = tuple(it.iteration() for it in store.iterations(session_id))
    status = SessionStatus.INTERRUPTED if rec.state is SessionStatus.RUNNING else rec.state
    return Session(maneuver, design, rec.plant_kind, iterations, rec.current_params, status, rec.message, math.nan)


def session_from_json(data: dict[str, Any]) -> Session:
    """A session from ``aerobat export … --format json`` (or ``show --json``) output."""
    import numpy as np

    from aerobat.core.design import Design, DesignStatus
    from aerobat.core.learning import Iteration, Session

    if not isinstance(data, dict):
        raise ConfigError(f"session JSON: expected an object (a dict), got {type(data).__name__}")
    if "maneuver" in data and "design" not in data:
        raise ConfigError("session JSON: no 'design' field; session.json is a summary, use the output of "
                          "`aerobat export ID --format json` or `aerobat show ID --json`")
    try:
        maneuver = from_spec(data["maneuver"], source="session JSON maneuver")
        # the export's design is the stored one without what only its computation knew (its wall time,
        # how many simulations) and with ``converged`` as its status says; arrays as the codec reads them
        table = {"compute_s": math.nan, "evaluations": 0, **data["design"]}
        table["converged"] = DesignStatus(table["status"]) is DesignStatus.CONVERGED
        design = Design.from_json_dict(maneuver, table)
        iterations = tuple(Iteration.from_json_dict(it) for it in data["iterations"])
        status = _ended(data["status"])
        return Session(maneuver, design, data["plant"], iterations, np.asarray(data["final_params"]), status,
                       data["message"], float(data.get("wall_s", math.nan)))
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
        raise ConfigError(f"session JSON: missing or malformed field: {type(exc).__name__}: {exc}") from None
