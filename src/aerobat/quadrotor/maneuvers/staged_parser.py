"""Reading a maneuver file's table: one function per section, in the order the sections are checked.

:func:`parse_maneuver_table` turns the TOML table of a maneuver file (``docs/maneuvers.md``)
into a :class:`ParsedManeuver`: the learned parameters, the expressions of the stages and
ramp-downs, the start and the final-state errors, every expression parsed once and every
number checked. Each ``parse_*`` function reads one section and raises
:class:`~aerobat.errors.ConfigError` naming the file and the field; the sections are read in
a fixed order (name, constants, parameters, derived, stages, ramp_down, initial, errors), so
a file with several mistakes always reports the same one first.
:class:`~aerobat.quadrotor.maneuvers.staged.StagedManeuver` evaluates what this returns.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from aerobat.core.expressions import Expression, parse_expression
from aerobat.core.maneuver import ErrorKind, ErrorSpec, ParameterSpec
from aerobat.errors import ConfigError
from aerobat.quadrotor.vehicle import VehicleParams

__all__ = [
    "CHANNEL_FIELDS",
    "QUANTITIES",
    "ParsedManeuver",
    "Stage",
    "check_keys",
    "parse_maneuver_table",
    "expect_table",
    "vehicle_names",
]

CHANNEL_FIELDS = {"collective_m_s2": "collective", "rate_p_rad_s": "rate_p", "rate_q_rad_s": "rate_q",
                  "rate_r_rad_s": "rate_r", "accel_p_rad_s2": "accel_p", "accel_q_rad_s2": "accel_q",
                  "accel_r_rad_s2": "accel_r"}
"""A stage's input fields in the file → the program's channel names."""
QUANTITIES = {
    **{f"position_{a}": ("m", ErrorKind.POSITION) for a in "xyz"},
    **{f"velocity_{a}": ("m/s", ErrorKind.VELOCITY) for a in "xyz"},
    **{f"rotation_{a}": ("rad", ErrorKind.ANGLE) for a in "xyz"},
    **{name: ("rad", ErrorKind.ANGLE) for name in ("roll", "pitch", "yaw")},
}
"""The final-state quantities an ``[[errors]]`` entry may name → (unit, kind)."""
_TOP = ("name", "description", "constants", "parameters", "derived", "stages", "ramp_down", "initial", "errors")
_PARAMETER_FIELDS = ("description", "unit", "guess", "lower", "upper", "scale", "lower_name", "upper_name")
_RAMPS = ("collective_s", "rates_s")
_START = ("position_m", "velocity_m_s", "attitude_rad")
_NAME_OK = "a letter or _ followed by letters, digits or _"


@dataclass(frozen=True)
class Stage:
    """One ``[[stages]]`` entry: its name, its duration (s) and its constant inputs (channel, value)."""

    name: str
    duration: Expression
    inputs: tuple[tuple[str, Expression], ...]


@dataclass(frozen=True, eq=False)
class ParsedManeuver:
    """A maneuver file's table, checked and with every expression parsed.

    Parameters
    ----------
    name : the maneuver's name (stripped).
    base : the vehicle's constants and the file's ``[constants]``, by name (numbers).
    parameters : the learned parameters, in file order.
    guesses : each parameter's ``guess`` (an expression of ``base``).
    derived : the ``[derived]`` expressions by name; ``order`` evaluates each after those it reads.
    order : the derived names in evaluation order.
    stages : the ``[[stages]]``, in order.
    ramps : the ``[ramp_down]`` durations (s), ``collective_s`` and ``rates_s``.
    start : the ``[initial]`` vectors ``position_m``, ``velocity_m_s``, ``attitude_rad``.
    errors : the final-state errors that matter.
    targets : each error's target, in its unit.
    quantities : each error's quantity (a key of :data:`QUANTITIES`).
    """

    name: str
    base: Mapping[str, float]
    parameters: tuple[ParameterSpec, ...]
    guesses: tuple[Expression, ...]
    derived: Mapping[str, Expression]
    order: tuple[str, ...]
    stages: tuple[Stage, ...]
    ramps: Mapping[str, Expression]
    start: Mapping[str, tuple[float, float, float]]
    errors: tuple[ErrorSpec, ...]
    targets: np.ndarray
    quantities: tuple[str, ...]


def vehicle_names(vehicle: VehicleParams) -> dict[str, float]:
    """The design vehicle's constants as expression names."""
    return {"m": vehicle.mass_kg, "l": vehicle.arm_length_m, "Ixx": vehicle.inertia_xx_kg_m2,
            "Iyy": vehicle.inertia_yy_kg_m2, "Izz": vehicle.inertia_zz_kg_m2, "g": vehicle.gravity_m_s2,
            "beta_min": vehicle.collective_reduced_min_m_s2, "beta_max": vehicle.collective_reduced_max_m_s2,
            "kappa": vehicle.drag_constant_m, "f_min": vehicle.rotor_thrust_min_n, "f_max": vehicle.rotor_thrust_max_n}


def parse_maneuver_table(content: Any, vehicle: VehicleParams, source: str) -> ParsedManeuver:
    """A maneuver file's ``content`` (a TOML table) checked and parsed; ``source`` names it in messages."""
    src, t = source, expect_table(content, source)
    check_keys(t, _TOP, src)
    name = parse_name(t, src)
    fixed = vehicle_names(vehicle)
    base = {**fixed, **parse_constants(t, src, fixed)}
    parameters, guesses = parse_parameters(t, src, base)
    derived, order = parse_derived(t, src, base, frozenset(p.name for p in parameters))
    names = frozenset({*base, *(p.name for p in parameters), *derived})
    stages = parse_stages(t, src, names)
    ramps = parse_ramp_down(t, src, names)
    start = parse_initial(t, src)
    errors, targets, quantities = parse_errors(t, src, base)
    if len(errors) > len(parameters):
        raise ConfigError(f"{src}: {len(errors)} errors but only {len(parameters)} parameters: each error needs a "
                          f"parameter to correct it (Sect. 4.1)")
    return ParsedManeuver(name=name, base=base, parameters=parameters, guesses=guesses, derived=derived,
                          order=order, stages=stages, ramps=ramps, start=start, errors=errors,
                          targets=np.array(targets), quantities=quantities)


# ------------------------------------------------------------------ the sections
def parse_name(t: Mapping[str, Any], src: str) -> str:
    """The top-level ``name``: a non-empty string, stripped."""
    name = t.get("name")
    if not isinstance(name, str) or not name.strip():
        raise ConfigError(f"{src}: name: expected a non-empty string")
    return name.strip()


def parse_constants(t: Mapping[str, Any], src: str, fixed: Mapping[str, float]) -> dict[str, float]:
    """``[constants]``: each an expression of the vehicle's names (``fixed``) and the constants before it."""
    constants: dict[str, float] = {}
    for key, value in expect_table(t.get("constants", {}), f"{src}.constants").items():
        _identifier(key, f"{src}.constants")
        if key in fixed:
            raise ConfigError(f"{src}.constants.{key}: {key!r} is a vehicle constant and cannot be redefined")
        expr = parse_expression(value, where=f"{src}.constants.{key}", known=frozenset({*fixed, *constants}))
        constants[key] = expr.evaluate({**fixed, **constants}, where=f"{src}.constants.{key}")
    return constants


def parse_parameters(t: Mapping[str, Any], src: str,
                     base: Mapping[str, float]) -> tuple[tuple[ParameterSpec, ...], tuple[Expression, ...]]:
    """``[parameters.NAME]``: the learned parameters and their guesses (at least one parameter)."""
    params_table = expect_table(t.get("parameters", {}), f"{src}.parameters")
    if not params_table:
        raise ConfigError(f"{src}: [parameters]: define at least one learned parameter")
    specs, guesses = [], []
    for key, entry in params_table.items():
        spec, guess = _parameter(key, entry, src, base)
        specs.append(spec)
        guesses.append(guess)
    return tuple(specs), tuple(guesses)


def _parameter(key: Any, entry: Any, src: str, base: Mapping[str, float]) -> tuple[ParameterSpec, Expression]:
    where = f"{src}.parameters.{_identifier(key, f'{src}.parameters')}"
    if key in base:
        raise ConfigError(f"{where}: {key!r} is already a constant or vehicle name")
    entry = expect_table(entry, where)
    check_keys(entry, _PARAMETER_FIELDS, where)
    known = frozenset(base)
    bounds = [parse_expression(entry.get(b, inf), where=f"{where}.{b}", known=known).evaluate(
        base, where=f"{where}.{b}") if b in entry else inf for b, inf in (("lower", -math.inf), ("upper", math.inf))]
    texts = {k: _text(entry, k, key if k == "description" else "", where)
             for k in ("description", "unit", "lower_name", "upper_name")}
    try:
        spec = ParameterSpec(
            name=key, description=texts["description"], unit=texts["unit"], lower=bounds[0], upper=bounds[1],
            scale=_number(parse_expression(entry.get("scale", 1.0), where=f"{where}.scale", known=known).evaluate(
                base, where=f"{where}.scale"), f"{where}.scale", low=1e-12),
            bound_names=(texts["lower_name"], texts["upper_name"]))
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    if "guess" not in entry:
        raise ConfigError(f"{where}: missing required field guess")
    return spec, parse_expression(entry["guess"], where=f"{where}.guess", known=known)


def parse_derived(t: Mapping[str, Any], src: str, base: Mapping[str, float],
                  parameters: frozenset[str]) -> tuple[dict[str, Expression], tuple[str, ...]]:
    """``[derived]``: expressions of everything else (and of each other, without cycles), and their order."""
    derived_raw = expect_table(t.get("derived", {}), f"{src}.derived")
    names = frozenset({*base, *parameters, *derived_raw})
    derived: dict[str, Expression] = {}
    for key, value in derived_raw.items():
        _identifier(key, f"{src}.derived")
        if key in base or key in parameters:
            raise ConfigError(f"{src}.derived.{key}: {key!r} is already a parameter, constant or vehicle name")
        derived[key] = parse_expression(value, where=f"{src}.derived.{key}", known=names)
    return derived, tuple(_topological(derived, src))


def parse_stages(t: Mapping[str, Any], src: str, names: frozenset[str]) -> tuple[Stage, ...]:
    """``[[stages]]``: at least one, each with a ``duration_s`` and inputs on :data:`CHANNEL_FIELDS`."""
    stages_raw = t.get("stages")
    if not isinstance(stages_raw, list) or not stages_raw:
        raise ConfigError(f"{src}: [[stages]]: define at least one stage")
    stages = []
    for k, entry in enumerate(stages_raw):
        where = f"{src}.stages[{k}]"
        entry = expect_table(entry, where)
        check_keys(entry, ("name", "duration_s", *CHANNEL_FIELDS), where)
        if "duration_s" not in entry:
            raise ConfigError(f"{where}: missing required field duration_s")
        inputs = tuple((CHANNEL_FIELDS[f], parse_expression(entry[f], where=f"{where}.{f}", known=names))
                       for f in CHANNEL_FIELDS if f in entry)
        stages.append(Stage(_text(entry, "name", f"stage {k + 1}", where),
                            parse_expression(entry["duration_s"], where=f"{where}.duration_s", known=names),
                            inputs))
    return tuple(stages)


def parse_ramp_down(t: Mapping[str, Any], src: str, names: frozenset[str]) -> dict[str, Expression]:
    """``[ramp_down]``: the thrust and rate ramp-down durations (s) of Sect. 7.2, zero by default."""
    ramp = expect_table(t.get("ramp_down", {}), f"{src}.ramp_down")
    check_keys(ramp, _RAMPS, f"{src}.ramp_down")
    return {k: parse_expression(ramp.get(k, 0.0), where=f"{src}.ramp_down.{k}", known=names) for k in _RAMPS}


def parse_initial(t: Mapping[str, Any], src: str) -> dict[str, tuple[float, float, float]]:
    """``[initial]``: the start's position (m), velocity (m/s) and attitude (rad), zero by default."""
    initial = expect_table(t.get("initial", {}), f"{src}.initial")
    check_keys(initial, _START, f"{src}.initial")
    return {k: _vector(initial.get(k, [0.0, 0.0, 0.0]), f"{src}.initial.{k}") for k in _START}


def parse_errors(t: Mapping[str, Any], src: str,
                 base: Mapping[str, float]) -> tuple[tuple[ErrorSpec, ...], list[float], tuple[str, ...]]:
    """``[[errors]]``: at least one; each error's spec, target and quantity."""
    errors_raw = t.get("errors")
    if not isinstance(errors_raw, list) or not errors_raw:
        raise ConfigError(f"{src}: [[errors]]: name at least one final-state error")
    errors, targets, quantities = [], [], []
    for k, entry in enumerate(errors_raw):
        where = f"{src}.errors[{k}]"
        entry = expect_table(entry, where)
        check_keys(entry, ("name", "quantity", "target", "scale"), where)
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
        errors.append(ErrorSpec(name=ename, unit=unit, kind=kind, scale=_number(scale, f"{where}.scale", low=1e-12)))
        targets.append(parse_expression(entry.get("target", 0.0), where=f"{where}.target",
                                        known=frozenset(base)).evaluate(base, where=f"{where}.target"))
        quantities.append(quantity)
    return tuple(errors), targets, tuple(quantities)


# ------------------------------------------------------------------ values
def expect_table(value: Any, where: str) -> Mapping[str, Any]:
    """``value`` if it is a table; :class:`~aerobat.errors.ConfigError` naming ``where`` if not."""
    if not isinstance(value, Mapping):
        raise ConfigError(f"{where}: expected a table, got {type(value).__name__}")
    return value


def check_keys(content: Mapping[str, Any], allowed: tuple[str, ...], where: str) -> None:
    """:class:`~aerobat.errors.ConfigError` naming the unknown fields of ``content`` and the allowed ones."""
    unknown = sorted(set(content) - set(allowed))
    if unknown:
        raise ConfigError(f"{where}: unknown field(s) {', '.join(unknown)}; allowed: {', '.join(allowed)}")


def _text(entry: Mapping[str, Any], key: str, default: str, where: str) -> str:
    """A string field (default if absent); :class:`ConfigError` naming the field if it is anything else."""
    value = entry.get(key, default)
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


def _vector(value: Any, where: str) -> tuple[float, float, float]:
    if not isinstance(value, list) or len(value) != 3:
        raise ConfigError(f"{where}: expected an array of 3 numbers")
    return (_number(value[0], f"{where}[0]"), _number(value[1], f"{where}[1]"), _number(value[2], f"{where}[2]"))


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
