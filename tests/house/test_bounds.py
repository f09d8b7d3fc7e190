"""Every declared bound refuses what is outside it, with one line naming the field and the range.

The parameter classes are found by walking :mod:`aerobat` for dataclasses with declared bounds
(:func:`aerobat.core.bounds.constraints`), and the bad inputs are derived from the declarations,
as scikit-learn's common tests do with its parameter constraints: a new bounded field is tested
without a line here.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import pkgutil
import textwrap

import pytest

import aerobat
from aerobat.core.bounds import BOUNDS, Integer, Interval, Items, OneOf, Span, bounded, constraints
from aerobat.errors import ConfigError


def _dataclasses() -> dict[str, type]:
    found: dict[str, type] = {}
    for info in pkgutil.walk_packages(aerobat.__path__, "aerobat."):
        if info.name.endswith("__main__"):  # running the command line is no declaration
            continue
        try:
            module = importlib.import_module(info.name)
        except ImportError:  # an optional dependency (RotorPy, CasADi) not installed
            continue
        for value in vars(module).values():
            if isinstance(value, type) and dataclasses.is_dataclass(value) and value.__module__ == info.name:
                found[f"{value.__module__}.{value.__qualname__}"] = value
    return dict(sorted(found.items()))


DATACLASSES = _dataclasses()
CLASSES = [cls for cls in DATACLASSES.values() if constraints(cls)]


def _translation():
    from aerobat.quadrotor.maneuvers.translation import Translation
    from aerobat.quadrotor.vehicle import VehicleParams

    return Translation(vehicle=VehicleParams(), target_yz=(1.0, 0.0), final_angle_rad=0.0,
                       interval_inputs=((10.0, 0.0),), guess_times_s=(0.5,))


def _multiflip():
    from aerobat.quadrotor.maneuvers import MultiFlip
    from aerobat.quadrotor.vehicle import VehicleParams

    return MultiFlip(vehicle=VehicleParams())


def _input_arc():
    from aerobat.quadrotor.timeoptimal.solution import ArcKind, InputArc

    return InputArc(kind=ArcKind.MAX, start_s=0.5, end_s=1.0, value=20.0)


def _program():
    from aerobat.quadrotor.program import Program

    return Program(switches=(), duration_s=1.0)


def _geometry():
    from aerobat.quadrotor.identification.logfit import Geometry

    return Geometry(mass_kg=0.5, motor_x_m=0.08, motor_y_m=0.1)


def _log_fit_options():
    from aerobat.quadrotor.identification.logfit import LogFitOptions

    return LogFitOptions(fixed_time_constant_s=0.03)  # a value, so that its bound is tested too (None: fitted)


def _parameter_spec():
    from aerobat.core.maneuver import ParameterSpec

    return ParameterSpec(name="p0", description="a duration", unit="s", lower=0.0, upper=2.0, scale=0.02)


def _error_spec():
    from aerobat.core.maneuver import ErrorSpec

    return ErrorSpec(name="z", unit="m", scale=0.1)


def _firmware_config():
    from aerobat.plants.fpv.design_model import firmware_config, plant_settings
    from aerobat.plants.fpv.params import BetaflightParams

    return firmware_config(plant_settings(BetaflightParams()), gyro_rate_hz=8000)


def _airframe():
    from aerobat.quadrotor.xframe import Airframe

    # values, so that their bounds are tested too (None: the log's median; no battery model)
    return Airframe(battery_reference_v=23.7, battery_rest_v=24.2, battery_sag_v=4.2)


EXAMPLES = {
    # classes with required fields (or a default of None): one valid instance each (the others are
    # built with their defaults)
    "aerobat.quadrotor.maneuvers.translation.Translation": _translation,
    "aerobat.quadrotor.maneuvers.flip.MultiFlip": _multiflip,
    "aerobat.quadrotor.timeoptimal.solution.InputArc": _input_arc,
    "aerobat.quadrotor.program.Program": _program,
    "aerobat.quadrotor.identification.logfit.Geometry": _geometry,
    "aerobat.quadrotor.identification.logfit.LogFitOptions": _log_fit_options,
    "aerobat.core.maneuver.ParameterSpec": _parameter_spec,
    "aerobat.core.maneuver.ErrorSpec": _error_spec,
    "aerobat.quadrotor.firmware.config.FirmwareConfig": _firmware_config,
    "aerobat.quadrotor.xframe.Airframe": _airframe,
    "aerobat.store.query.SessionQuery": lambda: __import__("aerobat.store.query", fromlist=["SessionQuery"])
    .SessionQuery(study=3, limit=50, offset=100),  # values, so that their bounds are tested too (None: all)
}


def _example(cls: type):
    key = f"{cls.__module__}.{cls.__qualname__}"
    if key in EXAMPLES:
        return EXAMPLES[key]()
    return cls()


def _cases() -> list[tuple[type, str, object, str]]:
    cases = []
    for cls in CLASSES:
        default = _example(cls)
        for name, constraint in constraints(cls).items():
            if isinstance(constraint, Items | Span):
                for label, value, allowed in constraint.outside_items(getattr(default, name), default):
                    cases.append((cls, name, value, f"{name}{label}", allowed))
            else:
                for value in constraint.outside(default):
                    cases.append((cls, name, value, name, constraint.describe(default)))
    return cases


def test_the_walk_finds_the_parameter_classes():
    names = {cls.__name__ for cls in CLASSES}
    assert {"Aerodynamics", "Disturbances", "Drift", "MotionCapture", "Supervisor", "Volume"} <= names
    assert {"BenchmarkLimits", "InputArc", "RampDown", "Program", "Geometry", "LogFitOptions", "ParameterSpec",
            "ErrorSpec", "SafetyLimits", "PlantChoice"} <= names


@pytest.mark.parametrize("cls, field, value, where, allowed", _cases(),
                         ids=lambda v: v.__name__ if isinstance(v, type) else None)
def test_a_value_outside_the_declared_bound_is_refused_naming_field_and_range(cls, field, value, where, allowed):
    with pytest.raises(ConfigError) as info:
        dataclasses.replace(_example(cls), **{field: value})
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{where} = ")
    assert message.endswith(f"allowed {allowed}")


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_the_defaults_are_inside_their_bounds(cls):
    default = _example(cls)
    for name, constraint in constraints(cls).items():
        assert constraint.check(name, getattr(default, name), default) == getattr(default, name)


def test_the_constraints_describe_their_ranges_as_the_messages_do():
    assert Interval(0.0, 600.0, closed="right", unit="s").describe() == "(0, 600] (s)"
    assert Interval(low=0.0).describe() == ">= 0"
    assert Interval(high=0.0, closed="left").describe() == "< 0"
    assert Integer(1, 10_000).describe() == "1 … 10000"
    fence = Span(Interval(-50.0, 50.0, unit="m"), strict=True, end=50.0)
    assert fence.describe() == "[0] [-50, 50] (m); [1] > [0], <= 50"
    with pytest.raises(ConfigError, match=r"^n = 2.5 must be an integer|^n must be an integer, got float 2.5$"):
        Integer(1, 3).check("n", 2.5)


def test_choices_come_from_the_enum_or_the_literal():
    from aerobat.core.correction import CorrectionKind
    from aerobat.quadrotor.feedback import FeedbackScheme

    assert OneOf(CorrectionKind).choices == ("inverse", "tsvd", "damped")
    assert OneOf(FeedbackScheme).choices == tuple(s.value for s in FeedbackScheme)
    assert OneOf(FeedbackScheme).check("scheme", "none") is FeedbackScheme.NONE
    with pytest.raises(ConfigError, match=r"^correction = 'svd': allowed 'inverse', 'tsvd', 'damped'$"):
        OneOf(CorrectionKind).check("correction", "svd")


RANGE_CHECKS = {"check_range", "check_int", "check_number"}
"""The :mod:`aerobat.config` checks a field's range is declared with instead (``Interval``, ``Integer``)."""

UNDECLARED = {
    # "module.Class": "why its __post_init__ checks a field's range by hand instead of declaring it",
    # (none now: cross-field limits are declared with a limit naming the other field, e.g.
    # Interval("rotor_thrust_min_n", ...), and a check across sections, as ArenaParams's radio
    # latency against its rate and tick, raises its own ConfigError without these helpers)
}
"""Dataclasses allowed to call :data:`RANGE_CHECKS` on their own fields in ``__post_init__``, each with its reason."""


def _range_checks_by_hand(cls: type) -> list[str]:
    """The :data:`RANGE_CHECKS` calls in ``cls.__post_init__`` (what it checks is its own fields), as source text."""
    post_init = vars(cls).get("__post_init__")
    if post_init is None:
        return []
    calls = []
    for node in ast.walk(ast.parse(textwrap.dedent(inspect.getsource(post_init)))):
        if isinstance(node, ast.Call):
            func = node.func
            name = func.id if isinstance(func, ast.Name) else func.attr if isinstance(func, ast.Attribute) else None
            if name in RANGE_CHECKS:
                calls.append(ast.unparse(node))
    return calls


def test_no_parameter_class_checks_its_own_ranges_by_hand():
    by_hand = {key: calls for key, cls in DATACLASSES.items() if (calls := _range_checks_by_hand(cls))}
    undeclared = {key: calls for key, calls in by_hand.items() if key not in UNDECLARED}
    assert not undeclared, ("declare these bounds next to the field (bounded(default, Interval(...)) and "
                            f"validate(self)), or allow-list the class with its reason: {undeclared}")
    assert set(UNDECLARED) <= set(by_hand), f"allowed but checks nothing by hand now: {set(UNDECLARED) - set(by_hand)}"


ORDERINGS = (ast.Lt, ast.LtE, ast.Gt, ast.GtE)
REFUSALS = {"ConfigError", "ValueError"}

CROSS_FIELD = {
    "aerobat.core.maneuver.ParameterSpec": "lower < upper, where either may be infinite (no bound), which no "
                                           "Interval allows",
}
"""Dataclasses whose ``__post_init__`` compares fields without declared bounds itself, each with its reason."""


def _refuses(statements: list[ast.stmt]) -> bool:
    for node in (n for s in statements for n in ast.walk(s)):
        if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call):
            func = node.exc.func
            if (func.id if isinstance(func, ast.Name) else getattr(func, "attr", None)) in REFUSALS:
                return True
    return False


def _compared_by_hand(cls: type) -> list[str]:
    """Undeclared fields of ``cls`` whose value ``__post_init__`` compares (<, <=, >, >=) in an ``if`` that raises
    :class:`ConfigError` or ``ValueError``: ``self.field`` itself, or a name bound to ``getattr(self, …)`` or
    ``self.field``, as an operand (a field inside a call, ``len(self.items)`` or ``np.diff(self.times)``, is its
    shape or order, not its range)."""
    post_init = vars(cls).get("__post_init__")
    if post_init is None:
        return []
    tree = ast.parse(textwrap.dedent(inspect.getsource(post_init)))
    fields = {f.name: f for f in dataclasses.fields(cls)}
    bound: dict[str, str] = {}  # local name -> the field (or getattr's argument) it holds
    for node in ast.walk(tree):
        if not isinstance(node, ast.Assign):
            continue
        value, source = node.value, None
        if (isinstance(value, ast.Call) and isinstance(value.func, ast.Name) and value.func.id == "getattr"
                and isinstance(value.args[0], ast.Name) and value.args[0].id == "self"):
            source = ast.unparse(value.args[1])
        elif isinstance(value, ast.Attribute) and isinstance(value.value, ast.Name) and value.value.id == "self":
            source = value.attr
        if source is not None:
            bound.update({name.id: source for target in node.targets for name in ast.walk(target)
                          if isinstance(name, ast.Name)})
    found = set()
    for node in ast.walk(tree):
        if not isinstance(node, ast.If) or not _refuses(node.body):
            continue
        for compare in (c for c in ast.walk(node.test) if isinstance(c, ast.Compare)):
            if not any(isinstance(op, ORDERINGS) for op in compare.ops):
                continue
            for operand in (compare.left, *compare.comparators):
                for name in (operand, *(operand.elts if isinstance(operand, ast.Tuple) else ())):
                    if isinstance(name, ast.Attribute) and isinstance(name.value, ast.Name) and name.value.id == "self":
                        field = name.attr
                    elif isinstance(name, ast.Name) and name.id in bound:
                        field = bound[name.id]
                    else:
                        continue
                    if field not in fields or BOUNDS not in fields[field].metadata:
                        found.add(f"{field}: {ast.unparse(node.test)}")
    return sorted(found)


def test_no_parameter_class_compares_undeclared_fields_by_hand():
    by_hand = {key: found for key, cls in DATACLASSES.items() if (found := _compared_by_hand(cls))}
    undeclared = {key: found for key, found in by_hand.items() if key not in CROSS_FIELD}
    assert not undeclared, ("declare these bounds next to the field (bounded(default, Interval(...)), a limit "
                            f"may name another field) or list a genuine cross-field check in CROSS_FIELD: {undeclared}")
    stale = set(CROSS_FIELD) - set(by_hand)
    assert not stale, f"listed but compares nothing by hand now: {stale}"


def test_the_scan_sees_a_comparison_by_hand():
    @dataclasses.dataclass(frozen=True)
    class Compared:
        low_s: float = 0.0
        high_s: float = 1.0
        items: tuple[float, ...] = ()
        gain: float = bounded(1.0, Interval(0.0, 2.0))

        def __post_init__(self) -> None:
            for name in ("low_s", "high_s"):
                value = getattr(self, name)
                if value < 0:
                    raise ConfigError(f"{name} = {value}: allowed >= 0")
            if len(self.items) > 3 or self.gain > 1.5:  # a length, and a declared field: not flagged
                raise ValueError("too many")
            if not self.low_s < self.high_s:
                raise ConfigError("low_s must be below high_s")

    assert _compared_by_hand(Compared) == [
        "high_s: not self.low_s < self.high_s", "low_s: not self.low_s < self.high_s", "name: value < 0"]
    assert _compared_by_hand(CLASSES[0]) == []


def test_the_scan_sees_a_range_checked_by_hand():
    from aerobat import config

    @dataclasses.dataclass(frozen=True)
    class ByHand:
        gain: float = 1.0
        rates: tuple[float, float] = (1.0, 2.0)

        def __post_init__(self) -> None:
            for i, value in enumerate(self.rates):
                config.check_range(f"rates[{i}]", value, low=0.0)

    assert _range_checks_by_hand(ByHand) == ["config.check_range(f'rates[{i}]', value, low=0.0)"]
    assert _range_checks_by_hand(CLASSES[0]) == []
