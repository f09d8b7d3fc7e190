"""The vehicle library (presets with sources), [effects]/[source] in vehicle files, and the model effects."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from aerobat.cli.app import main
from aerobat.core.design import design
from aerobat.errors import ConfigError
from aerobat.experiments.vehicles import flip_feasibility
from aerobat.quadrotor.dynamics import THRUST, hover_state, model_plant_vector, plant_derivative
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.program import Program, Switch
from aerobat.quadrotor.simulate import NominalModel, simulate, simulate_batch
from aerobat.quadrotor.vehicle import (
    PRESETS,
    ModelEffects,
    VehicleConfig,
    hummingbird,
    load_vehicle,
    preset,
    preset_names,
    save_vehicle,
    vehicle_from_name_or_file,
    vehicle_table,
)

H = hummingbird()


# ------------------------------------------------------------------ presets


def test_every_preset_loads_cites_its_source_and_is_accepted_by_name():
    assert preset_names()[0] == "hummingbird" and set(PRESETS) == set(preset_names())
    assert set(preset_names()) >= {"hummingbird", "crazyflie21", "fpv5", "x2class"}
    for name in preset_names():
        config = vehicle_from_name_or_file(name)
        assert config.name == name and config.source, name
        assert config.effects.neutral
    assert preset("hummingbird") == hummingbird()


@pytest.mark.parametrize(("name", "thrust_to_weight", "beta", "roll_acc"), [
    ("crazyflie21", 2.00, (4.905, 17.658), 256.6),
    ("fpv5", 4.61, (8.829, 41.202), 304.3),
    ("x2class", 4.00, (5.886, 35.316), 60.6),
])
def test_preset_envelopes_are_the_researched_numbers(name, thrust_to_weight, beta, roll_acc):
    v = preset(name).vehicle
    assert v.collective_max_m_s2 / v.gravity_m_s2 == pytest.approx(thrust_to_weight, abs=0.01)
    assert (v.collective_reduced_min_m_s2, v.collective_reduced_max_m_s2) == beta
    assert v.max_roll_acceleration_rad_s2 == pytest.approx(roll_acc, abs=0.1)


@pytest.mark.parametrize(("name", "allowed", "refused", "limit"), [
    ("hummingbird", (3, 1800), (3, 720), "β̄"),
    ("crazyflie21", (1, 720), (1, 3000), "β̲"),
    ("fpv5", (3, 1800), (1, 1800), "β̲"),
    ("x2class", (3, 1800), (1, 720), "β̲"),
])
def test_each_preset_designs_a_flip_its_envelope_allows_and_refuses_one_naming_the_limit(name, allowed, refused,
                                                                                        limit):
    config = preset(name)
    ok, bad = flip_feasibility(config, [allowed[0]], [allowed[1]]) + flip_feasibility(config, [refused[0]],
                                                                                         [refused[1]])
    assert ok.feasible and math.isfinite(ok.duration_s)
    assert not bad.feasible
    assert "violated limits" in bad.reason and limit in bad.reason, bad.reason


def test_cli_vehicles_lists_every_preset_with_its_envelope(capsys):
    assert main(["vehicles", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in rows] == list(preset_names())
    fpv = rows[2]
    assert fpv["thrust_to_weight"] == pytest.approx(4.61, abs=0.01)
    assert fpv["max_roll_acceleration_rad_s2"] == pytest.approx(304.3, abs=0.1)
    assert main(["design", "flip", "--flips", "3", "--dims", "2", "--vehicle", "fpv5", "--json"]) == 0


# ------------------------------------------------------------------ files


def test_effects_and_source_round_trip_through_a_vehicle_file(tmp_path):
    effects = ModelEffects(rate_latency_s=(0.002, 0.001, 0.0), rate_damping_n_m_s=(0.004, -0.001, 0.002),
                           thrust_moment_arm_m=(0.003, -0.002, 0.0), motor_thrust_gains=(1.01, 0.99, 1.0, 1.0),
                           rotor_drag_s_m=0.04, rotor_drag_axial_s_m=0.02, body_drag_n_s2_m2=0.005)
    config = VehicleConfig(vehicle=H.vehicle, controller=H.controller, name="x", effects=effects,
                           source={"citation": "a paper", "values": [1, 2.5], "fit": {"sigma": {"k": 0.1}}})
    path = tmp_path / "x.toml"
    save_vehicle(config, path, header="made here")
    loaded = load_vehicle(path)
    assert loaded == config and dict(loaded.source) == {"citation": "a paper", "values": [1, 2.5],
                                                        "fit": {"sigma": {"k": 0.1}}}
    assert path.read_text().startswith("# made here\n")
    # the stored form keeps the effects (not the source); a vehicle without effects stores as it always did
    assert vehicle_table(config)["effects"]["rotor_drag_s_m"] == 0.04 and "source" not in vehicle_table(config)
    assert set(vehicle_table(H)) == {"name", "vehicle", "controller"}


@pytest.mark.parametrize(("text", "fragments"), [
    ("[vehicle]\n[effects]\nrate_latency_s = [0.2, 0, 0]\n",
     ["[effects]", "rate_latency_s[x] = 0.2", "out of range", "[0, 0.1]"]),
    ("[vehicle]\n[effects]\nmotor_thrust_gains = [1, 1, 1]\n", ["[effects].motor_thrust_gains", "4 values"]),
    ("[vehicle]\n[effects]\nlatency = 1\n", ["[effects]", "unknown field(s) latency"]),
    ("[vehicle]\n[source]\nwhen = 2024-01-01\n", ["[source].when", "expected a string, number"]),
    ("[vehicle]\n[extras]\n", ["unknown table(s) extras", "[effects], [source]"]),
])
def test_bad_effects_or_source_name_the_file_field_and_range(tmp_path, text, fragments):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_vehicle(path)
    for fragment in fragments:
        assert fragment in str(info.value), (fragment, str(info.value))
    assert str(path) in str(info.value)


# ------------------------------------------------------------------ the effects in the model


def _doublet(channel: str = "rate_p") -> Program:
    return Program(switches=(Switch(time_s=0.0, channel=channel, value=2.0), Switch(time_s=0.1, channel=channel,
                                                                                   value=0.0)), duration_s=0.3)


def test_no_effects_is_the_paper_model_exactly():
    with_zero = dataclasses.replace(H, effects=ModelEffects())
    a = simulate(_doublet(), H)
    b = simulate(_doublet(), with_zero)
    assert np.array_equal(a.states, b.states)
    assert np.array_equal(model_plant_vector(H)[:38], model_plant_vector(with_zero)[:38])


def test_latency_delays_the_rate_feedback():
    program = _doublet()

    def peak(latency: float) -> float:
        config = dataclasses.replace(H, effects=ModelEffects(rate_latency_s=(latency, 0.0, 0.0)))
        return float(simulate(program, config, max_step_s=1e-4).states[:, 10].max())

    # the loop acts on an old rate: it pushes on for longer and overshoots more the longer the latency
    assert 2.0 < peak(0.0) < peak(0.002) < peak(0.004)
    delayed = dataclasses.replace(H, effects=ModelEffects(rate_latency_s=(0.004, 0.0, 0.0)))
    slow = simulate(program, delayed, max_step_s=1e-4)
    # the batch kernel and the recording kernel agree; the onboard (sampled) playback delays alike
    final = simulate_batch([program], [delayed], max_step_s=1e-4)[0]
    assert np.allclose(final, slow.final_state, atol=1e-12)
    sampled = simulate(program, delayed, mode="sampled", tick_s=1e-4)
    assert abs(sampled.final_state[17] - slow.final_state[17]) < 1e-3


def test_moment_arms_gains_and_axial_drag_act_as_documented():
    arm = dataclasses.replace(H, effects=ModelEffects(thrust_moment_arm_m=(0.003, -0.002, 0.001),
                                                      rotor_drag_axial_s_m=0.1))
    x = hover_state(H.vehicle)
    x[5] = 1.0  # climbing at 1 m/s, level
    dx = np.zeros_like(x)
    thrust = x[THRUST].copy()
    plant_derivative(0.0, x, thrust, model_plant_vector(arm), dx)
    total = thrust.sum()
    inertia = (H.vehicle.inertia_xx_kg_m2, H.vehicle.inertia_yy_kg_m2, H.vehicle.inertia_zz_kg_m2)
    assert dx[10:13] * np.array(inertia) == pytest.approx(np.array([0.003, -0.002, 0.001]) * total, rel=1e-9)
    assert dx[5] == pytest.approx(-0.1 * total / H.vehicle.mass_kg * 1.0, rel=1e-9)  # hover thrust cancels g
    gains = dataclasses.replace(H, effects=ModelEffects(motor_thrust_gains=(1.0, 1.1, 1.0, 0.9)))
    plant_derivative(0.0, hover_state(H.vehicle), thrust, model_plant_vector(gains), dx)
    assert dx[10] * H.vehicle.inertia_xx_kg_m2 == pytest.approx(H.vehicle.arm_length_m * 0.2 * thrust[1], rel=1e-9)


def test_an_identified_vehicle_designs_with_its_effects():
    effects = ModelEffects(rate_latency_s=(0.002, 0.002, 0.001), rate_damping_n_m_s=(0.004, 0.004, 0.002))
    config = dataclasses.replace(H, effects=effects)
    flip = MultiFlip(vehicle=config.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
    plain, damped = (design(flip, NominalModel(c)).p_nominal for c in (H, config))
    assert design(flip, NominalModel(config)).converged
    assert plain[2] < damped[2]  # the damped vehicle coasts longer to turn as far
