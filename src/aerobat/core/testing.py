"""A conformance kit for maneuvers, plants and update rules — aerobat's own and yours.

``check_maneuver``, ``check_plant`` and ``check_rule`` assert what the design, the
learning loop and the store rely on, with messages that say which promise broke.
The test suite runs them over every registered maneuver, plant and rule; run them
on your own before you fly it::

    from aerobat.core.testing import check_maneuver, check_plant
    check_maneuver(MySlalom(...), model=NominalModel(config))
    check_plant(MyPlant(...), MySlalom(...))

The module also holds a toy problem small enough to read in a minute and cheap
enough to learn in milliseconds: a cart on a rail with viscous friction, pushed by
a bang-bang force (:class:`ToyManeuver`, :class:`ToyModel`, :class:`ToyPlant`).
It exercises every interface without any vehicle.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aerobat.core.bounds import Interval, bounded, validate
from aerobat.core.design import Design, FinalStateModel, design
from aerobat.core.maneuver import ErrorKind, ErrorSpec, Maneuver, ParameterSpec, batch_errors, check_parameters
from aerobat.core.plant import Plant, StatefulPlant, Trial, TrialStatus, repeats_exactly
from aerobat.core.rules.base import UpdateRule
from aerobat.errors import ConfigError

__all__ = [
    "ToyManeuver",
    "ToyModel",
    "ToyPlant",
    "ToyProgram",
    "check_maneuver",
    "check_plant",
    "check_rule",
]


# ------------------------------------------------------------------ the toy problem


@dataclass(frozen=True)
class ToyProgram:
    """Push with ``+force_n_kg`` for ``push_s``, then brake with ``−force_n_kg`` for ``brake_s``."""

    force_n_kg: float
    push_s: float
    brake_s: float

    @property
    def duration_s(self) -> float:
        return self.push_s + self.brake_s


def _cart(program: ToyProgram, friction_per_s: float, x0: np.ndarray) -> np.ndarray:
    """Exact final (position, velocity) of ẍ = u − c·ẋ under the bang-bang program."""
    x, v = float(x0[0]), float(x0[1])
    for u, t in ((program.force_n_kg, program.push_s), (-program.force_n_kg, program.brake_s)):
        if friction_per_s > 0:
            e = math.exp(-friction_per_s * t)
            v_inf = u / friction_per_s
            x += v_inf * t + (v - v_inf) * (1.0 - e) / friction_per_s
            v = v_inf + (v - v_inf) * e
        else:
            x += v * t + 0.5 * u * t * t
            v += u * t
    return np.array([x, v])


@dataclass(frozen=True)
class ToyManeuver:
    """Move a cart from rest at 0 to rest at ``distance_m`` with a push-then-brake force.

    Parameters: force [m/s²], push and brake durations [s]; errors: final position and
    velocity. Three parameters, two errors: the correction is a right pseudo-inverse.
    """

    distance_m: float = bounded(1.0, Interval(0.0, 100.0, closed="right", unit="m"))
    friction_per_s: float = 0.5
    name: str = "toy cart"
    parameters: tuple[ParameterSpec, ...] = field(init=False, repr=False, compare=False)
    errors: tuple[ErrorSpec, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        validate(self)
        object.__setattr__(self, "parameters", (
            ParameterSpec(name="p0", description="force", unit="m/s²", lower=0.1, upper=20.0, scale=1.0,
                          bound_names=("", "force limit")),
            ParameterSpec(name="p1", description="push duration", unit="s", lower=0.0, upper=10.0, scale=0.1),
            ParameterSpec(name="p2", description="brake duration", unit="s", lower=0.0, upper=10.0, scale=0.1),
        ))
        object.__setattr__(self, "errors", (
            ErrorSpec(name="x", unit="m", scale=0.01, kind=ErrorKind.POSITION),
            ErrorSpec(name="vx", unit="m/s", scale=0.01, kind=ErrorKind.VELOCITY),
        ))

    def guess(self) -> np.ndarray:
        t = math.sqrt(self.distance_m / 2.0)
        return np.array([2.0, t, t])

    def program(self, params: np.ndarray) -> ToyProgram:
        problem = check_parameters(self.parameters, params)
        if problem:
            raise ConfigError(f"{self.name}: {problem}")
        return ToyProgram(float(params[0]), float(params[1]), float(params[2]))

    def initial_state(self) -> np.ndarray:
        return np.zeros(2)

    def error(self, final_state: np.ndarray) -> np.ndarray:
        return np.array([final_state[0] - self.distance_m, final_state[1]])

    def is_valid(self, params: np.ndarray) -> bool:
        return check_parameters(self.parameters, params) is None

    def duration_s(self, params: np.ndarray) -> float:
        return self.program(params).duration_s

    def spec(self) -> dict[str, Any]:
        return {"kind": "toy", "distance_m": self.distance_m, "friction_per_s": self.friction_per_s}


class ToyModel:
    """The nominal cart model (a :class:`~aerobat.core.design.FinalStateModel`)."""

    def __init__(self, friction_per_s: float = 0.5) -> None:
        self.friction_per_s = friction_per_s

    def final_states(self, programs: Sequence[ToyProgram], initial_states: np.ndarray | None = None) -> np.ndarray:
        x0 = np.zeros((len(programs), 2)) if initial_states is None else np.asarray(initial_states, dtype=float)
        return np.stack([_cart(p, self.friction_per_s, x) for p, x in zip(programs, x0, strict=True)])


class ToyPlant:
    """The "real" cart: more friction than the model, a push that is 5 % weak, and measurement noise.

    It is a :class:`~aerobat.core.plant.StatefulPlant`: its random generator's state saves and
    restores, so a resumed run repeats an uninterrupted one.
    """

    name = "toy"

    def __init__(self, *, friction_per_s: float = 0.6, force_gain: float = 0.95, noise_m: float = 0.002,
                 seed: int = 0, crash_beyond_m: float = 50.0) -> None:
        self.friction_per_s = friction_per_s
        self.force_gain = force_gain
        self.noise_m = noise_m
        self.crash_beyond_m = crash_beyond_m
        self.rng = np.random.default_rng(seed)

    def fly(self, program: ToyProgram) -> Trial:
        real = ToyProgram(program.force_n_kg * self.force_gain, program.push_s, program.brake_s)
        final = _cart(real, self.friction_per_s, np.zeros(2))
        final = final + self.noise_m * self.rng.standard_normal(2)
        times = np.array([0.0, program.duration_s])
        states = np.stack([np.zeros(2), final])
        if not np.all(np.isfinite(final)) or abs(final[0]) > self.crash_beyond_m:
            nan = np.full(2, np.nan)
            return Trial(TrialStatus.CRASHED, f"left the rail at x = {final[0]:.3g} m", nan, times, states, nan)
        return Trial(TrialStatus.OK, "flown", final, times, states, np.zeros(2))

    def get_state(self) -> dict[str, Any]:
        return {"rng": self.rng.bit_generator.state}

    def set_state(self, state: dict[str, Any]) -> None:
        self.rng.bit_generator.state = state["rng"]


# ------------------------------------------------------------------ checks


class ConformanceError(AssertionError):
    """An implementation breaks a promise the rest of aerobat relies on."""


def _require(condition: bool, what: str, message: str) -> None:
    if not condition:
        raise ConformanceError(f"{what}: {message}")


def _json_round_trip(value: Any, what: str, label: str) -> Any:
    try:
        return json.loads(json.dumps(value, allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise ConformanceError(f"{what}: {label} is not plain JSON ({exc})") from None


def check_maneuver(maneuver: Maneuver, *, model: FinalStateModel | None = None,
                   rebuild: Callable[[dict[str, Any]], Maneuver] | None = None) -> Design | None:
    """Check a maneuver against the :class:`~aerobat.core.maneuver.Maneuver` protocol.

    Parameters
    ----------
    maneuver : the maneuver.
    model : a model to design it on; then the design must converge (its result is returned).
    rebuild : ``rebuild(spec) -> maneuver`` (e.g. :func:`aerobat.core.registry.from_spec`); then
        ``spec()`` must rebuild an equal specification.
    """
    what = f"maneuver {getattr(maneuver, 'name', type(maneuver).__name__)!r}"
    for attribute in ("name", "parameters", "errors", "guess", "program", "initial_state", "error", "is_valid",
                      "duration_s", "spec"):
        _require(hasattr(maneuver, attribute), what, f"has no {attribute!r} (Maneuver protocol)")
    _require(isinstance(maneuver.name, str) and bool(maneuver.name), what, "name must be a non-empty string")
    _require(len(maneuver.parameters) >= 1 and all(isinstance(p, ParameterSpec) for p in maneuver.parameters), what,
             "parameters must be a non-empty tuple of ParameterSpec")
    _require(len(maneuver.errors) >= 1 and all(isinstance(e, ErrorSpec) for e in maneuver.errors), what,
             "errors must be a non-empty tuple of ErrorSpec")
    _require(len(maneuver.errors) <= len(maneuver.parameters), what,
             f"{len(maneuver.errors)} errors but only {len(maneuver.parameters)} parameters: no right inverse of J")
    names = [p.name for p in maneuver.parameters]
    _require(len(set(names)) == len(names), what, f"parameter names repeat: {names}")
    guess = np.asarray(maneuver.guess(), dtype=float)
    _require(guess.shape == (len(maneuver.parameters),), what,
             f"guess() has shape {guess.shape}, expected ({len(maneuver.parameters)},)")
    _require(bool(maneuver.is_valid(guess)), what, "guess() violates the maneuver's own constraints")
    maneuver.program(guess)
    duration = float(maneuver.duration_s(guess))
    _require(math.isfinite(duration) and duration > 0, what, f"duration_s(guess) = {duration}, expected > 0")
    x0 = np.asarray(maneuver.initial_state(), dtype=float)
    _require(x0.ndim == 1 and bool(np.all(np.isfinite(x0))), what, "initial_state() must be a finite vector")
    e0 = np.asarray(maneuver.error(x0), dtype=float)
    _require(e0.shape == (len(maneuver.errors),), what,
             f"error(initial_state()) has shape {e0.shape}, expected ({len(maneuver.errors)},)")
    if hasattr(maneuver, "error_batch"):
        states = np.stack([x0, x0 + 0.01 * np.arange(x0.size)])
        one_by_one = np.stack([np.asarray(maneuver.error(s), dtype=float) for s in states])
        _require(batch_errors(maneuver, states).tobytes() == one_by_one.tobytes(), what,
                 "error_batch() differs from error() state by state")
    outside = guess.copy()
    spec0 = maneuver.parameters[0]
    if math.isfinite(spec0.upper):
        outside[0] = spec0.upper + 10 * spec0.scale
        _require(not maneuver.is_valid(outside), what, f"is_valid() accepts {spec0.name} beyond its upper bound")
    spec = _json_round_trip(maneuver.spec(), what, "spec()")
    _require(isinstance(spec, dict) and isinstance(spec.get("kind"), str), what,
             "spec() must be a table with a string 'kind'")
    if rebuild is not None:
        again = rebuild(spec)
        _require(_json_round_trip(again.spec(), what, "rebuilt spec()") == spec, what,
                 "spec() does not rebuild an equal maneuver")
    if model is None:
        return None
    result = design(maneuver, model)
    _require(result.converged, what, f"does not design on the given model: {result.message}")
    return result


def check_plant(plant: Plant, maneuver: Maneuver, *, params: np.ndarray | None = None) -> Trial:
    """Check a plant against the :class:`~aerobat.core.plant.Plant` protocol by flying ``maneuver``.

    Flies the maneuver's guess (or ``params``): the trial must be a :class:`Trial` with a
    :class:`TrialStatus`, consistent array shapes and JSON-ready ``info``. A
    :class:`~aerobat.core.plant.StatefulPlant` must also repeat a trial exactly after
    ``set_state(get_state())``, with a JSON-ready state, unless it flies on the wall clock
    (:func:`~aerobat.core.plant.repeats_exactly`: its state must only restore). Returns the first trial.
    """
    what = f"plant {getattr(plant, 'name', type(plant).__name__)!r}"
    _require(isinstance(getattr(plant, "name", None), str), what, "has no string 'name'")
    p = np.asarray(maneuver.guess() if params is None else params, dtype=float)
    program = maneuver.program(p)
    saved = None
    if isinstance(plant, StatefulPlant):
        saved = _json_round_trip(plant.get_state(), what, "get_state()")
    trial = plant.fly(program)
    _require(isinstance(trial, Trial), what, f"fly() returned {type(trial).__name__}, expected Trial")
    _require(isinstance(trial.status, TrialStatus), what, f"trial status {trial.status!r} is not a TrialStatus")
    _require(isinstance(trial.message, str), what, "trial message must be a string")
    n = np.asarray(maneuver.initial_state()).size
    _require(np.asarray(trial.final_state).shape == (n,), what,
             f"final_state has shape {np.shape(trial.final_state)}, expected ({n},)")
    times, states = np.asarray(trial.times_s), np.asarray(trial.states)
    _require(states.shape == (times.size, n), what,
             f"states has shape {states.shape}, expected ({times.size}, {n}) for {times.size} times")
    _require(bool(np.all(np.diff(times) >= 0)), what, "times_s must not decrease")
    if trial.ok:
        _require(bool(np.all(np.isfinite(maneuver.error(trial.final_state)))), what,
                 "an 'ok' trial must give a finite error")
    _json_round_trip(trial.info, what, "trial info")
    if saved is not None:
        assert isinstance(plant, StatefulPlant)
        plant.set_state(saved)
        if not repeats_exactly(plant):  # on the wall clock: the state restores, no trial repeats bit for bit
            return trial
        again = plant.fly(program)
        _require(again.status == trial.status and bool(np.array_equal(np.asarray(again.final_state),
                                                                 np.asarray(trial.final_state), equal_nan=True)),
                 what, "set_state(get_state()) does not repeat the trial exactly")
    return trial


def check_rule(build: Callable[[], UpdateRule], maneuver: Maneuver, plant: Plant, design_: Design, *,
               trials: int = 6) -> None:
    """Check an update rule: steps of the right shape, a JSON-ready state that resumes exactly.

    ``build()`` makes a fresh rule for ``design_``. The check learns ``trials`` trials on
    ``plant`` (a :class:`~aerobat.core.plant.StatefulPlant`), then learns the second half
    again from a fresh rule loaded with the saved state after the first half: every
    proposal must be identical, bit for bit.
    """
    from aerobat.core.learning import Learner

    rule = build()
    what = f"rule {getattr(rule, 'name', type(rule).__name__)!r}"
    _require(isinstance(rule, UpdateRule), what, "does not implement propose/observe/state/load_state")
    _require(isinstance(plant, StatefulPlant), what, "check_rule needs a plant with get_state/set_state")
    assert isinstance(plant, StatefulPlant)
    learner = Learner(maneuver, design_, rule=rule)
    half = trials // 2
    saved: tuple[dict[str, Any], dict[str, Any]] | None = None
    first: list[np.ndarray] = []
    for k in range(trials):
        if k == half:
            saved = (_json_round_trip(learner.state(), what, "state()"), plant.get_state())
        record = learner.tell(plant.fly(learner.program()))
        _require(record.step.shape == (len(maneuver.parameters),), what, f"step has shape {record.step.shape}")
        _require(bool(np.all(np.isfinite(record.step))) and math.isfinite(record.gamma), what,
                 f"non-finite step or γ at trial {k + 1}")
        first.append(learner.ask())
    assert saved is not None
    again = Learner(maneuver, design_, rule=build())
    again.load_state(saved[0])
    plant.set_state(saved[1])
    for k in range(half, trials):
        again.tell(plant.fly(again.program()))
        _require(np.array_equal(again.ask(), first[k]), what,
                 f"a rule resumed from state() after trial {half} differs at trial {k + 1}")


def _toy_from_spec(spec: Any, source: str) -> ToyManeuver:
    unknown = sorted(set(spec) - {"kind", "distance_m", "friction_per_s"})
    if unknown:
        raise ConfigError(f"{source}: unknown field(s) {', '.join(unknown)}")
    try:
        return ToyManeuver(distance_m=float(spec.get("distance_m", 1.0)),
                           friction_per_s=float(spec.get("friction_per_s", 0.5)))
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{source}: {exc}") from None


def _register_toy() -> None:
    from aerobat.core.registry import MANEUVERS

    if "toy" not in MANEUVERS.names():
        MANEUVERS.register("toy", _toy_from_spec)  # type: ignore[arg-type]


_register_toy()
