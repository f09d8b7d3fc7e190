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
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import tomli_w

from aerobat.config import (
    as_path,
    check_finite,
    check_range,
    check_type,
    dataclass_from_table,
    dataclass_to_table,
    read_toml,
    short_repr,
    write_file,
)
from aerobat.errors import ConfigError

__all__ = [
    "ControllerParams",
    "VehicleConfig",
    "VehicleParams",
    "hummingbird",
    "load_vehicle",
    "save_vehicle",
    "vehicle_from_name_or_file",
    "vehicle_from_table",
    "vehicle_table",
]

STANDARD_GRAVITY_M_S2 = 9.81


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

    mass_kg: float = 0.468
    arm_length_m: float = 0.17
    inertia_xx_kg_m2: float = 0.0023
    inertia_yy_kg_m2: float = 0.0023
    inertia_zz_kg_m2: float = 0.0046
    motor_rate_up_per_s: float = 80.0
    motor_rate_down_per_s: float = 60.0
    rotor_thrust_min_n: float = 0.08
    rotor_thrust_max_n: float = 2.8
    collective_reduced_min_m_s2: float = 3.92
    collective_reduced_max_m_s2: float = 21.58
    drag_constant_m: float = 0.016
    gravity_m_s2: float = STANDARD_GRAVITY_M_S2

    def __post_init__(self) -> None:
        check_range("mass_kg", self.mass_kg, low=0.01, high=100.0, unit="kg")
        check_range("arm_length_m", self.arm_length_m, low=0.01, high=5.0, unit="m")
        for name in ("inertia_xx_kg_m2", "inertia_yy_kg_m2", "inertia_zz_kg_m2"):
            check_range(name, getattr(self, name), low=1e-7, high=100.0, unit="kg m²")
        check_range("motor_rate_up_per_s", self.motor_rate_up_per_s, low=0.1, high=1e4, unit="1/s")
        check_range("motor_rate_down_per_s", self.motor_rate_down_per_s, low=0.1, high=1e4, unit="1/s")
        check_range("rotor_thrust_min_n", self.rotor_thrust_min_n, low=0.0, high=1e4, unit="N")
        check_range("rotor_thrust_max_n", self.rotor_thrust_max_n, low=self.rotor_thrust_min_n,
                    low_inclusive=False, high=1e4, unit="N")
        check_range("gravity_m_s2", self.gravity_m_s2, low=0.1, high=100.0, unit="m/s²")
        check_range("drag_constant_m", self.drag_constant_m, low=1e-5, high=1.0, unit="m")
        # eq 24: 4 f_min < m β̲ <= m β̄ < 4 f_max, and hover must be inside the envelope.
        lo = 4.0 * self.rotor_thrust_min_n / self.mass_kg
        hi = 4.0 * self.rotor_thrust_max_n / self.mass_kg
        if hi <= self.gravity_m_s2:
            raise ConfigError(f"rotor_thrust_max_n = {self.rotor_thrust_max_n:g} N is too small for mass_kg = "
                              f"{self.mass_kg:g} kg: four rotors give at most 4 f_max/m = {hi:.3g} m/s², below "
                              f"gravity_m_s2 = {self.gravity_m_s2:g}; the vehicle cannot hover")
        if lo >= self.gravity_m_s2:
            raise ConfigError(f"rotor_thrust_min_n = {self.rotor_thrust_min_n:g} N is too large for mass_kg = "
                              f"{self.mass_kg:g} kg: 4 f_min/m = {lo:.3g} m/s² is above gravity_m_s2 = "
                              f"{self.gravity_m_s2:g}; the vehicle cannot hover")
        check_range("collective_reduced_min_m_s2", self.collective_reduced_min_m_s2, low=lo,
                    high=self.gravity_m_s2, low_inclusive=False, high_inclusive=False,
                    unit="m/s², eq 24: 4 f_min/m < β̲ < g")
        check_range("collective_reduced_max_m_s2", self.collective_reduced_max_m_s2, low=self.gravity_m_s2,
                    high=hi, low_inclusive=False, high_inclusive=False, unit="m/s², eq 24: g < β̄ < 4 f_max/m")

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

    rate_gain_p_per_s: float = 100.0
    rate_gain_q_per_s: float = 100.0
    rate_gain_r_per_s: float = 10.0
    mass_kg: float = 0.468
    arm_length_m: float = 0.17
    inertia_xx_kg_m2: float = 0.0023
    inertia_yy_kg_m2: float = 0.0023
    inertia_zz_kg_m2: float = 0.0046
    drag_constant_m: float = 0.016
    motor_order: tuple[int, int, int, int] = (1, 2, 3, 4)

    def __post_init__(self) -> None:
        for name in ("rate_gain_p_per_s", "rate_gain_q_per_s", "rate_gain_r_per_s"):
            check_range(name, getattr(self, name), low=0.0, high=1e4, unit="1/s")
        check_range("mass_kg", self.mass_kg, low=0.01, high=100.0, unit="kg")
        check_range("arm_length_m", self.arm_length_m, low=0.01, high=5.0, unit="m")
        for name in ("inertia_xx_kg_m2", "inertia_yy_kg_m2", "inertia_zz_kg_m2"):
            check_range(name, getattr(self, name), low=1e-7, high=100.0, unit="kg m²")
        check_range("drag_constant_m", self.drag_constant_m, low=1e-5, high=1.0, unit="m")
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


@dataclass(frozen=True, kw_only=True)
class VehicleConfig:
    """A vehicle's physical constants together with its onboard controller.

    To change the vehicle, use :meth:`with_vehicle` (or :meth:`with_mass`): it re-derives the
    controller's nominal constants, which ``dataclasses.replace(config, vehicle=…)`` would keep
    from the old vehicle.
    """

    vehicle: VehicleParams
    controller: ControllerParams
    name: str = "custom"

    def with_vehicle(self, vehicle: VehicleParams, *, name: str | None = None) -> VehicleConfig:
        """This configuration for another vehicle: the controller keeps its gains and motor order and
        inverts with the new vehicle's constants."""
        gains = {k: getattr(self.controller, k) for k in ("rate_gain_p_per_s", "rate_gain_q_per_s",
                                                          "rate_gain_r_per_s", "motor_order")}
        return VehicleConfig(vehicle=vehicle, controller=ControllerParams.nominal_for(vehicle, **gains),
                             name=self.name if name is None else name)

    def with_mass(self, mass_kg: float) -> VehicleConfig:
        """The same vehicle and controller with another mass (see :meth:`VehicleParams.with_mass`)."""
        return self.with_vehicle(self.vehicle.with_mass(mass_kg))


def hummingbird() -> VehicleConfig:
    """The paper's Table 1 Hummingbird, with a controller that inverts with the same constants."""
    vehicle = VehicleParams()
    return VehicleConfig(vehicle=vehicle, controller=ControllerParams.nominal_for(vehicle), name="hummingbird")


PRESETS = {"hummingbird": hummingbird}


def load_vehicle(path: str | Path) -> VehicleConfig:
    """Load a vehicle TOML file.

    The file has a ``[vehicle]`` table (any :class:`VehicleParams` field; omitted
    fields take Table 1 values) and an optional ``[controller]`` table. Controller
    constants that are not given default to the vehicle's own (a nominal controller).
    """
    path = as_path(path)
    data = read_toml(path)
    unknown = sorted(set(data) - {"vehicle", "controller", "name"})
    if unknown:
        raise ConfigError(f"{path}: unknown table(s) {', '.join(unknown)}; allowed: name, [vehicle], [controller]")
    if "vehicle" not in data:
        raise ConfigError(f"{path}: missing required table [vehicle]")
    vehicle = dataclass_from_table(VehicleParams, data["vehicle"], source=f"{path}: [vehicle]")
    table = dict(data.get("controller", {})) if isinstance(data.get("controller", {}), dict) else None
    if table is None:
        raise ConfigError(f"{path}: [controller] must be a table")
    nominal = dataclass_to_table(ControllerParams.nominal_for(vehicle))
    controller = dataclass_from_table(ControllerParams, {**nominal, **table}, source=f"{path}: [controller]")
    name = data.get("name", path.stem)
    if not isinstance(name, str):
        raise ConfigError(f"{path}: name must be a string")
    return VehicleConfig(vehicle=vehicle, controller=controller, name=name)


def vehicle_table(config: VehicleConfig) -> dict[str, Any]:
    """``{"name", "vehicle", "controller"}``: the stored and file form of a configuration."""
    return {"name": config.name, "vehicle": dataclass_to_table(config.vehicle),
            "controller": dataclass_to_table(config.controller)}


def vehicle_from_table(table: Any, *, source: str) -> VehicleConfig:
    """Inverse of :func:`vehicle_table`; :class:`ConfigError` naming ``source`` and the field on bad input."""
    if not isinstance(table, dict) or "vehicle" not in table or "controller" not in table:
        raise ConfigError(f"{source}: expected a table with vehicle and controller")
    return VehicleConfig(
        vehicle=dataclass_from_table(VehicleParams, table["vehicle"], source=f"{source}.vehicle"),
        controller=dataclass_from_table(ControllerParams, table["controller"], source=f"{source}.controller"),
        name=str(table.get("name", "custom")),
    )


def save_vehicle(config: VehicleConfig, path: str | Path) -> None:
    """Write ``config`` as TOML that :func:`load_vehicle` reads back identically."""
    check_type("config", config, VehicleConfig, "a VehicleConfig")
    write_file(path, tomli_w.dumps(vehicle_table(config)))


def _exists(path: str) -> bool:
    """Whether ``path`` names something; False for names the file system refuses (too long, NUL…)."""
    try:
        return Path(path).exists()
    except (OSError, ValueError):
        return False


def vehicle_from_name_or_file(spec: str) -> VehicleConfig:
    """``"hummingbird"`` (a preset name) or a path to a vehicle TOML file."""
    check_type("vehicle", spec, str, "a preset name or a vehicle TOML file")
    if spec in PRESETS:
        return PRESETS[spec]()
    if not spec.endswith(".toml") and not _exists(spec):
        raise ConfigError(f"unknown vehicle {spec!r}: use one of {', '.join(PRESETS)} or a .toml file")
    return load_vehicle(spec)
