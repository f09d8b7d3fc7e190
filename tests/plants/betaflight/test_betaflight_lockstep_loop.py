"""The compiled lockstep loop (:mod:`aerobat.plants.betaflight.lockstep`): the same flight as step by step."""

from __future__ import annotations

import math
import socket
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from aerobat.core.design import design
from aerobat.core.plant import Trial
from aerobat.firmware.betaflight.errors import FirmwareNotResponding
from aerobat.firmware.betaflight.packets import MOTOR_STRUCT
from aerobat.plants.betaflight.flight import Flight, FramesEnd, FramesRun
from aerobat.plants.betaflight.lockstep import IO_LOG
from aerobat.plants.betaflight.physics import airframe_plant, step
from aerobat.plants.betaflight.plant import BetaflightPlant
from aerobat.plants.fpv.frame_by_frame import run_frames_by_frame
from aerobat.plants.fpv.frames import S_DROPPED, S_SENT, S_TICK, Mode, Radio, Until
from aerobat.plants.fpv.params import BetaflightParams
from aerobat.plants.lab_kernels import mocap_sample
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel
from aerobat.quadrotor.vehicle import fpv5

FAKE = Path(__file__).with_name("fake_sitl.py")
FPV = fpv5()


def _python_run_frames(flight: Flight, mode: Mode, frames: int, *, radio: Radio = Radio.LOSSY,
                       channels_us: np.ndarray | None = None, until: Until = Until.NONE, **_: object) -> FramesRun:
    """The step-by-step loop the compiled one replaced: the radio, the draws and each exchange and step in Python."""
    assert mode is Mode.STREAM and channels_us is not None
    queue: list[tuple[int, tuple[int, ...]]] = flight.__dict__.setdefault("python_queue", [])
    st, n = flight._st, flight.frame_steps
    for k in range(frames):
        row = tuple(int(c) for c in channels_us[k if len(channels_us) > 1 else 0])
        dropped = radio is Radio.LOSSY and flight.rng.random() < flight.params.radio.drop_probability
        st[S_SENT] += radio is not Radio.NONE
        if dropped:
            st[S_DROPPED] += 1
        elif radio is not Radio.NONE:
            queue.append((flight.tick + flight.latency_steps, row))
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
                flight._reserve_log(1)
                mocap_sample(flight.x, flight.tick * flight.step_s, mocap_noise[used], flight.log[flight.log_count])
                st[IO_LOG] += 1
                used += 1
            while queue and queue[0][0] <= flight.tick:
                flight.sitl.send_rc(queue.pop(0)[1])
            flight.sitl.exchange(flight.packet, flight.block)
            assert not step(flight.x, flight.motors, flight.plant, flight.aux, flight.pending, flight.counters,
                            noise[i], flight.packet, flight.scratch)
            st[S_TICK] += 1
        if until is Until.ARMED and min(flight.motor_commands()) > 0.0:
            return FramesRun(FramesEnd.MET, k + 1)
    return FramesRun(FramesEnd.DONE, frames)


def _arm_and_climb(plant: BetaflightPlant, flight: Flight) -> np.ndarray:
    plant.pilot.power_on_and_arm(flight)
    sticks = np.array([0.0, 0.0, 0.0, 1000.0])
    motors = []
    for k in range(flight.frames_for(0.6)):
        sticks[3] = 1000.0 + 8.0 * k  # a throttle ramp: the vehicle lifts off
        flight.frame(plant.pilot.channels(sticks, arm=True, angle=True))
        motors.append(flight.motors.copy())
    return np.array(motors)


def test_the_compiled_loop_flies_bit_for_bit_like_the_step_by_step_exchange(
        firmware: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch) -> None:
    seen = []
    for python in (False, True):
        if python:
            monkeypatch.setattr(Flight, "run_frames", _python_run_frames)
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
    params = BetaflightParams().replace(firmware__exchange="udp")  # the stand-in firmware's sockets
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
        delivered = flight.frames_sent - flight.frames_dropped - flight.frames_queued
        assert flight.motors[0] == delivered  # and counts the RC frames it got


def test_a_mute_firmware_trips_the_watchdog_inside_the_compiled_loop(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FAKE_SITL_MODE", "mute")
    params = BetaflightParams().replace(firmware__step_timeout_s=0.3, firmware__exchange="udp")
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


def _trial_record(trial: Trial, plant: BetaflightPlant) -> tuple[object, ...]:
    timing = {"wall_s", "real_time_factor", "firmware_cpu_s", "wall_per_firmware_cpu", "firmware_spin_s",
              "driver_spin_s", "compiled_calls", "driver_sleeping_share", "driver_spin_switches", "driver_spin_probes"}
    info = {key: value for key, value in trial.info.items() if key not in timing}
    return (trial.status, trial.message, trial.final_state.tobytes(), trial.times_s.tobytes(), trial.states.tobytes(),
            trial.start_state.tobytes(), repr(sorted(info.items())), plant.last_truth[1].tobytes(),
            trial.signals.names if trial.signals is not None else None,  # the firmware's own signals, sampled alike
            trial.signals.values.tobytes() if trial.signals is not None else None)


@pytest.mark.parametrize("exchange", ["udp", "shm"])
def test_the_compiled_supervisor_flies_a_trial_bit_for_bit_like_the_frame_by_frame_one(
        firmware: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch, exchange: str) -> None:
    # the supervisor's phases run compiled (frame_loop); a flight on the wall clock runs them frame by
    # frame in Python (frame_by_frame): both must fly the same trial from the same seed, radio drops,
    # noise, the pilot's settle and hover checks and the truth included
    flip = MultiFlip(vehicle=FPV.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
    program = flip.program(design(flip, NominalModel(FPV)).p_nominal)
    params = BetaflightParams().replace(firmware__exchange=exchange)
    compiled = Flight.run_frames

    def frame(self: Flight, channels_us: Any, *, lossless: bool = False) -> None:
        compiled(self, Mode.STREAM, 1, channels_us=np.array([channels_us], dtype=np.int64),
                 radio=Radio.LOSSLESS if lossless else Radio.LOSSY)

    seen = []
    for by_frame in (False, True):
        if by_frame:

            monkeypatch.setattr(Flight, "frame", frame)
            monkeypatch.setattr(Flight, "run_frames", lambda self, mode, frames, **run: run_frames_by_frame(
                self, self.params.volume, mode, frames, **run))
        plant = BetaflightPlant(FPV, params, seed=21)
        trial = plant.fly(program)
        assert trial.ok, trial.message
        seen.append(_trial_record(trial, plant))
    assert seen[0] == seen[1]


def test_the_link_latency_can_be_lowered_and_raised_again_up_to_the_configured_one() -> None:
    with _fake_flight() as flight:
        configured = flight.latency_steps
        assert configured > 0
        flight.latency_steps = 0
        flight.latency_steps = configured  # back up: the queue was sized for it
        assert flight.latency_steps == configured
        with pytest.raises(ValueError, match="latency of"):
            flight.latency_steps = configured + 1
