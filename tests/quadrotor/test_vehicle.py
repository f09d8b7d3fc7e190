"""Vehicle constants (Table 1), derived quantities, validation and vehicle TOML files."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from aerobat.config import ConfigError
from aerobat.quadrotor.vehicle import (
    ControllerParams,
    VehicleConfig,
    VehicleParams,
    hummingbird,
    load_vehicle,
    save_vehicle,
    vehicle_from_name_or_file,
)

TABLE_1 = {
    "mass_kg": 0.468,
    "arm_length_m": 0.17,
    "inertia_xx_kg_m2": 0.0023,
    "inertia_yy_kg_m2": 0.0023,
    "inertia_zz_kg_m2": 0.0046,
    "motor_rate_up_per_s": 80.0,
    "motor_rate_down_per_s": 60.0,
    "rotor_thrust_min_n": 0.08,
    "rotor_thrust_max_n": 2.8,
    "collective_reduced_min_m_s2": 3.92,
    "collective_reduced_max_m_s2": 21.58,
    "drag_constant_m": 0.016,
}


# ----------------------------------------------------------------- Table 1


def test_defaults_equal_table_1():
    v = VehicleParams()
    for name, value in TABLE_1.items():
        assert getattr(v, name) == value, name
    assert v.gravity_m_s2 == 9.81
    # every field is covered: nothing silently added without a Table 1 check
    assert {f.name for f in dataclasses.fields(v)} == set(TABLE_1) | {"gravity_m_s2"}


def test_hummingbird_preset_is_table_1_with_nominal_controller():
    cfg = hummingbird()
    assert cfg.vehicle == VehicleParams()
    assert cfg.name == "hummingbird"
    c = cfg.controller
    assert (c.mass_kg, c.arm_length_m, c.drag_constant_m) == (0.468, 0.17, 0.016)
    assert (c.inertia_xx_kg_m2, c.inertia_yy_kg_m2, c.inertia_zz_kg_m2) == (0.0023, 0.0023, 0.0046)
    assert c.motor_order == (1, 2, 3, 4)
    assert (c.rate_gain_p_per_s, c.rate_gain_q_per_s, c.rate_gain_r_per_s) == (100.0, 100.0, 10.0)


def test_derived_quantities():
    v = VehicleParams()
    assert v.hover_thrust_n == pytest.approx(0.468 * 9.81, rel=1e-15)
    assert v.hover_rotor_thrust_n == pytest.approx(0.468 * 9.81 / 4, rel=1e-15)
    assert v.collective_min_m_s2 == pytest.approx(4 * 0.08 / 0.468, rel=1e-15)
    assert v.collective_max_m_s2 == pytest.approx(4 * 2.8 / 0.468, rel=1e-15)  # 23.93 m/s²
    # eq 27: l m (β̄ − β̲) / (4 I_xx) = 0.17 · 0.468 · 17.66 / 0.0092 = 152.7206… rad/s²
    assert v.max_roll_acceleration_rad_s2 == pytest.approx(152.72060869565, rel=1e-12)
    assert v.max_roll_acceleration_rad_s2 == pytest.approx(152.72, abs=5e-3)
    assert v.max_pitch_acceleration_rad_s2 == pytest.approx(152.72060869565, rel=1e-12)
    # a non-symmetric vehicle: pitch uses I_yy, roll I_xx
    w = VehicleParams(inertia_yy_kg_m2=0.0046)
    assert w.max_pitch_acceleration_rad_s2 == pytest.approx(
        v.max_roll_acceleration_rad_s2 / 2, rel=1e-12
    )
    # the reduced envelope sits inside the absolute one (eq 24)
    assert v.collective_min_m_s2 < v.collective_reduced_min_m_s2 < v.gravity_m_s2
    assert v.gravity_m_s2 < v.collective_reduced_max_m_s2 < v.collective_max_m_s2


def test_the_example_flip_uses_the_eq_27_acceleration():
    """The shipped flip programs use the eq 27 bound: their peak accel_p equals it."""
    from aerobat.quadrotor.program import load_program

    root = Path(__file__).resolve().parents[2] / "examples"
    for name in ("single_flip.toml", "triple_flip_1800.toml"):
        prog = load_program(root / name)
        peak = max(abs(s.value) for s in prog.switches if s.channel == "accel_p")
        assert peak == pytest.approx(VehicleParams().max_roll_acceleration_rad_s2, rel=1e-12)


@pytest.mark.parametrize(
    ("field", "value", "fragment"),
    [
        ("mass_kg", -0.5, "[0.01, 100]"),
        ("mass_kg", 0.0, "[0.01, 100]"),
        ("arm_length_m", 10.0, "[0.01, 5]"),
        ("inertia_zz_kg_m2", 0.0, "[1e-07, 100]"),
        ("motor_rate_up_per_s", -80.0, "[0.1, 10000]"),
        ("motor_rate_down_per_s", math.inf, "must be finite"),
        ("rotor_thrust_min_n", -0.1, "[0, 10000]"),
        ("rotor_thrust_max_n", 0.05, "(0.08, 10000]"),  # must exceed f_min
        ("collective_reduced_min_m_s2", 0.5, "4 f_min/m < β̲ < g"),  # below 4 f_min / m = 0.684
        ("collective_reduced_min_m_s2", 10.0, "4 f_min/m < β̲ < g"),  # above g
        ("collective_reduced_max_m_s2", 24.0, "(9.81, 23.9316)"),  # above 4 f_max / m
        ("collective_reduced_max_m_s2", 9.0, "g < β̄ < 4 f_max/m"),  # below g
        ("drag_constant_m", 2.0, "[1e-05, 1]"),
        ("gravity_m_s2", math.nan, "must be finite"),
    ],
)
def test_invalid_vehicle_names_field_and_range(field, value, fragment):
    with pytest.raises(ValueError) as info:
        VehicleParams(**{field: value})
    message = str(info.value)
    assert message.startswith(field), message
    assert fragment in message, message


def test_vehicle_rejects_non_numbers():
    with pytest.raises(ValueError, match=r"^mass_kg must be a number, got str"):
        VehicleParams(mass_kg="0.468")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"^arm_length_m must be a number, got bool"):
        VehicleParams(arm_length_m=True)  # type: ignore[arg-type]


def test_vehicle_is_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        VehicleParams().mass_kg = 1.0  # type: ignore[misc]


# ------------------------------------------------------------- controller


def test_controller_nominal_for_copies_the_vehicle_constants():
    v = VehicleParams(mass_kg=0.5, arm_length_m=0.2, inertia_xx_kg_m2=0.003, drag_constant_m=0.02)
    c = ControllerParams.nominal_for(v, rate_gain_r_per_s=20.0)
    assert (c.mass_kg, c.arm_length_m, c.inertia_xx_kg_m2, c.drag_constant_m) == (
        0.5,
        0.2,
        0.003,
        0.02,
    )
    assert c.inertia_yy_kg_m2 == v.inertia_yy_kg_m2 and c.inertia_zz_kg_m2 == v.inertia_zz_kg_m2
    assert c.rate_gain_r_per_s == 20.0 and c.rate_gain_p_per_s == 100.0


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"motor_order": (1, 2, 3, 3)}, r"motor_order = \(1, 2, 3, 3\) must be a permutation"),
        ({"motor_order": (0, 1, 2, 3)}, r"motor_order .* must be a permutation"),
        (
            {"rate_gain_p_per_s": -1.0},
            r"^rate_gain_p_per_s = -1 is out of range: allowed \[0, 10000\]",
        ),
        ({"mass_kg": 0.0}, r"^mass_kg = 0 is out of range"),
        ({"drag_constant_m": math.nan}, r"^drag_constant_m = nan must be finite"),
    ],
)
def test_invalid_controller_names_field(kwargs, pattern):
    with pytest.raises(ValueError, match=pattern):
        ControllerParams(**kwargs)


# ---------------------------------------------------------------- TOML io


def _write(tmp_path: Path, text: str, name: str = "vehicle.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_vehicle_round_trip_default(tmp_path):
    cfg = hummingbird()
    path = tmp_path / "hb.toml"
    save_vehicle(cfg, path)
    assert load_vehicle(path) == cfg


def test_vehicle_round_trip_non_default(tmp_path):
    vehicle = VehicleParams(
        mass_kg=0.51,
        arm_length_m=0.18,
        inertia_zz_kg_m2=0.0051,
        motor_rate_down_per_s=45.5,
        collective_reduced_max_m_s2=20.0,
        gravity_m_s2=9.80665,
    )
    controller = ControllerParams(
        rate_gain_p_per_s=90.0, mass_kg=0.49, arm_length_m=0.175, motor_order=(2, 1, 4, 3)
    )
    cfg = VehicleConfig(vehicle=vehicle, controller=controller, name="miswired")
    path = tmp_path / "x.toml"
    save_vehicle(cfg, path)
    loaded = load_vehicle(path)
    assert loaded == cfg
    assert isinstance(loaded.controller.motor_order, tuple)


def test_vehicle_file_partial_tables_default_to_table_1_and_nominal_controller(tmp_path):
    path = _write(tmp_path, "[vehicle]\nmass_kg = 0.5\n", "light.toml")
    cfg = load_vehicle(path)
    assert cfg.name == "light"  # file stem
    assert cfg.vehicle == VehicleParams(mass_kg=0.5)
    assert cfg.controller == ControllerParams.nominal_for(VehicleParams(mass_kg=0.5))
    assert vehicle_from_name_or_file(str(path)) == cfg
    assert vehicle_from_name_or_file("hummingbird") == hummingbird()


@pytest.mark.parametrize(
    ("text", "fragments"),
    [
        ("[vehicle]\nmass_kg = -0.5\n", ["[vehicle]", "mass_kg = -0.5", "out of range"]),
        ("[vehicle]\nmass = 0.5\n", ["[vehicle]", "unknown field(s) mass"]),
        ('[vehicle]\nmass_kg = "0.5"\n', ["[vehicle].mass_kg", "expected a number", "'0.5'"]),
        (
            "[vehicle]\ncollective_reduced_max_m_s2 = 24.0\n",
            ["[vehicle]", "collective_reduced_max_m_s2 = 24", "4 f_max/m"],
        ),
        ("[vehicle]\ninertia_xx_kg_m2 = nan\n", ["[vehicle]", "inertia_xx_kg_m2 = nan", "finite"]),
        ("[vehicle]\n[controller]\nmotor_order = [1, 1, 2, 3]\n", ["[controller]", "motor_order"]),
        (
            "[vehicle]\n[controller]\nmotor_order = [1, 2, 3]\n",
            ["[controller].motor_order", "expected an array of 4 values, got 3"],
        ),
        ("[vehicle]\n[controller]\ngain = 3.0\n", ["[controller]", "unknown field(s) gain"]),
        ('name = "a"\n', ["missing required table [vehicle]"]),
        ("[vehicle]\n[engine]\n", ["unknown table(s) engine"]),
        ("[vehicle]\nname = 3\n", ["[vehicle]", "unknown field(s) name"]),
        ("name = 3\n[vehicle]\n", ["name must be a string"]),
        ("[vehicle\n", ["invalid TOML"]),
    ],
)
def test_invalid_vehicle_file_names_file_and_field(tmp_path, text, fragments):
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_vehicle(path)
    message = str(info.value)
    assert message.startswith(f"{path}: "), message
    for fragment in fragments:
        assert fragment in message, message
    assert "\n" not in message


def test_missing_vehicle_file(tmp_path):
    with pytest.raises(ConfigError, match="file not found"):
        load_vehicle(tmp_path / "nope.toml")
    with pytest.raises(ConfigError, match="unknown vehicle 'crazyflie'"):
        vehicle_from_name_or_file("crazyflie")


def test_config_error_is_value_error():
    assert issubclass(ConfigError, ValueError)


def test_with_mass_keeps_rotor_limits_and_rederives_the_controller():
    from aerobat.quadrotor.vehicle import hummingbird

    config = hummingbird()
    heavy = config.with_mass(config.vehicle.mass_kg * 1.25)
    v0, v1 = config.vehicle, heavy.vehicle
    # per-rotor thrust limits are the motors': m·β is unchanged
    assert v1.mass_kg * v1.collective_reduced_max_m_s2 == pytest.approx(v0.mass_kg * v0.collective_reduced_max_m_s2)
    assert v1.mass_kg * v1.collective_reduced_min_m_s2 == pytest.approx(v0.mass_kg * v0.collective_reduced_min_m_s2)
    assert heavy.controller.mass_kg == v1.mass_kg  # the controller inverts with the new mass
    assert heavy.controller.rate_gain_p_per_s == config.controller.rate_gain_p_per_s
    assert v1.inertia_xx_kg_m2 == v0.inertia_xx_kg_m2
    with pytest.raises(ConfigError, match="mass_kg"):
        config.with_mass(0.0)
    with pytest.raises(ConfigError, match="mass_kg"):
        config.with_mass(True)
