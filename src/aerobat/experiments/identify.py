"""Identification runs: fly the identification sequence on a plant, keep it in the store, fit, write the vehicle.

::

    from aerobat.experiments.identify import identify, write_identified_vehicle
    from aerobat.plants import PlantChoice

    run = identify(PlantChoice("arena", seed=1), prior=hummingbird(), store=store)
    write_identified_vehicle(run, "my_vehicle.toml")     # IdentificationFailed if the fit is not usable
    design(MultiFlip(vehicle=run.fit.config.vehicle, flips=3), NominalModel(run.fit.config))

An identification is a stored session like a learning session: its maneuver is the
:class:`~aerobat.quadrotor.identification.IdentificationSequence` (kind ``identification``),
each flight — retries included — is an iteration with its measured trajectory and the
plant's state, its parameter is the trial's number and its error is how far from the
start the trial ended. The fitted vehicle is not in the store (the schema has no place
for it): :func:`refit_session` fits again from the stored flights alone.

Bad data: a trial whose trigger was lost, whose plant stopped answering or that was
aborted is flown again (up to ``max_attempts``); a trial that crashed is not flown again
and is skipped with a message; at most ``max_flights`` flights are flown in all. A fit
with too few usable trials is refused before it starts, naming what is missing; a fit
whose residual is too large is returned with its ``problems`` and
:func:`write_identified_vehicle` refuses it.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from aerobat.core.design import Design, DesignStatus
from aerobat.core.learning import Iteration, IterationStatus, SessionStatus, step_to
from aerobat.core.plant import Plant, StatefulPlant, Trial, TrialStatus
from aerobat.errors import ConfigError, IdentificationFailed, OutputError, SessionNotFound
from aerobat.experiments.designing import resolve_design_model
from aerobat.experiments.setup import plant_choice_from_record, plant_record_config
from aerobat.plants import DesignModel, PlantChoice
from aerobat.quadrotor.feedback import OPEN_LOOP
from aerobat.quadrotor.identification import (
    FitOptions,
    IdentificationSequence,
    IdentificationTrial,
    VehicleFit,
    fit_vehicle,
    identification_sequence,
    sequence_from_spec,
)
from aerobat.quadrotor.vehicle import VehicleConfig, save_vehicle, vehicle_table
from aerobat.store import Store

__all__ = ["Flight", "IdentificationRun", "fly_sequence", "identify", "refit_session", "write_identified_vehicle"]

_RETRY = (TrialStatus.NO_TRIGGER, TrialStatus.LOST, TrialStatus.ABORTED)


@dataclass(frozen=True)
class Flight:
    """One flight of an identification trial (``attempt`` counts from 1)."""

    number: int
    trial: IdentificationTrial
    attempt: int
    result: Trial


@dataclass(frozen=True)
class IdentificationRun:
    """What an identification flew and fitted.

    Attributes
    ----------
    sequence : the trials, as stored.
    plant : the plant choice that flew them.
    flights : every flight, retries included, in order.
    notes : trials skipped and why, retries.
    fit : the fit (None if it was refused: too few usable trials).
    session_id : the stored session (None without a store).
    wall_s : wall time of flying and fitting [s].
    """

    sequence: IdentificationSequence
    plant: PlantChoice
    flights: tuple[Flight, ...]
    notes: tuple[str, ...]
    fit: VehicleFit | None
    session_id: int | None
    wall_s: float

    @property
    def final_flights(self) -> list[tuple[IdentificationTrial, Trial]]:
        """Each trial's last flight (the one the fit uses, if it was measured)."""
        last: dict[int, Flight] = {}
        for flight in self.flights:
            last[self.sequence.trials.index(flight.trial)] = flight
        return [(f.trial, f.result) for _, f in sorted(last.items())]


def fly_sequence(plant: Plant, trials: Sequence[IdentificationTrial], *, max_attempts: int = 2,
                 max_flights: int = 12, on_flight: Callable[[Flight], None] | None = None,
                 ) -> tuple[list[Flight], list[str]]:
    """Fly each trial, again if its trigger was lost, the plant stopped answering or it was aborted.

    A crashed trial is not flown again (what crashed once is no safe identification trial).
    Stops after ``max_flights`` flights; the trials not flown then are skipped with a note.
    """
    if not 1 <= max_attempts <= 10:
        raise ConfigError(f"max_attempts = {max_attempts}: allowed 1 … 10")
    if not 1 <= max_flights <= 100:
        raise ConfigError(f"max_flights = {max_flights}: allowed 1 … 100")
    flights: list[Flight] = []
    notes: list[str] = []
    for k, trial in enumerate(trials):
        for attempt in range(1, max_attempts + 1):
            if len(flights) >= max_flights:
                left = [t.name for t in trials[k:]]
                notes.append(f"flight budget of {max_flights} used up: not flown: {', '.join(left)}")
                return flights, notes
            result = plant.fly(trial.program)
            flight = Flight(len(flights) + 1, trial, attempt, result)
            flights.append(flight)
            if on_flight is not None:
                on_flight(flight)
            if result.ok:
                break
            if result.status is TrialStatus.CRASHED:
                notes.append(f"{trial.name}: crashed ({result.message}); skipped, not flown again")
                break
            if result.status in _RETRY and attempt < max_attempts:
                notes.append(f"{trial.name}: {result.status.value} ({result.message}); flown again")
                continue
            notes.append(f"{trial.name}: {result.status.value} after {attempt} attempt(s) ({result.message}); "
                         f"skipped")
            break
    return flights, notes


def _sequence_design(sequence: IdentificationSequence) -> Design:
    """The store's design record for an identification: fixed programs, nothing designed."""
    n_err = len(sequence.errors)
    maneuver: Any = sequence  # a Maneuver in all the store reads (name, parameters, errors, spec)
    return Design(
        maneuver=maneuver, p_guess=np.zeros(1), p_nominal=np.zeros(1), residual=np.zeros(n_err),
        residual_norm=0.0, converged=True, status=DesignStatus.CONVERGED,
        message=f"identification sequence of {len(sequence.trials)} fixed programs built on {sequence.prior.name}; "
                f"nothing to design",
        jacobian=np.zeros((n_err, 1)), correction=np.zeros((1, n_err)), correction_kind="none",
        singular_values=np.zeros(1), condition_number=math.inf, rank=0,
        duration_s=float(sum(t.program.duration_s for t in sequence.trials)), compute_s=0.0, evaluations=0)


def identify(plant: PlantChoice, prior: VehicleConfig, *, store: Store | None = None, flips: bool = True,
             max_angle_rad: float = 0.5, max_attempts: int = 2, max_flights: int = 12,
             options: FitOptions | None = None, on_flight: Callable[[Flight], None] | None = None,
             command: Sequence[str] = (), name: str = "identified",
             design_model: DesignModel | str | None = None) -> IdentificationRun:
    """Fly the identification sequence built on ``prior`` on ``plant`` and fit the model.

    Parameters
    ----------
    plant : which plant flies (built around ``prior``: its onboard controller inverts with
        ``prior``'s constants, as a real vehicle's firmware does with the values it was given).
        Identification always flies the open loop: onboard feedback would hide the very
        dynamics being measured, so the plant's feedback is set to ``none``.
    prior : the vehicle one believes one has; the fit starts from it and keeps its controller.
    store : keep the identification as a session (every flight committed as it happens).
    flips : include the two slow flips.
    max_angle_rad : the largest attitude a rate doublet may reach.
    max_attempts, max_flights : retries per trial and flights in all (see :func:`fly_sequence`).
    options : the fit's options.
    on_flight : called after each flight (progress output).
    command : the command line, kept with the session.
    name : the identified vehicle's name.
    design_model : the model the slow flips are designed on (None: the plant's default, its firmware's
        on ``betaflight`` and ``fc``; the fit's own model is the paper's either way).

    Raises
    ------
    IdentificationFailed
        Too few usable trials (the session, if stored, is marked failed with the same message).
    """
    started = time.perf_counter()
    plant = dataclasses.replace(plant, feedback=OPEN_LOOP)
    flip_model = None
    if resolve_design_model(plant, design_model) is DesignModel.FIRMWARE and flips:
        assert plant.spec.firmware_model is not None
        flip_model = plant.spec.firmware_model(prior, plant.settings)[0]  # the slow flips fly as designed
    trials, notes = identification_sequence(prior, flips=flips, max_angle_rad=max_angle_rad, flip_model=flip_model)
    sequence = IdentificationSequence(prior, trials)
    flying = plant.build(prior)
    session_id = None
    if store is not None:
        session_id = store.create_session(
            vehicle=vehicle_table(prior), plant_kind=plant.kind, plant_config=plant_record_config(plant),
            maneuver=sequence, design=_sequence_design(sequence), seed=plant.seed,
            rule={"name": "identification", "schedule": "none"}, target_iterations=len(trials),
            start_params=np.zeros(1), command=command)

    def record(flight: Flight) -> None:
        if store is not None and session_id is not None:
            _store_flight(store, session_id, sequence, flight, flying)
        if on_flight is not None:
            on_flight(flight)

    flights, flown_notes = fly_sequence(flying, trials, max_attempts=max_attempts, max_flights=max_flights,
                                        on_flight=record)
    notes += flown_notes
    run = IdentificationRun(sequence, plant, tuple(flights), tuple(notes), None, session_id, 0.0)
    try:
        fit = fit_vehicle(prior, run.final_flights, options=options, name=name)
    except IdentificationFailed as exc:
        if store is not None and session_id is not None:
            store.finish_session(session_id, SessionStatus.FAILED, str(exc))
        raise
    if store is not None and session_id is not None:
        store.finish_session(session_id, SessionStatus.COMPLETED if fit.acceptable else SessionStatus.FAILED,
                             _fit_message(fit))
    return IdentificationRun(sequence, plant, tuple(flights), tuple(notes), fit, session_id,
                             time.perf_counter() - started)


def _store_flight(store: Store, session_id: int, sequence: IdentificationSequence, flight: Flight,
                  plant: Plant) -> None:
    index = sequence.trials.index(flight.trial)
    result = flight.result
    error = sequence.error(result.final_state) if result.ok else np.full(len(sequence.errors), np.nan)
    retried = "" if flight.attempt == 1 else f", attempt {flight.attempt}"
    params = np.array([float(index)])
    trial = dataclasses.replace(result, info={**result.info, "trial": flight.trial.name,
                                              "trial_kind": flight.trial.kind.value, "attempt": flight.attempt})
    iteration = Iteration(flight.number, 0, IterationStatus.of_trial(result.status), params, error, 0.0, 1.0,
                          step_to(params, np.array([float(min(index + 1, len(sequence.trials) - 1))])),
                          f"{flight.trial.name}{retried}: {result.message}", trial)
    store.append_iteration(session_id, iteration,
                           plant_state=plant.get_state() if isinstance(plant, StatefulPlant) else None)


def _fit_message(fit: VehicleFit) -> str:
    used = f"{len(fit.trials)} trials fitted, residual {fit.position_rms_m * 1e3:.2f} mm / " \
           f"{math.degrees(fit.angle_rms_rad):.2f}° RMS"
    if fit.acceptable:
        return f"identified: {used}"
    return f"fit refused: {'; '.join(fit.problems)} ({used})"


def _last_identification(store: Store) -> int:
    """The newest identification session that is not running: ``--from-session last`` (issue 44: a study's learning
    session, still running, was taken)."""
    for summary in store.list_sessions(newest_first=True):
        if summary.state is SessionStatus.RUNNING:
            continue
        spec = store.maneuver(store.session(summary.id).maneuver_id).spec
        if isinstance(spec, Mapping) and spec.get("kind") == "identification":
            return summary.id
    raise SessionNotFound(f"{store.path}: holds no finished identification session (`aerobat identify` flies one)")


def refit_session(store: Store, ref: int | str, *, options: FitOptions | None = None,
                  name: str = "identified") -> IdentificationRun:
    """Fit again from a stored identification session's flights (nothing is flown).

    Raises
    ------
    ConfigError
        The session is not an identification.
    IdentificationFailed
        Its flights hold too few usable trials.
    """
    started = time.perf_counter()
    last = isinstance(ref, str) and ref.strip().lower() == "last"
    session_id = _last_identification(store) if last else store.resolve_session(ref)
    rec = store.session(session_id)
    where = f"{store.path}: session {session_id}"
    sequence = sequence_from_spec(store.maneuver(rec.maneuver_id).spec, where)
    prec = store.plant(rec.plant_id)
    plant = plant_choice_from_record(prec.kind, prec.config, rec.seed, source=f"{where} plant")
    flights = []
    for it in store.iterations(session_id, trajectories=True):
        index = int(round(float(it.params[0])))
        if not 0 <= index < len(sequence.trials):
            raise ConfigError(f"{where}: iteration {it.index} flew trial {index}, which the sequence does not have")
        times = it.times_s if it.times_s is not None else np.empty(0)
        states = it.states if it.states is not None else np.empty((0, 20))
        final = it.final_state if it.final_state is not None else np.full(20, np.nan)
        start = it.start_state if it.start_state is not None else np.full(20, np.nan)
        result = Trial(TrialStatus(it.status), it.message, final, times, states, start, dict(it.info or {}))
        attempt = int((it.info or {}).get("attempt", 1))
        flights.append(Flight(it.index, sequence.trials[index], attempt, result))
    run = IdentificationRun(sequence, plant, tuple(flights), (), None, session_id, 0.0)
    fit = fit_vehicle(sequence.prior, run.final_flights, options=options, name=name)
    return IdentificationRun(sequence, plant, tuple(flights), (), fit, session_id, time.perf_counter() - started)


def identified_source(run: IdentificationRun) -> dict[str, Any]:
    """The ``[source]`` table of an identified vehicle file: how it was identified and how certain."""
    fit = run.fit
    if fit is None:
        raise IdentificationFailed("nothing was fitted")
    derived = fit.derived()
    return {
        "summary": f"identified on the {run.plant.kind} plant (seed {run.plant.seed}) from {len(fit.trials)} "
                   f"trials, prior {run.sequence.prior.name}",
        "method": "aerobat identify: least squares on the compiled model, motion-capture positions and attitudes "
                  "only (docs/identification.md)",
        "plant": run.plant.kind,
        "seed": run.plant.seed,
        "session": run.session_id if run.session_id is not None else -1,
        "flights": len(run.flights),
        "trials_used": [t.trial.name for t in fit.trials],
        "position_rms_m": fit.position_rms_m,
        "angle_rms_rad": fit.angle_rms_rad,
        "notes": list(fit.notes) + list(run.notes),
        "parameters": {row["name"]: {"value": row["value"], "sigma": row["sigma"], "unit": row["unit"],
                                     "fitted": row["fitted"]} for row in fit.parameter_rows()},
        "derived": {name: {"value": value, "sigma": sigma} for name, (value, sigma) in derived.items()},
    }


def write_identified_vehicle(run: IdentificationRun, path: str | Path) -> VehicleConfig:
    """Write the identified vehicle (with its ``[source]`` table) to ``path``; returns it.

    Raises
    ------
    IdentificationFailed
        There is no fit, or it is not acceptable (its residual is too large…): no file is written.
    OutputError
        The file cannot be written.
    """
    fit = run.fit
    if fit is None:
        raise IdentificationFailed("nothing was fitted: no vehicle file written")
    if not fit.acceptable:
        raise IdentificationFailed(f"{_fit_message(fit)}; no vehicle file written", fit)
    config = VehicleConfig(vehicle=fit.config.vehicle, controller=fit.config.controller, name=fit.config.name,
                           effects=fit.config.effects, source=identified_source(run))
    header = (f"{config.name}: identified by aerobat on the {run.plant.kind} plant (seed {run.plant.seed}).\n"
              f"[controller] is the onboard loop the trials were flown with (the prior's, {run.sequence.prior.name});"
              f"\n[effects] are equivalent terms beyond the paper's model; [source] has every fitted parameter "
              f"with its 1-sigma uncertainty.")
    try:
        save_vehicle(config, path, header=header)
    except OSError as exc:
        raise OutputError(f"{path}: cannot write the vehicle file: {exc.strerror or exc}") from None
    return config
