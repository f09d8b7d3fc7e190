"""Typed specifications of the built-in job kinds: what a study puts in a job, field by field.

A job travels as JSON (to a local worker, a Dask cluster, the store), so :class:`~aerobat.experiments.job.Job`
keeps a plain table; these frozen dataclasses are that table's one definition. A study builds a job with
``Job(key, SPEC.kind, SPEC(...).to_table())``; the job function reads it back with ``SPEC.from_table(spec)``,
which names a missing or mistyped field. The tables keep the fields in declaration order, as stored
studies have them (their digests are unchanged), and an optional field that is None is left out.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypeVar

from aerobat.errors import ConfigError

__all__ = ["BenchmarkJob", "DesignJob", "LearnJob", "RuleRunJob"]

S = TypeVar("S", bound="_JobSpec")

_TYPES: dict[str, tuple[type, ...]] = {"dict": (dict,), "int": (int,), "float": (int, float), "str": (str,),
                                       "bool": (bool,)}


class _JobSpec:
    """Shared by the job specifications: the table and back."""

    kind: ClassVar[str]

    def to_table(self) -> dict[str, Any]:
        """The JSON-ready table (fields in order; a None is left out)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)  # type: ignore[arg-type]
                if getattr(self, f.name) is not None}

    @classmethod
    def from_table(cls: type[S], table: Mapping[str, Any], *, source: str = "job spec") -> S:
        """The specification of ``table``; :class:`ConfigError` naming ``source`` and the field."""
        if not isinstance(table, Mapping):
            raise ConfigError(f"{source}: expected a table, got {type(table).__name__}")
        values: dict[str, Any] = {}
        for f in dataclasses.fields(cls):  # type: ignore[arg-type]
            if f.name not in table:
                required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
                if required:
                    raise ConfigError(f"{source}: {cls.kind} job without its '{f.name}'")
                continue
            value = table[f.name]
            allowed = _allowed(str(f.type))
            if value is not None and allowed and (not isinstance(value, allowed)
                                                  or (isinstance(value, bool) and bool not in allowed)):
                raise ConfigError(f"{source}.{f.name}: expected {str(f.type).replace(' | None', '')}, "
                                  f"got {type(value).__name__}")
            values[f.name] = value
        return cls(**values)


def _allowed(hint: str) -> tuple[type, ...]:
    types: tuple[type, ...] = ()
    for part in hint.replace("[str, Any]", "").split("|"):
        types += _TYPES.get(part.strip(), ())
    return types


@dataclass(frozen=True)
class LearnJob(_JobSpec):
    """One learning run on one plant (a robustness study's vehicle)."""

    kind: ClassVar[str] = "learn"
    maneuver: dict[str, Any]
    """The maneuver's ``spec()``."""
    design: dict[str, Any]
    """The nominal design, computed once per study (``Design.to_json_dict``)."""
    model: dict[str, Any]
    """The nominal vehicle's table."""
    plant: dict[str, Any]
    """The plant choice's table (``PlantChoice.to_table``), its seed included."""
    properties: dict[str, Any] = field(default_factory=dict)
    """What was sampled to make this plant, by name (reported with the result)."""
    iterations: int = 30
    """Trials to fly."""
    rule: str = "paper"
    """The update rule's label."""
    tolerance_m: float = 0.12
    """Position error [m] that counts as success."""


@dataclass(frozen=True)
class RuleRunJob(_JobSpec):
    """One method (update rule or model-free baseline) learning one maneuver on one plant seed."""

    kind: ClassVar[str] = "rule_run"
    maneuver: dict[str, Any]
    design: dict[str, Any]
    model: dict[str, Any]
    plant: dict[str, Any]
    method: str
    """A rule's label or a baseline's name."""
    trials: int
    """Trials to fly."""
    tolerance_m: float = 0.12
    """Position error [m] that counts as reached."""
    scenario: str | None = None
    """The feedback study's scenario (reported with the result; None: not a feedback study's)."""
    scheme: str | None = None
    """The feedback study's scheme (reported with the result)."""


@dataclass(frozen=True)
class DesignJob(_JobSpec):
    """A nominal design of one maneuver (an envelope study's cell)."""

    kind: ClassVar[str] = "design"
    maneuver: dict[str, Any]
    model: dict[str, Any]
    continuation: bool = False
    """A flip that fails from its guess is tried again from its neighbours in rate."""


@dataclass(frozen=True)
class BenchmarkJob(_JobSpec):
    """One time-optimal solve (a point of a benchmark map)."""

    kind: ClassVar[str] = "benchmark"
    y_m: float
    z_m: float
    """The target [m]."""
    limits: dict[str, Any] = field(default_factory=dict)
    """The benchmark's limits (``BenchmarkLimits`` fields)."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.y_m) and math.isfinite(self.z_m)):
            raise ConfigError(f"benchmark job: the target ({self.y_m}, {self.z_m}) m must be finite")
