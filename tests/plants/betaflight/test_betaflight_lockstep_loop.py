"""The compiled lockstep loop (:mod:`aerobat.plants.betaflight.lockstep`): the same flight as step by step."""

from __future__ import annotations

import math
import socket
import time
from pathlib import Path

import numpy as np
import pytest

from aerobat.plants.betaflight.errors import FirmwareNotResponding
from aerobat.plants.betaflight.flight import Flight
from aerobat.plants.betaflight.packets import MOTOR_STRUCT
from aerobat.plants.betaflight.params import BetaflightParams
from aerobat.plants.betaflight.physics import airframe_plant, step
from aerobat.plants.betaflight.plant import BetaflightPlant
from aerobat.plants.lab_kernels import mocap_sample
from aerobat.quadrotor.vehicle import fpv5

FAKE = Path(__file__).with_name("fake_sitl.py")
FPV = fpv5()


def _python_advance(flight: Flight, n: int) -> None:
    """The step-by-step loop the compiled one replaced: one Python exchange and physics step per gyro step."""
    noise = flight._noise(n)
    mc = flight.params.motion_capture
    rows = n // flight.mocap_every + 2
    mocap_noise = np.zeros((rows, 6))
    if mc.position_noise_m:
        mocap_noise[:, :3] = mc.position_noise_m * flight.rng.standard_normal((rows, 3))
    if mc.attitude_noise_rad:
        mocap_noise[:, 3:] = mc.attitude_noise_rad * flight.rng.standard_normal((rows, 3))
    used = 0
    for i in range(n):
        if flight.tick % flight.mocap_every == 0:
            mocap_sample(flight.x, flight.tick * flight.step_s, mocap_noise[used], flight.log[flight.log_count])
            flight.log_count += 1
            used += 1
        while flight._queue and flight._queue[0][0] <= flight.tick:
            flight.sitl.send_rc(flight._queue.pop(0)[1])
        flight.sitl.exchange(flight.packet, flight.block)
        assert not step(flight.x, flight.motors, flight.plant, flight.aux, flight.pending, flight.counters,
                        noise[i], flight.packet, flight.scratch)
        flight.tick += 1


def _arm_and_climb(plant: BetaflightPlant, flight: Flight) -> np.ndarray:
    plant.power_on_and_arm(flight)
    sticks = np.array([0.0, 0.0, 0.0, 1000.0])
    motors = []
    for k in range(flight.frames_for(0.6)):
        sticks[3] = 1000.0 + 8.0 * k  # a throttle ramp: the vehicle lifts off
        flight.frame(plant.channels(sticks, arm=True, angle=True))
        motors.append(flight.motors.copy())
    return np.array(motors)


def test_the_compiled_loop_flies_bit_for_bit_like_the_step_by_step_exchange(
        firmware: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch) -> None:
    seen = []
    for python in (False, True):
        if python:
            monkeypatch.setattr(Flight, "_advance", _python_advance)
        plant = BetaflightPlant(FPV, seed=5)
        with plant.open_flight() as flight:
            motors = _arm_and_climb(plant, flight)
            seen.append((motors, flight.truth(), flight.mocap().copy(), flight.sitl.steps, flight.tick))
    (motors, truth, mocap, packets, ticks), again = seen
    assert motors[-1].max() > 0.2  # it flew: motors well above idle
    assert np.array_equal(motors, again[0]) and np.array_equal(truth, again[1]) and np.array_equal(mocap, again[2])
    assert packets == ticks == again[3] == again[4]  # one motor packet per state packet either way


def test_firmware_cpu_time_is_part_of_the_trial_timing(firmware: tuple[Path, Path]) -> None:
    plant = BetaflightPlant(FPV, seed=6)
    with plant.open_flight() as flight:
        before = flight.firmware_cpu_time_s()
        _arm_and_climb(plant, flight)
        during = flight.firmware_cpu_time_s()
        assert before is not None and during is not None and during > before
        timing = plant._timing(flight, time.perf_counter() - 1.0)
    assert timing["firmware_cpu_s"] == pytest.approx(during, rel=0.5)
    assert math.isclose(timing["wall_per_firmware_cpu"], timing["wall_s"] / timing["firmware_cpu_s"])
    assert flight.firmware_cpu_time_s() is not None  # kept from the end of the process


def _fake_flight() -> Flight:
    params = BetaflightParams()
    return Flight(FAKE, None, params, airframe_plant(params), np.zeros(3),  # type: ignore[arg-type]
                  np.random.default_rng(0), 9.81)


def test_a_stray_datagram_is_skipped_and_the_answer_taken() -> None:
    with _fake_flight() as flight:
        flight.frame(tuple([1500] * 16))
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as stray:
            stray.sendto(b"\x00" * (MOTOR_STRUCT.size - 4), ("127.0.0.1", flight.sitl.ports.motor_port))
            flight.frame(tuple([1500] * 16))
        assert flight.sitl.steps == flight.tick == 2 * flight.frame_steps
        # the fake answers each state packet with its timestamp: the last packet is the last step's
        assert flight.motors[2] == pytest.approx((flight.tick - 1) * flight.step_s)
        delivered = flight.frames_sent - flight.frames_dropped - len(flight._queue)
        assert flight.motors[0] == delivered  # and counts the RC frames it got


def test_a_mute_firmware_trips_the_watchdog_inside_the_compiled_loop(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FAKE_SITL_MODE", "mute")
    params = BetaflightParams().replace(firmware__step_timeout_s=0.3)
    with Flight(FAKE, None, params, airframe_plant(params), np.zeros(3),  # type: ignore[arg-type]
                np.random.default_rng(0), 9.81) as flight:
        started = time.monotonic()
        with pytest.raises(FirmwareNotResponding, match="no motor packet within 0.3 s"):
            flight.frame(tuple([1500] * 16))
        assert time.monotonic() - started < 0.3 + 0.2
        assert flight.tick == 0 and flight.sitl.steps == 0


def test_the_firmware_packet_is_received_whole() -> None:
    with _fake_flight() as flight:
        assert flight.block.nbytes == MOTOR_STRUCT.size and flight.motors.base is not None
        flight.frame(tuple([1500] * 16))
        assert MOTOR_STRUCT.unpack_from(flight.block.tobytes()) == tuple(float(v) for v in flight.motors)
        assert flight.motors.size == 19  # motors, then the set point and the P, I, D, F terms
