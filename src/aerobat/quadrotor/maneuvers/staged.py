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

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from aerobat.config import as_path, dataclass_from_table, dataclass_to_table, read_toml
from aerobat.core.expressions import Expression, parse_expression
from aerobat.core.maneuver import ErrorKind, ErrorSpec, ParameterSpec, check_parameters
from aerobat.errors import ConfigError
from aerobat.quadrotor.dynamics import POS, QUAT, VEL, euler_zyx, hover_state, quaternion_from_rotation_vector
from aerobat.quadrotor.dynamics import rotation_angles as unwrapped_angles
from aerobat.quadrotor.program import CHANNEL_LIMITS, Program, RampDown, Switch
from aerobat.quadrotor.vehicle import VehicleParams

__all__ = ["StagedManeuver", "load_maneuver_file", "staged_from_spec", "vehicle_names"]

CHANNEL_FIELDS = {"collective_m_s2": "collective", "rate_p_rad_s": "rate_p", "rate_q_rad_s": "rate_q",
                  "rate_r_rad_s": "rate_r", "accel_p_rad_s2": "accel_p", "accel_q_rad_s2": "accel_q",
                  "accel_r_rad_s2": "accel_r"}
QUANTITIES = {
    **{f"position_{a}": ("m", ErrorKind.POSITION) for a in "xyz"},
    **{f"velocity_{a}": ("m/s", ErrorKind.VELOCITY) for a in "xyz"},
    **{f"rotation_{a}": ("rad", ErrorKind.ANGLE) for a in "xyz"},
    **{name: ("rad", ErrorKind.ANGLE) for name in ("roll", "pitch", "yaw")},
}
_TOP = ("name", "description", "constants", "parameters", "derived", "stages", "ramp_down", "initial", "errors")
_NAME_OK = "a letter or _ followed by letters, digits or _"


def vehicle_names(vehicle: VehicleParams) -> dict[str, float]:
    """The design vehicle's constants as expression names."""
    return {"m": vehicle.mass_kg, "l": vehicle.arm_length_m, "Ixx": vehicle.inertia_xx_kg_m2,
            "Iyy": vehicle.inertia_yy_kg_m2, "Izz": vehicle.inertia_zz_kg_m2, "g": vehicle.gravity_m_s2,
            "beta_min": vehicle.collective_reduced_min_m_s2, "beta_max": vehicle.collective_reduced_max_m_s2,
            "kappa": vehicle.drag_constant_m, "f_min": vehicle.rotor_thrust_min_n, "f_max": vehicle.rotor_thrust_max_n}


def _table(value: Any, where: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise ConfigError(f"{where}: expected a table, got {type(value).__name__}")
    return value


def _check_keys(table: Mapping[str, Any], allowed: tuple[str, ...], where: str) -> None:
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise ConfigError(f"{where}: unknown field(s) {', '.join(unknown)}; allowed: {', '.join(allowed)}")


def _text(table: Mapping[str, Any], key: str, default: str, where: str) -> str:
    """A string field (default if absent); :class:`ConfigError` naming the field if it is anything else."""
    value = table.get(key, default)
    if not isinstance(value, str):
        raise ConfigError(f"{where}.{key}: expected a string in quotes, got {type(value).__name__} {value!r}")
    return value


def _identifier(name: Any, where: str) -> str:
    if not isinstance(name, str) or not name.isidentifier() or name.startswith("__"):
        raise ConfigError(f"{where}: {name!r} is not a valid name ({_NAME_OK})")
    return name


def _number(value: Any, where: str, *, low: float = -math.inf, high: float = math.inf) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ConfigError(f"{where}: expected a finite number, got {value!r}")
    if not low <= value <= high:
        raise ConfigError(f"{where} = {value:g} is out of range: allowed [{low:g}, {high:g}]")
    return float(value)


def _topological(derived: Mapping[str, Expression], where: str) -> list[str]:
    """Derived names in an order where each comes after those it reads; a cycle is an error."""
    order: list[str] = []
    state: dict[str, int] = {}

    def visit(name: str, path: list[str]) -> None:
        if state.get(name) == 2:
            return
        if state.get(name) == 1:
            cycle = " → ".join([*path[path.index(name):], name])
            raise ConfigError(f"{where}.derived: cyclic definition {cycle}")
        state[name] = 1
        for dep in sorted(derived[name].names):
            if dep in derived:
                visit(dep, [*path, name])
        state[name] = 2
        order.append(name)

    for name in derived:
        visit(name, [])
    return order


@dataclass(frozen=True)
class _Stage:
    name: str
    duration: Expression
    inputs: tuple[tuple[str, Expression], ...]


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

    def __post_init__(self) -> None:
        if not isinstance(self.vehicle, VehicleParams):
            raise ConfigError(f"{self.source}: vehicle must be a VehicleParams, got {type(self.vehicle).__name__}")
        src, t = self.source, _table(self.table, self.source)
        _check_keys(t, _TOP, src)
        name = t.get("name")
        if not isinstance(name, str) or not name.strip():
            raise ConfigError(f"{src}: name: expected a non-empty string")
        object.__setattr__(self, "name", name.strip())
        fixed = vehicle_names(self.vehicle)
        constants: dict[str, float] = {}
        for key, value in _table(t.get("constants", {}), f"{src}.constants").items():
            _identifier(key, f"{src}.constants")
            if key in fixed:
                raise ConfigError(f"{src}.constants.{key}: {key!r} is a vehicle constant and cannot be redefined")
            expr = parse_expression(value, where=f"{src}.constants.{key}", known=frozenset({*fixed, *constants}))
            constants[key] = expr.evaluate({**fixed, **constants}, where=f"{src}.constants.{key}")
        base = {**fixed, **constants}
        params_table = _table(t.get("parameters", {}), f"{src}.parameters")
        if not params_table:
            raise ConfigError(f"{src}: [parameters]: define at least one learned parameter")
        specs, guesses = [], []
        for key, entry in params_table.items():
            where = f"{src}.parameters.{_identifier(key, f'{src}.parameters')}"
            if key in base:
                raise ConfigError(f"{where}: {key!r} is already a constant or vehicle name")
            entry = _table(entry, where)
            _check_keys(entry, ("description", "unit", "guess", "lower", "upper", "scale", "lower_name",
                                "upper_name"), where)
            bounds = [parse_expression(entry.get(b, inf), where=f"{where}.{b}", known=frozenset(base)).evaluate(
                base, where=f"{where}.{b}") if b in entry else inf for b, inf in (("lower", -math.inf),
                                                                                 ("upper", math.inf))]
            texts = {k: _text(entry, k, key if k == "description" else "", where)
                     for k in ("description", "unit", "lower_name", "upper_name")}
            try:
                specs.append(ParameterSpec(
                    name=key, description=texts["description"], unit=texts["unit"],
                    lower=bounds[0], upper=bounds[1],
                    scale=_number(parse_expression(entry.get("scale", 1.0), where=f"{where}.scale",
                                                   known=frozenset(base)).evaluate(base, where=f"{where}.scale"),
                                  f"{where}.scale", low=1e-12),
                    bound_names=(texts["lower_name"], texts["upper_name"])))
            except ConfigError as exc:
                raise ConfigError(f"{where}: {exc}") from None
            if "guess" not in entry:
                raise ConfigError(f"{where}: missing required field guess")
            guesses.append(parse_expression(entry["guess"], where=f"{where}.guess", known=frozenset(base)))
        object.__setattr__(self, "parameters", tuple(specs))
        pnames = frozenset(params_table)
        derived_raw = _table(t.get("derived", {}), f"{src}.derived")
        names = frozenset({*base, *pnames, *derived_raw})
        derived: dict[str, Expression] = {}
        for key, value in derived_raw.items():
            _identifier(key, f"{src}.derived")
            if key in base or key in pnames:
                raise ConfigError(f"{src}.derived.{key}: {key!r} is already a parameter, constant or vehicle name")
            derived[key] = parse_expression(value, where=f"{src}.derived.{key}", known=names)
        order = _topological(derived, src)
        stages_raw = t.get("stages")
        if not isinstance(stages_raw, list) or not stages_raw:
            raise ConfigError(f"{src}: [[stages]]: define at least one stage")
        stages = []
        for k, entry in enumerate(stages_raw):
            where = f"{src}.stages[{k}]"
            entry = _table(entry, where)
            _check_keys(entry, ("name", "duration_s", *CHANNEL_FIELDS), where)
            if "duration_s" not in entry:
                raise ConfigError(f"{where}: missing required field duration_s")
            inputs = tuple((CHANNEL_FIELDS[f], parse_expression(entry[f], where=f"{where}.{f}", known=names))
                           for f in CHANNEL_FIELDS if f in entry)
            stages.append(_Stage(_text(entry, "name", f"stage {k + 1}", where),
                                 parse_expression(entry["duration_s"], where=f"{where}.duration_s", known=names),
                                 inputs))
        ramp = _table(t.get("ramp_down", {}), f"{src}.ramp_down")
        _check_keys(ramp, ("collective_s", "rates_s"), f"{src}.ramp_down")
        ramps = {k: parse_expression(ramp.get(k, 0.0), where=f"{src}.ramp_down.{k}", known=names)
                 for k in ("collective_s", "rates_s")}
        initial = _table(t.get("initial", {}), f"{src}.initial")
        _check_keys(initial, ("position_m", "velocity_m_s", "attitude_rad"), f"{src}.initial")
        start = {k: self._vector(initial.get(k, [0.0, 0.0, 0.0]), f"{src}.initial.{k}")
                 for k in ("position_m", "velocity_m_s", "attitude_rad")}
        errors_raw = t.get("errors")
        if not isinstance(errors_raw, list) or not errors_raw:
            raise ConfigError(f"{src}: [[errors]]: name at least one final-state error")
        errors, targets, quantities = [], [], []
        for k, entry in enumerate(errors_raw):
            where = f"{src}.errors[{k}]"
            entry = _table(entry, where)
            _check_keys(entry, ("name", "quantity", "target", "scale"), where)
            quantity = entry.get("quantity")
            if not isinstance(quantity, str):
                raise ConfigError(f"{where}.quantity: expected one name in quotes, got {type(quantity).__name__} "
                                  f"{quantity!r}; allowed: {', '.join(QUANTITIES)}")
            if quantity not in QUANTITIES:
                raise ConfigError(f"{where}.quantity: {quantity!r}; allowed: {', '.join(QUANTITIES)}")
            unit, kind = QUANTITIES[quantity]
            ename = entry.get("name", quantity)
            if not isinstance(ename, str) or not ename:
                raise ConfigError(f"{where}.name: expected a non-empty string")
            scale = parse_expression(entry.get("scale", 0.1 if unit != "rad" else math.radians(5)),
                                     where=f"{where}.scale", known=frozenset(base)).evaluate(base, where=where)
            errors.append(ErrorSpec(name=ename, unit=unit, kind=kind,
                                    scale=_number(scale, f"{where}.scale", low=1e-12)))
            targets.append(parse_expression(entry.get("target", 0.0), where=f"{where}.target",
                                            known=frozenset(base)).evaluate(base, where=f"{where}.target"))
            quantities.append(quantity)
        if len(errors) > len(specs):
            raise ConfigError(f"{src}: {len(errors)} errors but only {len(specs)} parameters: each error needs a "
                              f"parameter to correct it (Sect. 4.1)")
        object.__setattr__(self, "errors", tuple(errors))
        object.__setattr__(self, "_compiled", {
            "base": base, "guesses": guesses, "derived": derived, "order": order, "stages": stages,
            "ramps": ramps, "start": start, "targets": np.array(targets), "quantities": quantities})
        guess = self.guess()
        problem = check_parameters(self.parameters, guess)
        if problem:
            raise ConfigError(f"{src}: the guess violates the bounds: {problem}")
        self._evaluate(guess, where=f"{src} (at the guess)")

    @staticmethod
    def _vector(value: Any, where: str) -> tuple[float, float, float]:
        if not isinstance(value, list) or len(value) != 3:
            raise ConfigError(f"{where}: expected an array of 3 numbers")
        return (_number(value[0], f"{where}[0]"), _number(value[1], f"{where}[1]"), _number(value[2], f"{where}[2]"))

    # ------------------------------------------------------------------ evaluation
    def _scope(self, params: np.ndarray, where: str) -> dict[str, float]:
        c = self.__dict__["_compiled"]
        scope = dict(c["base"])
        scope.update(zip((p.name for p in self.parameters), (float(v) for v in params), strict=True))
        for name in c["order"]:
            scope[name] = c["derived"][name].evaluate(scope, where=f"{where}: derived.{name}")
        return scope

    def _evaluate(self, params: np.ndarray, *, where: str) -> tuple[list[float], list[list[tuple[str, float]]],
                                                                     dict[str, float]]:
        c = self.__dict__["_compiled"]
        scope = self._scope(params, where)
        durations, values = [], []
        for k, stage in enumerate(c["stages"]):
            durations.append(stage.duration.evaluate(scope, where=f"{where}: stages[{k}].duration_s"))
            values.append([(ch, e.evaluate(scope, where=f"{where}: stages[{k}].{ch}")) for ch, e in stage.inputs])
        ramps = {k: e.evaluate(scope, where=f"{where}: ramp_down.{k}") for k, e in c["ramps"].items()}
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
                return f"stage {k} ({self.__dict__['_compiled']['stages'][k].name}) has negative duration {d:.4g} s"
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
        c = self.__dict__["_compiled"]
        return np.array([e.evaluate(c["base"], where=f"{self.source}.parameters.{p.name}.guess")
                         for e, p in zip(c["guesses"], self.parameters, strict=True)])

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
        start = self.__dict__["_compiled"]["start"]
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
        c = self.__dict__["_compiled"]
        s = np.asarray(final_state, dtype=float)
        unwrapped, euler = unwrapped_angles(s), euler_zyx(s)
        values = []
        for quantity in c["quantities"]:
            kind, _, axis = quantity.partition("_")
            index = "xyz".index(axis) if axis else ("roll", "pitch", "yaw").index(kind)
            values.append({"position": s[POS], "velocity": s[VEL], "rotation": unwrapped}.get(kind, euler)[index])
        return np.array(values) - c["targets"]

    def failure_hint(self, params: np.ndarray, error: np.ndarray) -> str | None:
        """Why a design from ``params`` (the guess) may fail: a target reached with the wrong sign.

        A component that ends on the opposite side of a non-zero target (by more than half the
        target) is what a rate or acceleration of the wrong sign does: a roll flip turned the other
        way, a step taken to the other side. None if nothing suggests it.
        """
        c = self.__dict__["_compiled"]
        error = np.asarray(error, dtype=float)
        if error.shape != c["targets"].shape or not np.all(np.isfinite(error)):
            return None
        wrong = []
        for spec, target, e in zip(self.errors, c["targets"], error, strict=True):
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
    _check_keys(spec, ("kind", "source", "maneuver", "vehicle"), source)
    vehicle = dataclass_from_table(VehicleParams, _table(spec.get("vehicle"), f"{source}.vehicle"),
                                   source=f"{source}.vehicle")
    return StagedManeuver(vehicle=vehicle, table=_table(spec.get("maneuver"), f"{source}.maneuver"),
                          source=str(spec.get("source", source)))
