"""Maneuvers described in files: stages of constant inputs whose durations and values are parameters.

A maneuver file (TOML, see ``docs/maneuvers.md``) says what the paper's Sect. 4 asks
for — an initial state, the final-state errors that matter, and a parameterized input
U(t, p) — without code:

* ``[parameters.NAME]``: the learned parameters (``guess``, ``lower``, ``upper``, ``scale``,
  ``unit``, ``description``);
* ``[constants]`` and ``[derived]``: named numbers and expressions (the algebraic links of
  Sect. 7, e.g. eq 36's duration that brings the rate back to zero);
* ``[[stages]]``: consecutive stages, each with a ``duration_s`` and constant values on the
  input channels ``collective_m_s2``, ``rate_p/q/r_rad_s``, ``accel_p/q/r_rad_s2``
  (every value a number, a parameter or an expression);
* ``[ramp_down]``: the thrust and rate ramp-downs of Sect. 7.2;
* ``[initial]``: where the maneuver starts (hover by default);
* ``[[errors]]``: the final-state components that matter, their targets and scales.

Frames (as everywhere in aerobat): world x, y horizontal and z up; body x forward, y left,
z up (along thrust); body rates p, q, r about body x, y, z, right-handed. A positive roll
rate tilts the thrust toward −y, a positive pitch rate toward +x. Expressions may use the
design vehicle's constants: ``m``, ``l``, ``Ixx``, ``Iyy``, ``Izz``, ``g``, ``beta_min``,
``beta_max`` (β̲, β̄), ``kappa``, ``f_min``, ``f_max``.

A stage of zero duration is valid (its inputs are simply never flown): a parameter at its
lower bound of zero never makes two switches collide.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from aerobat.config import as_path, dataclass_from_table, dataclass_to_table, read_toml
from aerobat.core.maneuver import ErrorSpec, ParameterSpec, check_parameters
from aerobat.errors import ConfigError
from aerobat.quadrotor.dynamics import POS, QUAT, VEL, euler_zyx, hover_state, quaternion_from_rotation_vector
from aerobat.quadrotor.dynamics import rotation_angles as unwrapped_angles
from aerobat.quadrotor.maneuvers.staged_parser import (
    CHANNEL_FIELDS,
    ParsedManeuver,
    check_keys,
    expect_table,
    parse_maneuver_table,
    vehicle_names,
)
from aerobat.quadrotor.program import CHANNEL_LIMITS, Program, RampDown, Switch
from aerobat.quadrotor.vehicle import VehicleParams

__all__ = ["StagedManeuver", "load_maneuver_file", "staged_from_spec", "vehicle_names"]


@dataclass(frozen=True, kw_only=True, eq=False)
class StagedManeuver:
    """A maneuver read from a file (``table`` is the file's content, kept whole for the store).

    Parameters
    ----------
    vehicle : the design model's constants (expressions may read them).
    table : the maneuver file's content (a TOML table).
    source : where it came from, for messages (a file name).
    """

    vehicle: VehicleParams
    table: Mapping[str, Any]
    source: str = "maneuver"
    name: str = field(init=False)
    parameters: tuple[ParameterSpec, ...] = field(init=False, repr=False, compare=False)
    errors: tuple[ErrorSpec, ...] = field(init=False, repr=False, compare=False)
    _parsed: ParsedManeuver = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.vehicle, VehicleParams):
            raise ConfigError(f"{self.source}: vehicle must be a VehicleParams, got {type(self.vehicle).__name__}")
        parsed = parse_maneuver_table(self.table, self.vehicle, self.source)
        object.__setattr__(self, "_parsed", parsed)
        object.__setattr__(self, "name", parsed.name)
        object.__setattr__(self, "parameters", parsed.parameters)
        object.__setattr__(self, "errors", parsed.errors)
        guess = self.guess()
        problem = check_parameters(self.parameters, guess)
        if problem:
            raise ConfigError(f"{self.source}: the guess violates the bounds: {problem}")
        self._evaluate(guess, where=f"{self.source} (at the guess)")

    # ------------------------------------------------------------------ evaluation
    def _scope(self, params: np.ndarray, where: str) -> dict[str, float]:
        c = self._parsed
        scope = dict(c.base)
        scope.update(zip((p.name for p in self.parameters), (float(v) for v in params), strict=True))
        for name in c.order:
            scope[name] = c.derived[name].evaluate(scope, where=f"{where}: derived.{name}")
        return scope

    def _evaluate(self, params: np.ndarray, *, where: str) -> tuple[list[float], list[list[tuple[str, float]]],
                                                                     dict[str, float]]:
        c = self._parsed
        scope = self._scope(params, where)
        durations, values = [], []
        for k, stage in enumerate(c.stages):
            durations.append(stage.duration.evaluate(scope, where=f"{where}: stages[{k}].duration_s"))
            values.append([(ch, e.evaluate(scope, where=f"{where}: stages[{k}].{ch}")) for ch, e in stage.inputs])
        ramps = {k: e.evaluate(scope, where=f"{where}: ramp_down.{k}") for k, e in c.ramps.items()}
        return durations, values, ramps

    def _problem(self, params: np.ndarray) -> str | None:
        problem = check_parameters(self.parameters, params)
        if problem:
            return problem
        try:
            durations, values, ramps = self._evaluate(np.asarray(params, dtype=float), where=self.source)
        except ConfigError as exc:
            return str(exc)
        for k, d in enumerate(durations):
            if d < 0:
                return f"stage {k} ({self._parsed.stages[k].name}) has negative duration {d:.4g} s"
        if sum(durations) <= 0.01:
            return f"total duration {sum(durations):.4g} s must exceed 0.01 s"
        for k, stage_values in enumerate(values):
            for channel, v in stage_values:
                lo, hi = CHANNEL_LIMITS[channel.split("_")[0]]
                if not lo <= v <= hi:
                    return f"stage {k}: {channel} = {v:.4g} outside [{lo:g}, {hi:g}]"
        if any(r < 0 for r in ramps.values()):
            return "a ramp-down duration is negative"
        return None

    # ------------------------------------------------------------------ protocol
    def guess(self) -> np.ndarray:
        c = self._parsed
        return np.array([e.evaluate(c.base, where=f"{self.source}.parameters.{p.name}.guess")
                         for e, p in zip(c.guesses, self.parameters, strict=True)])

    def is_valid(self, params: np.ndarray) -> bool:
        return self._problem(params) is None

    def duration_s(self, params: np.ndarray) -> float:
        problem = self._problem(params)
        if problem:
            raise ConfigError(f"{self.name}: invalid parameters: {problem}")
        return float(sum(self._evaluate(np.asarray(params, dtype=float), where=self.source)[0]))

    def program(self, params: np.ndarray) -> Program:
        problem = self._problem(params)
        if problem:
            raise ConfigError(f"{self.name}: invalid parameters: {problem}")
        durations, values, ramps = self._evaluate(np.asarray(params, dtype=float), where=self.source)
        used = [ch for ch in CHANNEL_FIELDS.values() if any(ch == c for stage in values for c, _ in stage)]
        hover = {"collective": self.vehicle.gravity_m_s2}
        events: dict[tuple[str, float], float] = {}
        start = 0.0
        for d, stage in zip(durations, values, strict=True):
            given = dict(stage)
            for ch in used:  # a later stage at the same instant (zero duration) replaces the earlier one
                events[(ch, round(start, 12))] = given.get(ch, hover.get(ch, 0.0))
            start += d
        end = start
        switches = tuple(Switch(time_s=t, channel=ch, value=v)
                         for (ch, t), v in sorted(events.items(), key=lambda e: e[0][1]) if t < end)
        return Program(switches=switches, duration_s=end,
                       ramp_down=RampDown(collective_s=min(ramps["collective_s"], end),
                                          rates_s=min(ramps["rates_s"], end)),
                       hover_collective_m_s2=self.vehicle.gravity_m_s2, name=self.name)

    def initial_state(self) -> np.ndarray:
        start = self._parsed.start
        x = hover_state(self.vehicle, start["position_m"])
        x[VEL] = start["velocity_m_s"]
        roll, pitch, yaw = start["attitude_rad"]
        if roll or pitch or yaw:
            from aerobat.quadrotor.dynamics import quaternion_multiply

            qz = quaternion_from_rotation_vector(np.array([0.0, 0.0, yaw]))
            qy = quaternion_from_rotation_vector(np.array([0.0, pitch, 0.0]))
            qx = quaternion_from_rotation_vector(np.array([roll, 0.0, 0.0]))
            x[QUAT] = quaternion_multiply(quaternion_multiply(qz, qy), qx)
        return x

    def error(self, final_state: np.ndarray) -> np.ndarray:
        c = self._parsed
        s = np.asarray(final_state, dtype=float)
        unwrapped, euler = unwrapped_angles(s), euler_zyx(s)
        values = []
        for quantity in c.quantities:
            kind, _, axis = quantity.partition("_")
            index = "xyz".index(axis) if axis else ("roll", "pitch", "yaw").index(kind)
            values.append({"position": s[POS], "velocity": s[VEL], "rotation": unwrapped}.get(kind, euler)[index])
        return np.array(values) - c.targets

    def failure_hint(self, params: np.ndarray, error: np.ndarray) -> str | None:
        """Why a design from ``params`` (the guess) may fail: a target reached with the wrong sign.

        A component that ends on the opposite side of a non-zero target (by more than half the
        target) is what a rate or acceleration of the wrong sign does: a roll flip turned the other
        way, a step taken to the other side. None if nothing suggests it.
        """
        c = self._parsed
        error = np.asarray(error, dtype=float)
        if error.shape != c.targets.shape or not np.all(np.isfinite(error)):
            return None
        wrong = []
        for spec, target, e in zip(self.errors, c.targets, error, strict=True):
            reached = target + e
            if target != 0.0 and reached * target < 0.0 and abs(reached) > 0.5 * abs(target):
                wrong.append((abs(e) / spec.scale, spec, target, reached))
        if not wrong:
            return None
        _, spec, target, reached = max(wrong, key=lambda w: w[0])
        return (f"at the guess {spec.name} ends at {reached:+.3g} {spec.unit}, the opposite sign of its target "
                f"{target:+.3g}: a rate or acceleration of the wrong sign? (a positive roll rate tilts the thrust "
                f"toward -y, a positive pitch rate toward +x; docs/maneuvers.md, 'Frames and signs')")

    def spec(self) -> dict[str, Any]:
        return {"kind": "staged", "source": self.source, "maneuver": _plain(self.table),
                "vehicle": dataclass_to_table(self.vehicle)}


def _plain(value: Any) -> Any:
    """TOML values as JSON values (dates refused)."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if value is None or isinstance(value, bool | int | float | str):
        return value
    raise ConfigError(f"maneuver file: {value!r} ({type(value).__name__}) cannot be stored; use numbers and strings")


def load_maneuver_file(path: str | Path, vehicle: VehicleParams) -> StagedManeuver:
    """The maneuver a file describes, designed for ``vehicle``; :class:`ConfigError` naming the file and field."""
    path = as_path(path)
    table = read_toml(path)
    _plain(table)
    return StagedManeuver(vehicle=vehicle, table=table, source=str(path))


def staged_from_spec(spec: Mapping[str, Any], source: str) -> StagedManeuver:
    """Rebuild a :class:`StagedManeuver` from its ``spec()`` (registered as maneuver kind ``staged``)."""
    check_keys(spec, ("kind", "source", "maneuver", "vehicle"), source)
    vehicle = dataclass_from_table(VehicleParams, expect_table(spec.get("vehicle"), f"{source}.vehicle"),
                                   source=f"{source}.vehicle")
    return StagedManeuver(vehicle=vehicle, table=expect_table(spec.get("maneuver"), f"{source}.maneuver"),
                          source=str(spec.get("source", source)))
