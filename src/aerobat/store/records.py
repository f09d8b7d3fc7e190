"""What the store returns: frozen records of vehicles, plants, maneuvers, designs, sessions, iterations, studies."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from enum import StrEnum
from typing import Any

import numpy as np

from aerobat.core.design import Design, DesignStatus
from aerobat.core.maneuver import ErrorKind, Maneuver
from aerobat.core.notes import IterationNote
from aerobat.core.outcomes import Iteration, IterationStatus, SessionStatus, step_to
from aerobat.core.plant import Signals

__all__ = [
    "DesignRecord",
    "IterationRecord",
    "JobStatus",
    "ManeuverRecord",
    "PlantRecord",
    "SessionRecord",
    "SessionSummary",
    "StudyJobRecord",
    "StudyKind",
    "StudyRecord",
    "VehicleRecord",
]


@dataclass(frozen=True)
class VehicleRecord:
    """A vehicle configuration (physical constants and onboard controller).

    Attributes
    ----------
    id : row id.
    name : the configuration's name.
    config : ``{"name", "vehicle": {...}, "controller": {...}}`` as written by the caller.
    """

    id: int
    name: str
    config: dict[str, Any]


@dataclass(frozen=True)
class PlantRecord:
    """A plant configuration: its kind, the vehicle it flies and its settings table."""

    id: int
    kind: str
    vehicle_id: int
    config: dict[str, Any]


@dataclass(frozen=True)
class ManeuverRecord:
    """A maneuver specification (``Maneuver.spec()``) with its parameter and error names.

    Attributes
    ----------
    spec : the specification table; :func:`aerobat.core.registry.from_spec` rebuilds the maneuver.
    parameter_names, parameter_units : per parameter.
    error_names, error_units, error_scales : per error component.
    error_kinds : per error component, what it measures (:class:`~aerobat.core.maneuver.ErrorKind`).
    """

    id: int
    kind: str
    name: str
    spec: dict[str, Any]
    parameter_names: tuple[str, ...]
    parameter_units: tuple[str, ...]
    error_names: tuple[str, ...]
    error_units: tuple[str, ...]
    error_scales: tuple[float, ...]
    error_kinds: tuple[ErrorKind, ...]

    @property
    def position_mask(self) -> tuple[bool, ...]:
        """Which error components are positions (their norm is the reported position error)."""
        return tuple(kind is ErrorKind.POSITION for kind in self.error_kinds)


@dataclass(frozen=True)
class DesignRecord:
    """A nominal design, every array exactly as computed (float64).

    Attributes
    ----------
    p_guess, p_nominal : (n_par,) guess p^g and solution p⁰.
    residual : (n_err,) e(p⁰) on the model.
    jacobian : (n_err, n_par) J.
    correction : (n_par, n_err) C.
    singular_values : of J in scaled coordinates.
    status : :class:`~aerobat.core.design.DesignStatus`.
    """

    id: int
    maneuver_id: int
    vehicle_id: int
    p_guess: np.ndarray
    p_nominal: np.ndarray
    residual: np.ndarray
    residual_norm: float
    jacobian: np.ndarray
    correction: np.ndarray
    correction_kind: str
    singular_values: np.ndarray
    condition_number: float
    rank: int
    converged: bool
    status: DesignStatus
    message: str
    duration_s: float
    compute_s: float
    evaluations: int
    created_at: str

    def design(self, maneuver: Maneuver) -> Design:
        """The :class:`~aerobat.core.design.Design` this record holds, for ``maneuver``, arrays bit for bit."""
        own = {f.name: getattr(self, f.name) for f in fields(Design) if f.name != "maneuver"}
        return Design(maneuver=maneuver, **own)


@dataclass(frozen=True)
class SessionRecord:
    """A learning session and its running summary.

    Attributes
    ----------
    seed : the plant's seed (None if it has none).
    rule : the update rule and schedule, e.g. ``{"name": "paper", "schedule": {"kind": "paper", "minimum": 0.1}}``.
    target_iterations : measured iterations the session aims for.
    start_params : (n_par,) parameters of the first trial (p⁰, or a warm start).
    warm_start_from : the session whose learned parameters ``start_params`` are, if any.
    state : :class:`~aerobat.core.learning.SessionStatus`.
    display_state : ``state``, except ``killed`` for a ``running`` session whose process is gone.
    owner : ``host:pid:start`` of the process that runs (or last ran) it.
    command : the command-line arguments that started it.
    n_records, n_measured : trials stored, and those that gave a measurement (``ok``).
    last_index, last_correction : counters to resume from.
    last_error : (n_err,) error of the last measured trial (None before the first).
    last_position_error_m : 2-norm of its position components [m].
    current_params : (n_par,) parameters the next trial flies.
    study_id : the study this session belongs to, if any.
    vehicle, plant_vehicle : names of the design model and of the vehicle the plant flew.
    feedback : the plant's onboard feedback scheme (``none``: the paper's open loop).
    tags, notes : the user's tags, and notes as ``(recorded_at, text)`` (``aerobat tag`` / ``note``).
    """

    id: int
    maneuver_id: int
    design_id: int
    plant_id: int
    seed: int | None
    rule: dict[str, Any]
    target_iterations: int
    start_params: np.ndarray
    warm_start_from: int | None
    state: SessionStatus
    display_state: str
    message: str
    started_at: str
    updated_at: str
    ended_at: str | None
    host: str | None
    pid: int | None
    owner: str | None
    command: tuple[str, ...]
    aerobat_version: str | None
    n_records: int
    n_measured: int
    last_index: int
    last_correction: int
    last_error: np.ndarray | None
    last_position_error_m: float | None
    current_params: np.ndarray
    maneuver_name: str
    plant_kind: str
    study_id: int | None = None
    vehicle: str = ""
    plant_vehicle: str = ""
    feedback: str = "none"
    tags: tuple[str, ...] = ()
    notes: tuple[tuple[str, str], ...] = ()

    def __repr__(self) -> str:
        return (f"SessionRecord({self.id}, {self.maneuver_name!r} on {self.plant_kind!r}, {self.display_state}, "
                f"{self.n_measured}/{self.target_iterations} measured)")


@dataclass(frozen=True)
class SessionSummary:
    """One row of ``aerobat sessions`` (read from the summary columns only).

    ``vehicle`` is the design model's name, ``plant_vehicle`` the name of the vehicle the plant
    flew, ``feedback`` the plant's onboard feedback scheme (``none``: the paper's open loop),
    ``tags`` the user's tags (``aerobat tag``), ``maneuver_kind`` the maneuver's kind, ``rule`` the
    update rule's name.
    """

    id: int
    maneuver_name: str
    plant_kind: str
    seed: int | None
    n_records: int
    n_measured: int
    target_iterations: int
    last_position_error_m: float | None
    state: SessionStatus
    display_state: str
    started_at: str
    updated_at: str
    study_id: int | None = None
    vehicle: str = ""
    plant_vehicle: str = ""
    feedback: str = "none"
    tags: tuple[str, ...] = ()
    maneuver_kind: str = ""
    rule: str = ""


@dataclass(frozen=True)
class IterationRecord:
    """One stored trial.

    Attributes
    ----------
    index : 1-based record number in its session (every trial, lost ones included).
    correction : number of the correction this trial drove (0 if none).
    status : :class:`~aerobat.core.learning.IterationStatus`.
    params : (n_par,) parameters flown.
    next_params : (n_par,) parameters after this record's correction (= ``params`` unless ``ok``).
    error : (n_err,) measured error (NaN if none).
    gamma, scale : step size and constraint scaling used.
    final_state, start_state : measured states (None if not stored).
    times_s, states : (M,), (M, n_state) measured trajectory, float32 precision; None unless
        loaded with ``trajectories=True`` (``trajectory_rows`` says how long it is).
    plant_state : the plant's state after this trial (JSON table), if loaded and stored.
    learner_state : the learner's state after this trial (counters, parameters, the update
        rule's state; JSON table), if loaded and stored (schema 4).
    info : the plant's extras.
    notes : what learning noted about the correction (parameters held or pinned at a bound).
    signals : what the plant sampled inside itself (:class:`~aerobat.core.plant.Signals`: a flight
        controller's set point, PID terms and motors); None unless loaded with ``trajectories=True``
        and stored (schema 7).
    """

    session_id: int
    index: int
    correction: int
    status: IterationStatus
    params: np.ndarray
    next_params: np.ndarray
    error: np.ndarray
    gamma: float
    scale: float
    message: str
    final_state: np.ndarray | None
    start_state: np.ndarray | None
    trajectory_rows: int
    recorded_at: str
    times_s: np.ndarray | None = None
    states: np.ndarray | None = None
    plant_state: dict[str, Any] | None = None
    learner_state: dict[str, Any] | None = None
    info: dict[str, Any] = field(default_factory=dict)
    notes: tuple[IterationNote, ...] = ()
    signals: Signals | None = None

    def __repr__(self) -> str:
        return f"IterationRecord(session {self.session_id}, {self.index}, {self.status.value!r})"

    @property
    def warnings(self) -> tuple[str, ...]:
        """The notes that are warnings, in words."""
        return tuple(note.text for note in self.notes if note.kind.warning)

    def iteration(self) -> Iteration:
        """The stored trial as the core's :class:`~aerobat.core.learning.Iteration` (without its trial)."""
        return Iteration(self.index, self.correction, self.status, self.params, self.error, self.gamma, self.scale,
                         step_to(self.params, self.next_params), self.message, None, self.notes)




class StudyKind(StrEnum):
    """What a study studies (``aerobat study …``, ``aerobat benchmark map``): which report it has."""

    ROBUSTNESS = "robustness"
    RULES = "rules"
    FEEDBACK = "feedback"
    ENVELOPE = "envelope"
    MAP = "map"

    @classmethod
    def stored(cls, text: str) -> StudyKind | str:
        """The kind a ``studies`` row names; the name itself if it is none of these (a study an older
        aerobat ran under a name of its own through ``run_study``, which now takes a :class:`StudyKind`)."""
        try:
            return cls(text)
        except ValueError:
            return str(text)


@dataclass(frozen=True)
class StudyRecord:
    """A study: its kind, what defines it, and how far its jobs got.

    Attributes
    ----------
    kind : :class:`StudyKind` (the stored name, for a study of a kind this aerobat does not know).
    spec : everything that defines the study (JSON table).
    command : the command-line arguments that started it.
    out_dir : where its report and figures go.
    jobs_done, jobs_failed : jobs recorded as done, and as failed (failed ones run again on resume).
    """

    id: int
    kind: StudyKind | str
    spec: dict[str, Any]
    created_at: str
    command: tuple[str, ...]
    out_dir: str | None
    jobs_done: int
    jobs_failed: int


class JobStatus(StrEnum):
    """How one job ended: ``done`` (its result is valid) or ``failed`` (it raised; run again on resume)."""

    DONE = "done"
    FAILED = "failed"


@dataclass(frozen=True)
class StudyJobRecord:
    """One job of a study: its specification, its result (or failure) and the session it learned in."""

    study_id: int
    key: str
    status: JobStatus
    spec: dict[str, Any]
    result: dict[str, Any]
    error: str | None
    attempts: int
    session_id: int | None
    recorded_at: str
