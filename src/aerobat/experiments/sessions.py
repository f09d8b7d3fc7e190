"""Durable learning sessions: learning whose every trial is committed to the store as it happens.

::

    from aerobat.experiments import start_session, resume_session
    from aerobat.store import Store

    with Store("aerobat.sqlite") as store:
        run = start_session(store, flip, model=hummingbird(), plant=PlantChoice("arena", seed=1), iterations=30)
        outcome = run.run()                       # every trial is in the store when it returns
    with Store("aerobat.sqlite") as store:        # later, or in another process after a kill
        outcome = resume_session(store, "last").run()

A stored iteration holds the parameters flown, the measured error, the step
actually applied, the plant's state and the learner's state after it, all in one
commit. Resuming restores the learner (its update rule's own state included) and
the plant from the last commit, so a resumed session flies exactly the trials an
uninterrupted one would have flown. This is what ``aerobat learn`` runs.
"""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aerobat.config import as_float_array, check_int, check_type, short_repr
from aerobat.core.bounds import ITERATIONS
from aerobat.core.design import Design
from aerobat.core.learning import Iteration, IterationStatus, Learner, SessionStatus, learn
from aerobat.core.maneuver import Maneuver, check_maneuver, position_indices
from aerobat.core.plant import Plant, StatefulPlant, is_deterministic, repeats_exactly
from aerobat.core.registry import from_spec
from aerobat.core.rules import RuleChoice
from aerobat.errors import ConfigError, DesignFailed, StoreError
from aerobat.experiments.designing import NominalDesign, design_model_of, design_vehicle_table, nominal_design
from aerobat.experiments.setup import build_rule, plant_choice_from_record, plant_record_config
from aerobat.plants import DesignModel, PlantChoice
from aerobat.quadrotor.vehicle import VehicleConfig, vehicle_from_table, vehicle_table
from aerobat.store import Store

__all__ = [
    "SessionOutcome",
    "StoredSession",
    "position_error_m",
    "resume_session",
    "spec_difference",
    "start_session",
    "warm_start",
]


@dataclass(frozen=True)
class SessionOutcome:
    """How one :meth:`StoredSession.run` ended.

    Attributes
    ----------
    session_id : the stored session.
    status : :class:`~aerobat.core.learning.SessionStatus` as stored.
    message : why, in words.
    measured, target : measured iterations stored, and the target.
    last_index : the last stored trial.
    warnings : learner warnings raised during this run (e.g. a parameter pinned at a bound).
    wall_s : wall time of this run [s].
    """

    session_id: int
    status: SessionStatus
    message: str
    measured: int
    target: int
    last_index: int
    warnings: tuple[str, ...]
    wall_s: float

    @property
    def completed(self) -> bool:
        return self.status is SessionStatus.COMPLETED


@dataclass
class StoredSession:
    """A learning session whose trials go to the store (see :func:`start_session`, :func:`resume_session`)."""

    store: Store
    id: int
    maneuver: Maneuver
    design: Design
    model: VehicleConfig
    plant_choice: PlantChoice
    rule_choice: RuleChoice
    plant: Plant
    learner: Learner
    target: int
    resumed: bool = False
    exact: bool = True
    inexact_because: str = ""
    warnings: list[str] = field(default_factory=list)
    design_model: DesignModel = DesignModel.PAPER
    """Which model designed it (the stored design is kept on resume)."""
    design_model_description: str = ""
    full_output_share: float | None = None
    """On a model that records its motors, the share of p⁰'s steps with a motor at full output, when this call
    designed it (:attr:`~.designing.NominalDesign.full_output_share`; None on resume or for a design passed in)."""

    @property
    def measured(self) -> int:
        """Measured iterations stored so far."""
        return self.learner.measured

    def __repr__(self) -> str:
        return (f"StoredSession({self.id} in {self.store.path}: {self.maneuver.name!r} on {self.plant_choice.kind!r}, "
                f"{self.measured}/{self.target} measured)")

    def run(self, *, on_iteration: Callable[[Iteration], None] | None = None,
            should_stop: Callable[[], bool] | None = None,
            critical: Callable[[], contextlib.AbstractContextManager[Any]] | None = None) -> SessionOutcome:
        """Learn until the target is reached (or a trial crashes, or ``should_stop()``); store every trial.

        Parameters
        ----------
        on_iteration : called with each iteration once it is committed (progress output).
        should_stop : polled between trials; True stops after the trial in flight (``interrupted``).
        critical : a context manager factory wrapped around each commit (e.g. one that defers a
            second Ctrl-C until the commit is done).

        Raises
        ------
        StoreError
            An iteration could not be stored (disk full, store deleted…): the session is
            marked ``failed`` where that is still possible; every earlier iteration is kept.
        """
        store, sid = self.store, self.id
        get_state = self.plant.get_state if isinstance(self.plant, StatefulPlant) else None
        guard = critical or contextlib.nullcontext
        started = time.perf_counter()
        before = self.measured

        def record(it: Iteration) -> None:
            with guard():
                store.append_iteration(sid, it, plant_state=get_state() if get_state is not None else None,
                                       learner_state=self.learner.state())
            for warning in it.warnings:
                self.warnings.append(f"iteration {it.index}: {warning}")
            if on_iteration is not None:
                on_iteration(it)

        try:
            # start_session refused a design that did not converge unless forced; a resumed session continues
            if before >= self.target:  # killed after its last iteration was stored: nothing to fly, only closing
                status, message = SessionStatus.COMPLETED, ""
            else:
                session = learn(self.maneuver, self.design, self.plant, iterations=self.target - before,
                                learner=self.learner, on_iteration=record, should_stop=should_stop, force=True)
                status, message = session.status, session.message
        except StoreError as exc:
            with contextlib.suppress(StoreError):
                store.finish_session(sid, SessionStatus.FAILED, f"could not store an iteration: {exc}")
            raise
        except KeyboardInterrupt:
            status, message = SessionStatus.INTERRUPTED, "interrupted: the trial in flight was abandoned"
        except BaseException as exc:
            with contextlib.suppress(StoreError):
                store.finish_session(sid, SessionStatus.FAILED, f"{type(exc).__name__}: {exc}")
            raise
        summary = store.session(sid)
        if status is SessionStatus.INTERRUPTED and summary.n_measured >= self.target:
            status = SessionStatus.COMPLETED
        if status is SessionStatus.COMPLETED:
            fresh = summary.n_measured - before
            noun = "iteration" if summary.n_measured == 1 else "iterations"
            message = f"{summary.n_measured} measured {noun}" + (f", {fresh} after resuming" if self.resumed else "")
        store.finish_session(sid, status, message)
        return SessionOutcome(sid, status, message, summary.n_measured, self.target, summary.last_index,
                              tuple(self.warnings), time.perf_counter() - started)


def _check_target(iterations: Any) -> int:
    return ITERATIONS.check("iterations", iterations)


def start_session(
    store: Store,
    maneuver: Maneuver,
    *,
    model: VehicleConfig,
    plant: PlantChoice | None = None,
    rule: RuleChoice | None = None,
    iterations: int = 30,
    design_result: Design | None = None,
    correction: str = "tsvd",
    start_params: np.ndarray | None = None,
    warm_start_from: int | None = None,
    force: bool = False,
    command: Sequence[str] = (),
    study_id: int | None = None,
    plant_model: VehicleConfig | None = None,
    design_model: DesignModel | str | None = None,
) -> StoredSession:
    """Create a stored session: design (unless given), build the rule and the plant, record them.

    Parameters
    ----------
    store : where every trial goes.
    maneuver : what to learn (designed on ``model``).
    model : the nominal vehicle (the design model; the plant's onboard controller inverts with it).
    plant_model : the vehicle the plant is built around, if not ``model`` — e.g. a vehicle identified
        on the arena is designed on, but the arena stays the one built around the Hummingbird
        (its true vehicle and its onboard controller come from this one). The plant's feedback
        still tracks ``model``'s flight of each program (the flight the design promises).
    plant : which plant flies (default: the arena, seed 0).
    rule : the update rule (default: the paper's).
    iterations : measured iterations to learn.
    design_result : a design already computed for ``maneuver`` on ``model`` (a
        :class:`~aerobat.experiments.designing.NominalDesign` says which model it ran on; else computed here).
    design_model : the model to design on when designing here: ``"paper"`` or ``"firmware"`` (None: the
        plant's default, the firmware's on ``betaflight`` and ``fc``; :func:`~.designing.nominal_design`).
    correction : right inverse used for C when designing here (``tsvd``, ``inverse``, ``damped``).
    start_params : start from these parameters (e.g. another session's) instead of p⁰.
    warm_start_from : the session ``start_params`` came from.
    force : learn even from a design that did not converge.
    command : the command line, kept for reference.
    study_id : the study this session learns for.

    Raises
    ------
    DesignFailed
        The design did not converge (unless ``force``) or its correction matrix is unusable.
    """
    target = _check_target(iterations)
    check_type("store", store, Store, "a Store")
    check_maneuver(maneuver)
    check_type("model", model, VehicleConfig, "a VehicleConfig (e.g. aerobat.hummingbird())")
    plant = PlantChoice("arena") if plant is None else check_type("plant", plant, PlantChoice, "a PlantChoice")
    rule = RuleChoice() if rule is None else check_type("rule", rule, RuleChoice, "a RuleChoice")
    if design_result is not None:
        check_type("design_result", design_result, (Design, NominalDesign),
                   "a Design (from aerobat.design()), a NominalDesign or None")
    if isinstance(command, str) or not isinstance(command, Sequence) or not all(isinstance(a, str) for a in command):
        raise ConfigError(f"command: expected a list of strings, got {short_repr(command)}")
    if warm_start_from is not None:
        check_int("warm_start_from", warm_start_from, low=1)
    if study_id is not None:
        check_int("study_id", study_id, low=1)
    if design_result is None:
        nominal: NominalDesign | None = nominal_design(maneuver, model, plant=plant, design_model=design_model,
                                                       correction=correction)
    else:
        nominal = design_result if isinstance(design_result, NominalDesign) else None
    result = nominal.design if nominal is not None else design_result
    assert isinstance(result, Design)
    if not result.converged and not (force and np.all(np.isfinite(result.correction))):
        raise DesignFailed(f"design failed, nothing to learn: {result.message}"
                           + ("" if force else " (force=True / --force learns anyway)"), result)
    update_rule = build_rule(rule, result, model)
    base = plant_model if plant_model is not None else model
    flying = plant.build(base, design_model=model)  # the feedback tracks the design model's flight
    start = (np.array(result.p_nominal, dtype=float) if start_params is None
             else as_float_array("start_params", start_params, (len(maneuver.parameters),)))
    learner = Learner(maneuver, result, rule=update_rule, params=start)
    session_id = store.create_session(
        vehicle=vehicle_table(base), design_vehicle=design_vehicle_table(model, nominal), plant_kind=plant.kind,
        plant_config=plant_record_config(plant), maneuver=maneuver, design=result, seed=plant.seed,
        rule=rule.to_table(), target_iterations=target, start_params=start, warm_start_from=warm_start_from,
        command=command, study_id=study_id)
    kind, description = design_model_of(design_vehicle_table(model, nominal))
    return StoredSession(store, session_id, maneuver, result, model, plant, rule, flying, learner, target,
                         design_model=kind, design_model_description=description,
                         full_output_share=nominal.full_output_share if nominal is not None else None)


def resume_session(store: Store, ref: int | str, *, iterations: int | None = None,
                   take_over: bool = False) -> StoredSession:
    """Take over a stored session to continue it exactly where its last commit left it.

    Parameters
    ----------
    store : the store that holds it.
    ref : its id, or ``"last"``.
    iterations : a new target of measured iterations (default: the stored one).
    take_over : resume a session last run on another machine (whose process cannot be checked
        from here); the caller vouches that it is gone.

    Raises
    ------
    ConfigError
        The session is complete (and ``iterations`` does not raise the target), or its stored
        parts cannot be rebuilt.
    SessionInUse
        Another live process runs it.
    """
    check_type("store", store, Store, "a Store")
    session_id = store.resolve_session(ref)
    store.verify_session(session_id)  # every record it continues from, against its checksum
    rec = store.session(session_id)
    where = f"{store.path}: session {session_id}"
    mrec = store.maneuver(rec.maneuver_id)
    maneuver = from_spec(mrec.spec, source=f"{where} maneuver")
    drec = store.design(rec.design_id)
    prec = store.plant(rec.plant_id)
    design_table = store.vehicle(drec.vehicle_id).config
    model = vehicle_from_table(design_table, source=f"{where} design vehicle")
    plant_vehicle = vehicle_from_table(store.vehicle(prec.vehicle_id).config, source=f"{where} plant vehicle")
    target = rec.target_iterations if iterations is None else _check_target(iterations)
    if target <= rec.n_measured and (rec.state is SessionStatus.COMPLETED or target < rec.n_measured):
        raise ConfigError(f"{where} already has {rec.n_measured} of {rec.target_iterations} measured iterations "
                          f"({rec.display_state}); ask for more than {rec.n_measured} to learn more")
    result = drec.design(maneuver)
    rule_choice = RuleChoice.from_table(rec.rule, source=f"{where} rule")
    update_rule = build_rule(rule_choice, result, model)
    plant_choice = plant_choice_from_record(prec.kind, prec.config, rec.seed, source=f"{where} plant")
    plant = plant_choice.build(plant_vehicle, design_model=model)
    if not maneuver.is_valid(rec.current_params):
        raise ConfigError(f"{where}: stored parameters violate the maneuver's bounds")
    learner = Learner(maneuver, result, rule=update_rule, params=rec.current_params,
                      correction=rec.last_correction, index=rec.last_index, measured=rec.n_measured)
    last = store.last_iteration(session_id)
    exact = True
    because = ""
    if last is not None:
        if last.learner_state is not None:
            learner.load_state(last.learner_state)
        else:  # written before schema 4: bring a stateful rule back by replaying its history
            exact = _replay_legacy(learner, store, session_id, rule_choice, where)
        if isinstance(plant, StatefulPlant) and last.plant_state is not None:
            try:
                plant.set_state(last.plant_state)
            except (KeyError, TypeError, ValueError) as exc:
                raise ConfigError(f"{where}: stored plant state: {exc}") from None
        elif not is_deterministic(plant):
            exact = False  # the plant continues from a fresh random state
            because = f"the {prec.kind} plant's state was not stored"
    if exact and not repeats_exactly(plant):
        exact = False
        because = f"the {prec.kind} plant flies on the wall clock: no trial repeats bit for bit"
    if exact and _rounds_differently(rec.aerobat_version):
        exact = False
        because = (f"it was recorded by aerobat {rec.aerobat_version}, whose simulation rounds differently in the "
                   f"last bits (kernels without divisions since {KERNEL_ARITHMETIC_SINCE}): the resumed trials agree "
                   f"with an uninterrupted run to ~1e-9, not bit for bit")
    store.claim_session(session_id, take_over=take_over)
    if target != rec.target_iterations:
        store.set_target(session_id, target)
    kind, description = design_model_of(design_table)
    return StoredSession(store, session_id, maneuver, result, model, plant_choice, rule_choice, plant, learner,
                         target, resumed=True, exact=exact, inexact_because=because, design_model=kind,
                         design_model_description=description)


KERNEL_ARITHMETIC_SINCE = "0.3.0"
"""The version whose simulation kernels' arithmetic (reciprocals instead of divisions) the current one shares."""


def _rounds_differently(recorded_by: str | None) -> bool:
    """Whether a session recorded by aerobat ``recorded_by`` simulated with arithmetic older than this one's."""
    if not recorded_by:
        return False
    try:
        version = tuple(int(part) for part in recorded_by.split(".")[:3])
    except ValueError:
        return False
    return version < tuple(int(part) for part in KERNEL_ARITHMETIC_SINCE.split("."))


def _replay_legacy(learner: Learner, store: Store, session_id: int, choice: RuleChoice, where: str) -> bool:
    """Replay a pre-schema-4 session's history into its rule; returns whether that is exact."""
    if choice.isc:
        raise ConfigError(f"{where}: a '+isc' session stored before schema 4 cannot be resumed exactly (it needs "
                          f"every trial's measured trajectory); start a new one with --from-session instead")
    rule = learner.rule
    assert rule is not None
    for it in store.iterations(session_id):
        if it.status is not IterationStatus.OK:
            continue
        rule.propose(it.correction, np.asarray(it.params), np.asarray(it.error), None)
        rule.observe(np.asarray(it.params), np.asarray(it.error), np.asarray(it.next_params) - np.asarray(it.params))
    return True


def position_error_m(maneuver: Maneuver, error: np.ndarray) -> float:
    """Norm of the position components of an error vector [m] (NaN if there are none)."""
    idx = position_indices(maneuver.errors)
    return float(np.linalg.norm(np.asarray(error)[idx])) if idx else float("nan")


def warm_start(store: Store, ref: int | str, maneuver: Maneuver) -> tuple[np.ndarray, int]:
    """(learned parameters, session id) of a stored session that learned the same ``maneuver``.

    Raises :class:`ConfigError` naming the differences if the stored maneuver is another one.
    """
    source_id = store.resolve_session(ref)
    source = store.session(source_id)
    stored_spec = store.maneuver(source.maneuver_id).spec
    given_spec = json.loads(json.dumps(maneuver.spec()))
    if json.dumps(stored_spec, sort_keys=True) != json.dumps(given_spec, sort_keys=True):
        raise ConfigError(f"--from-session {source_id}: session {source_id} learned '{source.maneuver_name}', a "
                          f"different maneuver ({spec_difference(stored_spec, given_spec)}); a warm start needs the "
                          f"same maneuver specification")
    params = np.array(source.current_params, dtype=float)
    if not maneuver.is_valid(params):
        raise ConfigError(f"--from-session {source_id}: its learned parameters violate the maneuver's bounds")
    return params, source_id


def spec_difference(stored: dict[str, Any], given: dict[str, Any]) -> str:
    """The first few fields in which two JSON tables differ, in words."""
    keys = sorted(set(stored) | set(given))
    diffs = [f"{k} = {stored.get(k)!r} (stored) vs {given.get(k)!r}" for k in keys
             if json.dumps(stored.get(k), sort_keys=True) != json.dumps(given.get(k), sort_keys=True)]
    return "; ".join(d if len(d) < 160 else d[:157] + "…" for d in diffs[:4])
