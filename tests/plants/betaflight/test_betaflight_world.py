"""The Betaflight plant's world without the firmware: frames and signs, thrust curve, pilot, settings files."""

from __future__ import annotations

import math

import numpy as np
import pytest

from aerobat.errors import ConfigError
from aerobat.firmware.betaflight.settings import load_settings
from aerobat.plants import PLANTS, PlantChoice
from aerobat.plants.betaflight.physics import (
    A_GROUND,
    C_CONTACT,
    C_DELAY,
    N_COUNTERS,
    PACKET_DOUBLES,
    SCRATCH_ROWS,
    airframe_plant,
    aux_vector,
    derivative,
    ground_state,
    prime,
    step,
)
from aerobat.plants.fpv.params import Airframe, BetaflightParams, load_betaflight, save_betaflight
from aerobat.plants.fpv.pilot import StickMap, angle_sticks, program_sticks, throttle_for_collective
from aerobat.quadrotor.dynamics import N_STATE, quaternion_from_rotation_vector

IDEAL = BetaflightParams().replace(sensors__gyro_scale_error=(0.0, 0.0, 0.0), sensors__gyro_bias_rad_s=(0.0, 0.0, 0.0),
                                   sensors__attitude_error_rad=(0.0, 0.0), sensors__gyro_noise_rad_s=0.0,
                                   sensors__accel_noise_m_s2=0.0)


def packet_for(x: np.ndarray, *, contact: int = 0, motors: tuple[float, ...] = (0.0,) * 4) -> np.ndarray:
    plant = airframe_plant(IDEAL)
    aux = aux_vector(IDEAL, step_s=125e-6, ground_z_m=-100.0, gravity_m_s2=9.81)
    counters = np.zeros(N_COUNTERS, dtype=np.int64)
    counters[C_CONTACT] = contact
    packet = np.zeros(PACKET_DOUBLES)
    prime(x, plant, aux, counters, np.zeros(6), packet, np.zeros((SCRATCH_ROWS, N_STATE)))
    return packet


def attitude(rotation_vector: tuple[float, float, float]) -> np.ndarray:
    x = ground_state((0.0, 0.0, 0.0))
    x[6:10] = quaternion_from_rotation_vector(np.array(rotation_vector))
    return x


def test_level_at_rest_reads_minus_g_on_the_frd_z_axis() -> None:
    packet = packet_for(ground_state((0.0, 0.0, 0.0)), contact=1)
    assert packet[1:4] == pytest.approx([0.0, 0.0, 0.0])
    assert packet[4:7] == pytest.approx([0.0, 0.0, -9.81])
    assert packet[7:11] == pytest.approx([1.0, 0.0, 0.0, 0.0])


def test_free_fall_reads_zero_specific_force() -> None:
    assert packet_for(ground_state((0.0, 0.0, 5.0)))[4:7] == pytest.approx([0.0, 0.0, 0.0], abs=1e-9)


def test_rolled_right_pitched_down_and_yawed_right_in_betaflight_frames() -> None:
    # aerobat body FLU: roll right = +x rotation, nose down = +y rotation, nose right = −z rotation
    roll = packet_for(attitude((math.radians(20), 0.0, 0.0)))
    assert roll[8] == pytest.approx(math.sin(math.radians(10))) and abs(roll[9]) < 1e-12 and abs(roll[10]) < 1e-12
    pitch = packet_for(attitude((0.0, math.radians(20), 0.0)))
    assert pitch[9] == pytest.approx(-math.sin(math.radians(10)))  # FRD: nose down is a negative pitch
    yaw = packet_for(attitude((0.0, 0.0, -math.radians(30))))
    assert yaw[10] == pytest.approx(math.sin(math.radians(15)))  # NED: nose right is a positive heading


def test_gyro_axes() -> None:
    for axis, expected in ((10, (1.0, 0.0, 0.0)), (11, (0.0, -1.0, 0.0)), (12, (0.0, 0.0, -1.0))):
        x = ground_state((0.0, 0.0, 5.0))
        x[axis] = 1.0
        assert packet_for(x)[1:4] == pytest.approx(expected)


@pytest.mark.parametrize(("slots", "axis", "sign"), [
    ((1, 2), 10, +1),  # left motors up: roll right (+p)
    ((1, 3), 11, +1),  # rear motors up: nose down (+q in FLU)
    ((0, 1), 12, -1),  # counter-clockwise props up: nose right (−r in FLU)
])
def test_motor_layout_moments(slots: tuple[int, int], axis: int, sign: int) -> None:
    params = IDEAL.replace(airframe__com_offset_m=(0.0, 0.0, 0.0), airframe__thrust_gains=(1.0, 1.0, 1.0, 1.0),
                           airframe__rotor_inertia_kg_m2=0.0)
    plant = airframe_plant(params)
    aux = aux_vector(params, step_s=125e-6, ground_z_m=-100.0, gravity_m_s2=9.81)
    x = ground_state((0.0, 0.0, 5.0))
    x[13:17] = 1.8
    for slot in slots:
        x[13 + slot] = 2.2
    dx = np.zeros(N_STATE)
    derivative(0.0, x, np.full(4, 1.8), plant, aux, dx)
    others = [a for a in (10, 11, 12) if a != axis]
    assert sign * dx[axis] > 1.0 and all(abs(dx[a]) < 1e-9 for a in others)


def test_spinning_up_the_counter_clockwise_rotors_yaws_the_body_clockwise() -> None:
    x = ground_state((0.0, 0.0, 5.0))
    x[13:17] = 1.8  # equal thrusts: the drag moments cancel, only the rotors' reaction acts
    # without rotor inertia the four drag moments cancel (to rounding: the kernel sums them pairwise, fused)
    for inertia, check in ((8e-6, lambda r: r < -1.0), (0.0, lambda r: abs(r) < 1e-12)):
        params = IDEAL.replace(airframe__rotor_inertia_kg_m2=inertia)
        aux = aux_vector(params, step_s=125e-6, ground_z_m=-100.0, gravity_m_s2=9.81)
        dx = np.zeros(N_STATE)
        derivative(0.0, x, np.array([3.0, 3.0, 1.8, 1.8]), airframe_plant(params), aux, dx)  # slots 0, 1: CCW
        assert check(dx[12]), (inertia, dx[12])


def test_thrust_curve_and_its_inverse() -> None:
    airframe = Airframe()
    assert airframe.thrust_n(0.0) == 0.0 and airframe.thrust_n(1.0) == pytest.approx(8.5)
    assert airframe.thrust_n(0.055) == pytest.approx(0.583, abs=1e-3)  # fpv5.toml's f_min
    for u in (0.06, 0.25, 0.5, 0.9):
        assert airframe.command_for_thrust(airframe.thrust_n(u)) == pytest.approx(u)


def test_floor_holds_the_vehicle_until_thrust_exceeds_weight() -> None:
    plant = airframe_plant(IDEAL)
    aux = aux_vector(IDEAL, step_s=125e-6, ground_z_m=0.0, gravity_m_s2=9.81)
    x = ground_state((0.0, 0.0, aux[A_GROUND]))
    counters = np.zeros(N_COUNTERS, dtype=np.int64)
    counters[C_CONTACT], counters[C_DELAY] = 1, 1
    args = (plant, aux, np.zeros((2, 4)), counters, np.zeros(6), np.zeros(PACKET_DOUBLES),
            np.zeros((SCRATCH_ROWS, N_STATE)))
    idle = np.full(4, 0.055, dtype=np.float32)
    for _ in range(4000):
        assert step(x, idle, *args) == 0
    assert counters[C_CONTACT] == 1 and x[2] == 0.0 and np.all(x[3:6] == 0.0)
    full = np.full(4, 0.6, dtype=np.float32)
    for _ in range(4000):
        step(x, full, *args)
    assert counters[C_CONTACT] == 0 and x[2] > 0.1


def test_the_gyro_carries_each_rotors_vibration_line_at_its_rotation_frequency() -> None:
    """On the floor at a steady command: the gyro's roll line lies at √(f/k)/2π with the airframe's rms; without a
    vibration (the default) the packet is the true rate, bit for bit."""
    thrust = Airframe().thrust_n(0.2)
    shaking = IDEAL.replace(airframe__vibration_rms_rad_s=(0.2, 0.1, 0.05), airframe__vibration_thrust_n=thrust)
    step_s = 125e-6
    rolls = {}
    for name, params in (("still", IDEAL), ("shaking", shaking)):
        plant = airframe_plant(params)
        aux = aux_vector(params, step_s=step_s, ground_z_m=0.0, gravity_m_s2=9.81)
        x = ground_state((0.0, 0.0, aux[A_GROUND]))
        counters = np.zeros(N_COUNTERS, dtype=np.int64)
        counters[C_CONTACT], counters[C_DELAY] = 1, 1
        packet, scratch, pending = np.zeros(PACKET_DOUBLES), np.zeros((SCRATCH_ROWS, N_STATE)), np.zeros((2, 4))
        prime(x, plant, aux, counters, np.zeros(6), packet, scratch)
        command = np.full(4, 0.2, dtype=np.float32)
        roll, thrusts = [], []
        for i in range(24000):  # 3 s: the rotors settle, then 2 s of gyro
            assert step(x, command, plant, aux, pending, counters, np.zeros(6), packet, scratch) == 0
            if i >= 8000:
                roll.append(packet[1])
                thrusts.append(x[13:17].copy())
        assert counters[C_CONTACT] == 1  # below its weight: on the floor
        rolls[name] = np.array(roll)
    assert np.all(rolls["still"] == 0.0)  # the frame stands still on the floor: no rate, no line
    line = rolls["shaking"]
    forces = np.array(Airframe().thrust_gains) * np.mean(thrusts, axis=0)  # each rotor's gain: its own speed
    rotor_hz = np.sqrt(forces / Airframe().thrust_coefficient_n_s2) / (2.0 * math.pi)
    spectrum = np.abs(np.fft.rfft(line * np.hanning(line.size)))
    peak_hz = np.fft.rfftfreq(line.size, step_s)[np.argmax(spectrum)]
    assert rotor_hz.min() - 1.0 <= peak_hz <= rotor_hz.max() + 1.0
    assert 100.0 < peak_hz < 200.0
    # the four lines' amplitudes grow with each rotor's thrust (the uneven motors: 0.97-1.01 of the reference)
    assert float(np.sqrt(np.mean(line**2))) == pytest.approx(0.2, rel=0.15)


def test_pilot_sticks_signs() -> None:
    settings = load_settings()
    sticks = StickMap.from_settings(settings, Airframe(), 0.752)
    assert sticks.rate_max_rad_s == pytest.approx(math.radians(2000.0))
    limits = sticks.limits(max_tilt_rad=math.radians(35), max_climb_m_s=2.0, gravity_m_s2=9.81)
    hover_us = throttle_for_collective(9.81, limits)
    assert 1200 < hover_us < 1300  # u ≈ 0.25 on the thrust curve, 5.5 % idle, from 1050 us
    out = np.zeros(4)
    program_sticks(np.array([9.81, 1.0, 2.0, 3.0]), limits, out)
    assert out[:3] == pytest.approx([1.0 / sticks.rate_max_rad_s, 2.0 / sticks.rate_max_rad_s,
                                     -3.0 / sticks.rate_max_rad_s])
    gains = np.array([4.0, 3.5, 0.0, 3.0])
    level = np.array([1.0, 0.0, 0.0, 0.0])
    for target, check in (((1.0, 0.0, 0.0), lambda o: o[1] > 0.05 and abs(o[0]) < 1e-9),   # ahead: nose down
                          ((0.0, 1.0, 0.0), lambda o: o[0] < -0.05 and abs(o[1]) < 1e-9),  # left: roll left
                          ((0.0, 0.0, 1.0), lambda o: o[3] > hover_us + 10)):              # above: more throttle
        angle_sticks(np.zeros(3), np.zeros(3), level, np.array(target), np.zeros(3), gains, limits, 0.004, out)
        assert check(out), (target, out)


def test_settings_file_errors_name_the_file_field_and_range(tmp_path) -> None:
    path = tmp_path / "bf.toml"
    path.write_text("[radio]\nrate_hz = 5000.0\n")
    with pytest.raises(ConfigError, match=r"bf\.toml.*radio.*rate_hz = 5000 is out of range: allowed \[25, 1000\]"):
        load_betaflight(path)
    path.write_text("[airframe]\nmotor_tau_up_s = -1.0\n")
    with pytest.raises(ConfigError, match=r"airframe.*motor_tau_up_s"):
        load_betaflight(path)
    path.write_text("[firmware]\ngyro_rate_hz = 3000\n")
    with pytest.raises(ConfigError, match=r"gyro_rate_hz = 3000"):
        load_betaflight(path)
    path.write_text("[pilot]\nhover_seconds = 1.0\n")
    with pytest.raises(ConfigError, match=r"unknown field.*hover_seconds"):
        load_betaflight(path)


def test_settings_round_trip_and_choice_stores_content(tmp_path) -> None:
    params = BetaflightParams().replace(radio__drop_probability=0.05, pilot__hover_s=2.0)
    path = tmp_path / "bf.toml"
    save_betaflight(params, path)
    assert load_betaflight(path) == params
    choice = PlantChoice.from_file("betaflight", path, seed=3)
    again = PlantChoice.from_table(choice.to_table(), source="stored")
    assert again.settings == params and again.seed == 3
    assert PLANTS.get("betaflight", source="test").option == "--betaflight"


def test_firmware_settings_file_errors(tmp_path) -> None:
    path = tmp_path / "settings.toml"
    path.write_text("schema = 1\n[modes.ARM]\npermanent_id = 0\naux = 20\nrange_us = [1700, 2100]\n")
    with pytest.raises(ConfigError, match=r"settings\.toml: \[modes\.ARM\] aux = 20: out of range"):
        load_settings(path)
    path.write_text("schema = 2\n")
    with pytest.raises(ConfigError, match="schema"):
        load_settings(path)


def test_the_battery_sags_every_rotors_thrust_under_load() -> None:
    """Half a second at constant commands in the air: each rotor's thrust settles at f(u) × ((rest − sag ·
    mean(u²)) / reference)², and an airframe without a rest voltage flies exactly as before the battery model."""
    commands = np.array([0.3, 0.5, 0.7, 0.9], dtype=np.float32)

    def settled(params: BetaflightParams) -> np.ndarray:
        aux = aux_vector(params, step_s=125e-6, ground_z_m=-1e6, gravity_m_s2=9.81)
        x = ground_state((0.0, 0.0, 100.0))
        counters = np.zeros(N_COUNTERS, dtype=np.int64)
        counters[C_DELAY] = 1
        args = (airframe_plant(params), aux, np.zeros((2, 4)), counters, np.zeros(6), np.zeros(PACKET_DOUBLES),
                np.zeros((SCRATCH_ROWS, N_STATE)))
        for _ in range(4000):  # 0.5 s: fifteen motor time constants
            assert step(x, commands, *args) == 0
        return x[13:17].copy()

    sagging = IDEAL.replace(airframe__battery_reference_v=15.6, airframe__battery_rest_v=16.3,
                            airframe__battery_sag_v=3.0)
    u = commands.astype(float)
    factor = ((16.3 - 3.0 * np.mean(u**2)) / 15.6) ** 2
    expected = np.array([sagging.airframe.thrust_n(c) for c in u]) * factor
    assert settled(sagging) == pytest.approx(expected, rel=1e-6)
    assert sagging.airframe.battery_factor(u) == pytest.approx(factor, rel=1e-12)
    without = IDEAL.replace(airframe__battery_reference_v=15.6)  # a replay's reference only: no model flown
    assert np.array_equal(settled(without), settled(IDEAL))
    assert settled(IDEAL) == pytest.approx([IDEAL.airframe.thrust_n(c) for c in u], rel=1e-6)
