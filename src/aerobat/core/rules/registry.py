"""Update rules by name: one registry of :class:`RuleSpec`, one parser of the names users write.

=================  ===========================================================================
``paper``          the paper's rule (eq 4): Δp = −γ_i·C·e with the design's C and γ_i = max(1/i, 0.1)
``tsvd``           :class:`~aerobat.core.rules.regularized.RegularizedRule`: truncated-SVD correction,
                   noise-aware threshold, per-direction step sizes by Kesten's rule
``damped``         the same with damped (Levenberg–Marquardt) filter factors
``kalman``         :class:`~aerobat.core.rules.kalman.KalmanRule`: Kalman estimate of the unmodeled
                   offset d of eq 3 (Sect. 11), p = p⁰ − C·d̂ projected onto the parameter bounds
``broyden``        :class:`~aerobat.core.rules.regularized.BroydenRule`: ``tsvd`` with a safeguarded
                   good-Broyden update of J
``<name>+isc``     :class:`~aerobat.core.rules.isc.InitialStateCompensation` around any of the above
=================  ===========================================================================

A user writes ``tsvd+isc``; inside, that is ``RuleChoice(name="tsvd", isc=True)``.
:meth:`RuleChoice.parse` and :meth:`RuleChoice.from_table` are the only places that
read those strings; :meth:`RuleChoice.to_table` is what the store keeps.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from aerobat.config import check_type
from aerobat.core.bounds import Interval, OneOf, bounded, validate
from aerobat.core.design import Design
from aerobat.core.registry import Registry
from aerobat.core.rules.base import ConstantSchedule, PaperRule, PaperSchedule, Schedule, UpdateRule
from aerobat.core.rules.isc import DeviationFn, InitialStateCompensation
from aerobat.core.rules.kalman import KalmanRule
from aerobat.core.rules.regularized import BroydenRule, RegularizedRule
from aerobat.errors import ConfigError

__all__ = ["RULES", "IscModel", "RuleChoice", "RuleSpec", "ScheduleChoice", "ScheduleKind", "make_rule"]


@dataclass(frozen=True)
class RuleSpec:
    """How to build one family of update rules.

    Attributes
    ----------
    name : what users write (``"tsvd"``).
    summary : one line for listings.
    build : ``build(design, schedule, options) -> rule``; ``schedule`` is None for the rule's own step sizes.
    own_steps : the rule has its own step sizes (used unless a schedule is given).
    takes_schedule : a fixed schedule may replace its step sizes.
    """

    name: str
    summary: str
    build: Callable[[Design, Schedule | None, dict[str, Any]], UpdateRule]
    own_steps: bool = True
    takes_schedule: bool = True


def _paper(design: Design, schedule: Schedule | None, options: dict[str, Any]) -> UpdateRule:
    correction = options.pop("correction", design.correction)
    if options:
        raise ConfigError(f"rule 'paper': unknown options {sorted(options)}")
    return PaperRule(np.asarray(correction, dtype=float), schedule or PaperSchedule(), name="paper")


def _kalman(design: Design, schedule: Schedule | None, options: dict[str, Any]) -> UpdateRule:
    if schedule is not None:
        raise ConfigError("rule 'kalman' takes no schedule: its step is the Kalman gain")
    return KalmanRule(design, **options)


RULES: Registry[RuleSpec] = Registry("update rule", "aerobat.rules")
RULES.register("paper", RuleSpec("paper", "the paper's rule (eq 4): −γ_i·C·e, γ_i = max(1/i, 0.1)", _paper,
                                 own_steps=False))
RULES.register("tsvd", RuleSpec("tsvd", "truncated-SVD correction with a noise-aware threshold and Kesten steps",
                                lambda d, s, o: RegularizedRule(d, kind="tsvd", schedule=s, **o)))
RULES.register("damped", RuleSpec("damped", "damped (Levenberg–Marquardt) correction with Kesten steps",
                                  lambda d, s, o: RegularizedRule(d, kind="damped", schedule=s, **o)))
RULES.register("kalman", RuleSpec("kalman", "Kalman estimate of the unmodeled offset d (Sect. 11)", _kalman,
                                  takes_schedule=False))
RULES.register("broyden", RuleSpec("broyden", "tsvd with a safeguarded Broyden update of J",
                                   lambda d, s, o: BroydenRule(d, schedule=s, **o)))


class ScheduleKind(StrEnum):
    """A fixed step-size schedule's kind."""

    PAPER = "paper"
    CONSTANT = "constant"


_STEP = Interval(0.0, 1.0, closed="right", as_float=True)


@dataclass(frozen=True)
class ScheduleChoice:
    """A fixed step-size schedule: the paper's γ_i = max(1/i, minimum), or a constant ``value``."""

    kind: ScheduleKind = bounded(ScheduleKind.PAPER, OneOf(ScheduleKind))
    minimum: float = bounded(0.1, _STEP)
    value: float = bounded(1.0, _STEP)

    def __post_init__(self) -> None:
        validate(self)

    def schedule(self) -> Schedule:
        return PaperSchedule(self.minimum) if self.kind is ScheduleKind.PAPER else ConstantSchedule(self.value)

    def to_table(self) -> dict[str, Any]:
        return {"kind": "paper", "minimum": self.minimum} if self.kind is ScheduleKind.PAPER else {
            "kind": "constant", "value": self.value}


@dataclass(frozen=True)
class IscModel:
    """What initial-state compensation needs from the vehicle layer: S = ∂e/∂δx₀ and δ(trial, p)."""

    sensitivity: np.ndarray
    deviation: DeviationFn
    gain: float = 1.0
    center: bool = True


@dataclass(frozen=True)
class RuleChoice:
    """Which update rule a session uses.

    Attributes
    ----------
    name : a registered rule (:data:`RULES`).
    isc : wrap it in initial-state compensation.
    schedule : a fixed step-size schedule, or None for the rule's own (the paper's for ``paper``).
    """

    name: str = "paper"
    isc: bool = False
    schedule: ScheduleChoice | None = None

    def __post_init__(self) -> None:
        spec = RULES.get(self.name, source="rule")
        check_type("isc", self.isc, (bool, np.bool_), "True or False")
        check_type("schedule", self.schedule, (ScheduleChoice, type(None)), "a ScheduleChoice or None")
        if self.schedule is not None and not spec.takes_schedule:
            raise ConfigError(f"rule {self.name!r} takes no schedule: its step is its own")

    @property
    def label(self) -> str:
        """What users write: ``tsvd+isc``."""
        return f"{self.name}+isc" if self.isc else self.name

    @classmethod
    def parse(cls, text: str, *, schedule: ScheduleChoice | None = None, source: str = "--rule") -> RuleChoice:
        """``paper``, ``tsvd``, …, optionally with the suffix ``+isc``."""
        base, plus, suffix = str(text).strip().partition("+")
        if plus and suffix != "isc":
            raise ConfigError(f"{source} {text!r}: the only suffix is '+isc'")
        if base not in RULES:
            raise ConfigError(f"{source} {text!r}: unknown update rule; allowed: {', '.join(RULES.names())} "
                              f"(optionally with '+isc')")
        return cls(base, bool(plus), schedule)

    def to_table(self) -> dict[str, Any]:
        """The stored form: ``{"name": "tsvd+isc", "schedule": {...}}`` (as stores have always held it)."""
        if self.schedule is not None:
            schedule = self.schedule.to_table()
        elif RULES.get(self.name).own_steps:
            schedule = {"kind": "rule"}
        else:
            schedule = ScheduleChoice().to_table()
        return {"name": self.label, "schedule": schedule}

    @classmethod
    def from_table(cls, table: Mapping[str, Any], *, source: str) -> RuleChoice:
        """Inverse of :meth:`to_table`."""
        if not isinstance(table, Mapping) or not isinstance(table.get("name"), str):
            raise ConfigError(f"{source}: update rule {table!r}: expected a name and a schedule")
        schedule = table.get("schedule", {"kind": "rule"})
        if not isinstance(schedule, Mapping):
            raise ConfigError(f"{source}: step-size schedule {schedule!r}: expected a table")
        kind = schedule.get("kind")
        try:
            if kind == "rule":
                fixed = None
            elif kind == "paper":
                fixed = ScheduleChoice(ScheduleKind.PAPER, minimum=float(schedule.get("minimum", 0.1)))
            elif kind == "constant":
                fixed = ScheduleChoice(ScheduleKind.CONSTANT, value=float(schedule["value"]))
            else:
                raise ConfigError(f"step-size schedule {dict(schedule)!r}: expected kind 'paper', 'constant' or "
                                  f"'rule'")
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(f"{source}: {exc}") from None
        choice = cls.parse(table["name"], source=source)
        return cls(choice.name, choice.isc, fixed) if fixed is not None else choice


def make_rule(choice: RuleChoice | str, design: Design, *, isc: IscModel | None = None,
              **options: Any) -> UpdateRule:
    """Build the update rule ``choice`` for ``design``.

    Parameters
    ----------
    choice : a :class:`RuleChoice`, or its label (``"tsvd+isc"``).
    design : the nominal design (p⁰, J, C, the maneuver's scales and bounds).
    isc : the vehicle layer's sensitivity and deviation function; required for ``+isc``
        (e.g. :func:`aerobat.quadrotor.isc.quadrotor_isc`).
    options : passed to the rule's constructor (see each class).
    """
    if isinstance(choice, str):
        choice = RuleChoice.parse(choice, source="rule")
    check_type("choice", choice, RuleChoice, "a RuleChoice or a rule name ('paper', 'tsvd+isc', …)")
    check_type("design", design, Design, "a Design (from aerobat.design())")
    spec = RULES.get(choice.name, source="rule")
    schedule = choice.schedule.schedule() if choice.schedule is not None else None
    try:
        rule = spec.build(design, schedule, dict(options))
    except TypeError as exc:  # an option the rule does not take
        raise ConfigError(f"rule {choice.name!r}: {exc}") from None
    if choice.isc:
        if isc is None:
            raise ConfigError(f"rule {choice.label!r} needs the model's initial-state sensitivity "
                              f"(see aerobat.quadrotor.isc.quadrotor_isc)")
        rule = InitialStateCompensation(rule, isc.sensitivity, isc.deviation, gain=isc.gain, center=isc.center,
                                        name=choice.label)
    return rule
