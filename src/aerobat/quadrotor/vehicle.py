"""Vehicle and onboard-controller constants (paper Sect. 6, Table 1).

Two parameter sets, deliberately separate:

* :class:`VehicleParams` — the *physical* constants of a rigid-body quadrocopter
  (what the model, or a simulated testbed, integrates).
* :class:`ControllerParams` — what the *onboard* rate controller believes: its
  gains and the nominal constants it inverts eq 10 with (eqs 14–21). A real
  vehicle's true constants differ from these; the controller never learns that.

Motor numbering follows the paper's Fig. 4 and eq 10: motor 1 on +x_b, motor 2 on
+y_b, motor 3 on −x_b, motor 4 on −y_b; motors 1 and 3 produce +κ·f yaw moment,
motors 2 and 4 produce −κ·f.

A :class:`VehicleConfig` may add :class:`ModelEffects`, terms the paper's model leaves
out (rate-loop latency, rate damping, thrust-proportional moments, drag); an
identified vehicle (``aerobat identify``) carries them, and the design model
simulates them. All zero is the paper's model, and is what every preset uses.

Vehicle files (:func:`load_vehicle`) are ``name``, ``[vehicle]``, an optional
``[controller]``, an optional ``[effects]`` and an optional ``[source]`` (where the
numbers come from: citations, or the identification that produced them). Presets
are package data, one file each, in ``aerobat/quadrotor/vehicles/``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import tomli_w

from aerobat.config import (
    as_path,
    check_finite,
    check_type,
    dataclass_from_table,
    dataclass_to_table,
    read_toml,
    short_repr,
    write_file,
)
from aerobat.core.bounds import Interval, Items, bounded, validate
from aerobat.errors import ConfigError

__all__ = [
    "PRESETS",
    "ControllerParams",
    "ModelEffects",
    "VehicleConfig",
    "VehicleParams",
    "fpv5",
    "hummingbird",
    "load_vehicle",
    "preset",
    "preset_names",
    "save_vehicle",
    "vehicle_from_name_or_file",
    "vehicle_from_table",
    "vehicle_table",
]

STANDARD_GRAVITY_M_S2 = 9.81

_MASS = Interval(0.01, 100.0, unit="kg")
_ARM = Interval(0.01, 5.0, unit="m")
_INERTIA = Interval(1e-7, 100.0, unit="kg m²")
_MOTOR_RATE = Interval(0.1, 1e4, unit="1/s")
_DRAG_CONSTANT = Interval(1e-5, 1.0, unit="m")
_RATE_GAIN = Interval(0.0, 1e4, unit="1/s")
_REDUCED_ENVELOPE = ("collective_reduced_min_m_s2", "collective_reduced_max_m_s2")


@dataclass(frozen=True, kw_only=True)
class VehicleParams:
    """Physical constants of a quadrocopter (Table 1 of the paper).

    Attributes
    ----------
    mass_kg : vehicle mass m [kg].
    arm_length_m : motor-to-centre distance l [m].
    inertia_xx_kg_m2, inertia_yy_kg_m2, inertia_zz_kg_m2 : principal inertia [kg m²].
    motor_rate_up_per_s : first-order motor rate P_f,up when thrust rises [1/s].
    motor_rate_down_per_s : first-order motor rate P_f,dn when thrust falls [1/s].
    rotor_thrust_min_n, rotor_thrust_max_n : per-rotor thrust limits f_min, f_max [N].
    collective_reduced_min_m_s2 : β̲, reduced-envelope minimum mass-normalized collective [m/s²].
    collective_reduced_max_m_s2 : β̄, reduced-envelope maximum mass-normalized collective [m/s²].
    drag_constant_m : κ, rotor thrust-to-drag-moment constant [m].
    gravity_m_s2 : gravitational acceleration g [m/s²].
    """

    mass_kg: float = bounded(0.468, _MASS)
    arm_length_m: float = bounded(0.17, _ARM)
    inertia_xx_kg_m2: float = bounded(0.0023, _INERTIA)
    inertia_yy_kg_m2: float = bounded(0.0023, _INERTIA)
    inertia_zz_kg_m2: float = bounded(0.0046, _INERTIA)
    motor_rate_up_per_s: float = bounded(80.0, _MOTOR_RATE)
    motor_rate_down_per_s: float = bounded(60.0, _MOTOR_RATE)
    rotor_thrust_min_n: float = bounded(0.08, Interval(0.0, 1e4, unit="N"))
    rotor_thrust_max_n: float = bounded(2.8, Interval("rotor_thrust_min_n", 1e4, closed="right", unit="N"))
    collective_reduced_min_m_s2: float = bounded(3.92, Interval(
        "collective_min_m_s2", "gravity_m_s2", closed="neither", unit="m/s², eq 24: 4 f_min/m < β̲ < g"))
    collective_reduced_max_m_s2: float = bounded(21.58, Interval(
        "gravity_m_s2", "collective_max_m_s2", closed="neither", unit="m/s², eq 24: g < β̄ < 4 f_max/m"))
    drag_constant_m: float = bounded(0.016, _DRAG_CONSTANT)
    gravity_m_s2: float = bounded(STANDARD_GRAVITY_M_S2, Interval(0.1, 100.0, unit="m/s²"))

    def __post_init__(self) -> None:
        # the envelope's limits depend on the others: checked last, once hover is known to fit in it
        validate(self, skip=_REDUCED_ENVELOPE)
        # eq 24: 4 f_min < m β̲ <= m β̄ < 4 f_max, and hover must be inside the envelope.
        lo, hi = self.collective_min_m_s2, self.collective_max_m_s2
        if hi <= self.gravity_m_s2:
            raise ConfigError(f"rotor_thrust_max_n = {self.rotor_thrust_max_n:g} N is too small for mass_kg = "
                              f"{self.mass_kg:g} kg: four rotors give at most 4 f_max/m = {hi:.3g} m/s², below "
                              f"gravity_m_s2 = {self.gravity_m_s2:g}; the vehicle cannot hover")
        if lo >= self.gravity_m_s2:
            raise ConfigError(f"rotor_thrust_min_n = {self.rotor_thrust_min_n:g} N is too large for mass_kg = "
                              f"{self.mass_kg:g} kg: 4 f_min/m = {lo:.3g} m/s² is above gravity_m_s2 = "
                              f"{self.gravity_m_s2:g}; the vehicle cannot hover")
        validate(self, only=_REDUCED_ENVELOPE)

    # ---- derived quantities -------------------------------------------------
    @property
    def hover_thrust_n(self) -> float:
        """Total thrust that balances gravity, m·g [N]."""
        return self.mass_kg * self.gravity_m_s2

    @property
    def hover_rotor_thrust_n(self) -> float:
        """Per-rotor thrust in hover, m·g/4 [N]."""
        return self.hover_thrust_n / 4.0

    @property
    def collective_min_m_s2(self) -> float:
        """Absolute minimum mass-normalized collective, 4 f_min / m [m/s²]."""
        return 4.0 * self.rotor_thrust_min_n / self.mass_kg

    @property
    def collective_max_m_s2(self) -> float:
        """Absolute maximum mass-normalized collective, 4 f_max / m [m/s²]."""
        return 4.0 * self.rotor_thrust_max_n / self.mass_kg

    @property
    def max_roll_acceleration_rad_s2(self) -> float:
        """Eq 27: largest |â_p| on the reduced envelope, l m (β̄ − β̲) / (4 I_xx) [rad/s²]."""
        return self.arm_length_m * self.mass_kg * (
            self.collective_reduced_max_m_s2 - self.collective_reduced_min_m_s2
        ) / (4.0 * self.inertia_xx_kg_m2)

    def with_mass(self, mass_kg: float) -> VehicleParams:
        """The same vehicle with another mass: the per-rotor thrust limits stay (they are the motors'),
        so the reduced collective envelope β̲, β̄ scales with 1/m, keeping the same thrust margins."""
        if isinstance(mass_kg, bool) or not isinstance(mass_kg, int | float) or not mass_kg > 0:
            raise ConfigError(f"mass_kg = {mass_kg!r}: expected a number > 0 (kg)")
        check_finite("mass_kg", mass_kg, "kg")
        k = self.mass_kg / float(mass_kg)
        return dataclasses.replace(self, mass_kg=float(mass_kg),
                                   collective_reduced_min_m_s2=self.collective_reduced_min_m_s2 * k,
                                   collective_reduced_max_m_s2=self.collective_reduced_max_m_s2 * k)

    @property
    def max_pitch_acceleration_rad_s2(self) -> float:
        """Eq 27 for the pitch axis, l m (β̄ − β̲) / (4 I_yy) [rad/s²]."""
        return self.arm_length_m * self.mass_kg * (
            self.collective_reduced_max_m_s2 - self.collective_reduced_min_m_s2
        ) / (4.0 * self.inertia_yy_kg_m2)


@dataclass(frozen=True, kw_only=True)
class ControllerParams:
    """The onboard rate controller (eqs 14–21) and the nominal constants it inverts with.

    Attributes
    ----------
    rate_gain_p_per_s, rate_gain_q_per_s, rate_gain_r_per_s : P_p, P_q, P_r [1/s].
    mass_kg, arm_length_m, inertia_*_kg_m2, drag_constant_m : the *nominal* m, l, I, κ
        used to turn desired angular accelerations into motor thrusts.
    motor_order : which physical motor slot (1–4, paper numbering) receives the
        controller's motor command 1, 2, 3, 4. Identity on a correctly wired vehicle.
    """

    rate_gain_p_per_s: float = bounded(100.0, _RATE_GAIN)
    rate_gain_q_per_s: float = bounded(100.0, _RATE_GAIN)
    rate_gain_r_per_s: float = bounded(10.0, _RATE_GAIN)
    mass_kg: float = bounded(0.468, _MASS)
    arm_length_m: float = bounded(0.17, _ARM)
    inertia_xx_kg_m2: float = bounded(0.0023, _INERTIA)
    inertia_yy_kg_m2: float = bounded(0.0023, _INERTIA)
    inertia_zz_kg_m2: float = bounded(0.0046, _INERTIA)
    drag_constant_m: float = bounded(0.016, _DRAG_CONSTANT)
    motor_order: tuple[int, int, int, int] = (1, 2, 3, 4)
    """Checked by hand: a permutation, which no per-item range says."""

    def __post_init__(self) -> None:
        validate(self)
        order = self.motor_order
        whole = isinstance(order, tuple | list) and all(isinstance(m, int) and not isinstance(m, bool) for m in order)
        if not whole or sorted(order) != [1, 2, 3, 4]:
            raise ConfigError(f"motor_order = {short_repr(order)} must be a permutation of (1, 2, 3, 4)")

    @classmethod
    def nominal_for(cls, vehicle: VehicleParams, **gains: Any) -> ControllerParams:
        """A controller that inverts with exactly ``vehicle``'s constants (the design model)."""
        return cls(
            mass_kg=vehicle.mass_kg,
            arm_length_m=vehicle.arm_length_m,
            inertia_xx_kg_m2=vehicle.inertia_xx_kg_m2,
            inertia_yy_kg_m2=vehicle.inertia_yy_kg_m2,
            inertia_zz_kg_m2=vehicle.inertia_zz_kg_m2,
            drag_constant_m=vehicle.drag_constant_m,
            **gains,
        )


def _per_axis(low: float, high: float, unit: str) -> Items:
    return Items.each(Interval(low, high, unit=unit), "xyz", "three numbers (body x, y, z)")


@dataclass(frozen=True, kw_only=True)
class ModelEffects:
    """Terms beyond the paper's model that a design model may include (all zero: the paper's model).

    They are *equivalent* terms, as an identification measures them from outside the
    vehicle: a rate loop that is a firmware PID, a gyro with a scale error or a rotor
    wake that damps rotation all show up here as the first-order numbers below.

    Attributes
    ----------
    rate_latency_s : per body axis, the delay between the body rate and the rate the
        onboard loop acts on (gyro, filter and loop latency) [s].
    rate_damping_n_m_s : per body axis, a moment −c·ω [N m s/rad]: aerodynamic damping,
        and anything else that makes the steady rate fall short of the command (a gyro
        that reads high acts the same way; negative if the steady rate overshoots).
    thrust_moment_arm_m : per body axis, a moment a·T proportional to the collective
        thrust T [m]: a centre-of-mass offset and uneven motors (x, y), uneven motor
        yaw moments (z).
    motor_thrust_gains : per motor (paper numbering), thrust relative to the model's (uneven motors
        and propellers) [-].
    rotor_drag_s_m : in-plane rotor drag, force −k·T·v (body x, y) [s/m].
    rotor_drag_axial_s_m : axial rotor drag (thrust lost climbing, gained descending), force
        −k·T·v along body z [s/m].
    body_drag_n_s2_m2 : quadratic body drag, force −c·|v|·v [N s²/m²].
    """

    rate_latency_s: tuple[float, float, float] = bounded((0.0, 0.0, 0.0), _per_axis(0.0, 0.1, "s"))
    rate_damping_n_m_s: tuple[float, float, float] = bounded((0.0, 0.0, 0.0), _per_axis(-10.0, 10.0, "N m s/rad"))
    thrust_moment_arm_m: tuple[float, float, float] = bounded((0.0, 0.0, 0.0), _per_axis(-0.5, 0.5, "m"))
    motor_thrust_gains: tuple[float, float, float, float] = bounded(
        (1.0, 1.0, 1.0, 1.0), Items.each(Interval(0.5, 1.5), (1, 2, 3, 4), "four numbers (motors 1-4)"))
    rotor_drag_s_m: float = bounded(0.0, Interval(0.0, 1.0, unit="s/m"))
    rotor_drag_axial_s_m: float = bounded(0.0, Interval(0.0, 1.0, unit="s/m"))
    body_drag_n_s2_m2: float = bounded(0.0, Interval(0.0, 1.0, unit="N s²/m²"))

    def __post_init__(self) -> None:
        validate(self)

    @property
    def neutral(self) -> bool:
        """True if every term is zero (the paper's model)."""
        return self == ModelEffects()


@dataclass(frozen=True, kw_only=True)
class VehicleConfig:
    """A vehicle's physical constants together with its onboard controller.

    To change the vehicle, use :meth:`with_vehicle` (or :meth:`with_mass`): it re-derives the
    controller's nominal constants, which ``dataclasses.replace(config, vehicle=…)`` would keep
    from the old vehicle.

    Attributes
    ----------
    vehicle, controller : the physical constants and the onboard rate controller.
    name : what it is called.
    effects : terms beyond the paper's model (identified vehicles); zero by default.
    source : where the numbers come from (citations, or the identification that produced
        them): a read-only table of strings, numbers and booleans, kept in vehicle files but
        not in the store, and not part of equality.
    """

    vehicle: VehicleParams
    controller: ControllerParams
    name: str = "custom"
    effects: ModelEffects = field(default_factory=ModelEffects)
    source: Mapping[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.effects, ModelEffects):
            raise ConfigError(f"effects must be a ModelEffects, got {type(self.effects).__name__}")
        object.__setattr__(self, "source", _ReadOnly(_source_table(self.source, "source")))

    def with_vehicle(self, vehicle: VehicleParams, *, name: str | None = None) -> VehicleConfig:
        """This configuration for another vehicle: the controller keeps its gains and motor order and
        inverts with the new vehicle's constants."""
        gains = {k: getattr(self.controller, k) for k in ("rate_gain_p_per_s", "rate_gain_q_per_s",
                                                          "rate_gain_r_per_s", "motor_order")}
        return VehicleConfig(vehicle=vehicle, controller=ControllerParams.nominal_for(vehicle, **gains),
                             name=self.name if name is None else name, effects=self.effects, source=self.source)

    def with_mass(self, mass_kg: float) -> VehicleConfig:
        """The same vehicle and controller with another mass (see :meth:`VehicleParams.with_mass`)."""
        return self.with_vehicle(self.vehicle.with_mass(mass_kg))


class _ReadOnly(Mapping[str, Any]):
    """A read-only (and picklable) view of a validated ``[source]`` table."""

    def __init__(self, data: dict[str, Any]) -> None:
        self._data = data

    def __getitem__(self, key: str) -> Any:
        return self._data[key]

    def __iter__(self) -> Any:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __repr__(self) -> str:
        return repr(self._data)


def _source_value(value: Any, where: str, depth: int) -> Any:
    if isinstance(value, bool | str):
        return value
    if isinstance(value, int | float):
        if not math.isfinite(value):
            raise ConfigError(f"{where} = {value}: must be finite")
        return value
    if isinstance(value, list | tuple):
        return [_source_value(v, f"{where}[{i}]", depth) for i, v in enumerate(value)]
    if isinstance(value, Mapping) and depth < 2:
        return _source_table(value, where, depth + 1)
    raise ConfigError(f"{where}: expected a string, number, boolean, array or table, got "
                      f"{type(value).__name__} {value!r}")


def _source_table(table: Any, where: str, depth: int = 0) -> dict[str, Any]:
    """A plain, validated copy of a ``[source]`` table (strings, numbers, booleans, arrays, two levels of tables)."""
    if not isinstance(table, Mapping):
        raise ConfigError(f"{where}: expected a table, got {type(table).__name__}")
    out = {}
    for key, value in table.items():
        if not isinstance(key, str):
            raise ConfigError(f"{where}: keys must be strings, got {key!r}")
        out[key] = _source_value(value, f"{where}.{key}", depth)
    return out



def hummingbird() -> VehicleConfig:
    """The paper's Table 1 Hummingbird, with a controller that inverts with the same constants."""
    vehicle = VehicleParams()
    return VehicleConfig(vehicle=vehicle, controller=ControllerParams.nominal_for(vehicle), name="hummingbird")


_PRESET_FILES = ("crazyflie21", "fpv5", "x2class")


def preset_names() -> tuple[str, ...]:
    """Every preset name, the default (``hummingbird``, Table 1) first."""
    return ("hummingbird", *_PRESET_FILES)


def preset(name: str) -> VehicleConfig:
    """The preset ``name``, from its package file in ``aerobat/quadrotor/vehicles/`` (with its ``[source]``).

    ``preset("hummingbird")`` equals :func:`hummingbird` (Table 1), which builds it in code.
    """
    if not isinstance(name, str):  # an array would compare element by element
        raise ConfigError(f"vehicle preset: expected a name, one of {', '.join(preset_names())}; got "
                          f"{type(name).__name__} {short_repr(name)}")
    if name not in preset_names():
        raise ConfigError(f"unknown vehicle preset {name!r}: use one of {', '.join(preset_names())}")
    resource = resources.files("aerobat.quadrotor") / "vehicles" / f"{name}.toml"
    with resources.as_file(resource) as path:
        return load_vehicle(path)


def fpv5() -> VehicleConfig:
    """A 5-inch FPV racer (``vehicles/fpv5.toml``, sources in the file): the Betaflight plant's vehicle."""
    return preset("fpv5")


PRESETS = {name: (lambda name=name: preset(name)) for name in preset_names()}


def load_vehicle(path: str | Path) -> VehicleConfig:
    """Load a vehicle TOML file.

    The file has a ``[vehicle]`` table (any :class:`VehicleParams` field; omitted
    fields take Table 1 values), an optional ``[controller]`` table, an optional
    ``[effects]`` table (any :class:`ModelEffects` field; omitted: zero) and an optional
    ``[source]`` table (strings, numbers, booleans, arrays, nested tables; kept as read).
    Controller constants that are not given default to the vehicle's own (a nominal controller).
    """
    path = as_path(path)
    data = read_toml(path)
    unknown = sorted(set(data) - {"vehicle", "controller", "effects", "source", "name"})
    if unknown:
        raise ConfigError(f"{path}: unknown table(s) {', '.join(unknown)}; allowed: name, [vehicle], [controller], "
                          f"[effects], [source]")
    if "vehicle" not in data:
        raise ConfigError(f"{path}: missing required table [vehicle]")
    vehicle = dataclass_from_table(VehicleParams, data["vehicle"], source=f"{path}: [vehicle]")
    table = dict(data.get("controller", {})) if isinstance(data.get("controller", {}), dict) else None
    if table is None:
        raise ConfigError(f"{path}: [controller] must be a table")
    nominal = dataclass_to_table(ControllerParams.nominal_for(vehicle))
    controller = dataclass_from_table(ControllerParams, {**nominal, **table}, source=f"{path}: [controller]")
    effects = dataclass_from_table(ModelEffects, data.get("effects", {}), source=f"{path}: [effects]")
    source = _source_table(data.get("source", {}), f"{path}: [source]")
    name = data.get("name", path.stem)
    if not isinstance(name, str):
        raise ConfigError(f"{path}: name must be a string")
    return VehicleConfig(vehicle=vehicle, controller=controller, name=name, effects=effects, source=source)


def vehicle_table(config: VehicleConfig) -> dict[str, Any]:
    """``{"name", "vehicle", "controller"}`` (and ``"effects"`` unless zero): the stored form of a configuration.

    The ``source`` is not part of it: two files that describe the same vehicle store as one.
    """
    table = {"name": config.name, "vehicle": dataclass_to_table(config.vehicle),
             "controller": dataclass_to_table(config.controller)}
    if not config.effects.neutral:
        table["effects"] = dataclass_to_table(config.effects)
    return table


def vehicle_from_table(table: Any, *, source: str) -> VehicleConfig:
    """Inverse of :func:`vehicle_table`; :class:`ConfigError` naming ``source`` and the field on bad input."""
    if not isinstance(table, dict) or "vehicle" not in table or "controller" not in table:
        raise ConfigError(f"{source}: expected a table with vehicle and controller")
    return VehicleConfig(
        vehicle=dataclass_from_table(VehicleParams, table["vehicle"], source=f"{source}.vehicle"),
        controller=dataclass_from_table(ControllerParams, table["controller"], source=f"{source}.controller"),
        name=str(table.get("name", "custom")),
        effects=dataclass_from_table(ModelEffects, table.get("effects", {}), source=f"{source}.effects"),
    )


def save_vehicle(config: VehicleConfig, path: str | Path, *, header: str = "") -> None:
    """Write ``config`` as TOML that :func:`load_vehicle` reads back identically (``[source]`` included).

    ``header`` is written first as ``#`` comment lines.
    """
    check_type("config", config, VehicleConfig, "a VehicleConfig")
    table = vehicle_table(config)
    if config.source:
        table["source"] = _source_table(config.source, "source")
    comments = "".join(f"# {line}".rstrip() + "\n" for line in header.splitlines())
    write_file(path, comments + tomli_w.dumps(table))


def _exists(path: str) -> bool:
    """Whether ``path`` names something; False for names the file system refuses (too long, NUL…)."""
    try:
        return Path(path).exists()
    except (OSError, ValueError):
        return False


def vehicle_from_name_or_file(spec: str) -> VehicleConfig:
    """A preset name (``hummingbird``, ``crazyflie21``, ``fpv5``, ``x2class``) or a path to a vehicle TOML file."""
    check_type("vehicle", spec, str, "a preset name or a vehicle TOML file")
    if spec in PRESETS:
        return PRESETS[spec]()
    if not spec.strip():  # Path("") is the working folder
        raise ConfigError(f"vehicle '': empty; use one of {', '.join(PRESETS)} or a .toml file")
    if not spec.endswith(".toml") and not _exists(spec):
        raise ConfigError(f"unknown vehicle {spec!r}: use one of {', '.join(PRESETS)} or a .toml file")
    return load_vehicle(spec)
