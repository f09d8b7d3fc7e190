"""The shared-memory lockstep exchange (``firmware.exchange = "shm"``): the flights and the watchdog of UDP."""

from __future__ import annotations

import hashlib
import math
import os
import signal
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_betaflight_faults import sabotage, wait_gone

from aerobat.core.design import design
from aerobat.core.plant import TrialStatus
from aerobat.errors import ConfigError
from aerobat.firmware.betaflight.configure import AT_REST_LEVEL, step_at_rest
from aerobat.firmware.betaflight.errors import FirmwareExited, FirmwareNotResponding
from aerobat.firmware.betaflight.packets import Exchange
from aerobat.firmware.betaflight.shm import ensure_library
from aerobat.firmware.betaflight.sitl import SitlProcess
from aerobat.plants.betaflight.flight import Flight
from aerobat.plants.betaflight.physics import airframe_plant
from aerobat.plants.betaflight.plant import BetaflightPlant
from aerobat.plants.fpv.params import BetaflightParams
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel
from aerobat.quadrotor.vehicle import fpv5

FPV = fpv5()
FLIP = MultiFlip(vehicle=FPV.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
DESIGN = design(FLIP, NominalModel(FPV))
FAKE = Path(__file__).with_name("fake_sitl.py")
SHM = BetaflightParams().replace(firmware__exchange="shm")
UDP = BetaflightParams().replace(firmware__exchange="udp")
MEMFD = "memfd:aerobat-betaflight-lockstep"


def _digest(trial: Any) -> str:
    digest = hashlib.sha256()
    for array in (trial.final_state, trial.states, trial.times_s):
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def _mapped(pid: int) -> bool:
    try:
        return MEMFD in Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return False


def _dev_shm() -> set[str]:
    return set(os.listdir("/dev/shm")) if os.path.isdir("/dev/shm") else set()


def test_exchange_is_checked() -> None:
    assert BetaflightParams().firmware.exchange is Exchange.SHM  # the default (docs/performance.md, issue 27)
    assert UDP.firmware.exchange is Exchange.UDP
    with pytest.raises(ConfigError, match="^exchange = 'pipe': allowed 'udp', 'shm'$"):
        BetaflightParams().replace(firmware__exchange="pipe")
    with pytest.raises(ValueError, match="exchange = 'pipe'"):
        SitlProcess(FAKE, None, exchange="pipe")


def test_a_trial_over_shared_memory_is_bit_identical_to_udp(firmware: tuple[Path, Path]) -> None:
    program = FLIP.program(DESIGN.p_nominal)
    udp = BetaflightPlant(FPV, UDP, seed=3).fly(program)
    shm = BetaflightPlant(FPV, SHM, seed=3).fly(program)
    assert udp.ok and shm.ok, (udp.message, shm.message)
    assert udp.info["steps"] == shm.info["steps"] > 10_000
    assert _digest(udp) == _digest(shm)


def test_the_firmware_takes_its_packets_from_the_region_and_no_file_is_left(firmware: tuple[Path, Path]) -> None:
    before = _dev_shm()
    plant = BetaflightPlant(FPV, SHM, seed=4)
    with plant.open_flight() as flight:
        plant.pilot.power_on_and_arm(flight)
        pid = flight.sitl.pid
        assert pid is not None and flight.sitl.shm_address is not None
        assert _mapped(pid) and _mapped(os.getpid())  # both map the memfd; no path names it
        assert "through shared memory" in flight.sitl.log_path.read_text()
        assert flight.sitl.steps == flight.tick > 8000 and max(flight.motor_commands()) > 0.0  # armed
        assert _dev_shm() == before
    assert wait_gone(pid) and not _mapped(os.getpid()) and flight.sitl.shm_address is None
    assert _dev_shm() == before


def test_a_firmware_killed_mid_trial_is_lost_and_the_next_trial_flies(
        firmware: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch) -> None:
    killed: list[int] = []
    sabotage(monkeypatch, {1}, at_s=3.0, how=signal.SIGKILL, seen=killed)
    plant = BetaflightPlant(FPV, SHM, seed=13)
    started = time.monotonic()
    lost = plant.fly(FLIP.program(DESIGN.p_nominal))
    assert lost.status is TrialStatus.LOST and "exited with status -9" in lost.message
    assert time.monotonic() - started < 20.0
    assert len(killed) == 1 and wait_gone(killed[0])
    again = plant.fly(FLIP.program(DESIGN.p_nominal))
    assert again.ok, again.message
    assert not _mapped(os.getpid())


def test_a_hung_firmware_is_lost_within_the_step_timeout_and_the_next_trial_flies(
        firmware: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch) -> None:
    stopped: list[int] = []
    sabotage(monkeypatch, {1}, at_s=3.0, how=signal.SIGSTOP, seen=stopped)
    plant = BetaflightPlant(FPV, SHM.replace(firmware__step_timeout_s=0.5), seed=12)
    lost = plant.fly(FLIP.program(DESIGN.p_nominal))
    assert lost.status is TrialStatus.LOST and "no motor packet within 0.5 s" in lost.message
    assert stopped and wait_gone(stopped[0])  # the stopped process was killed, not left stopped
    again = plant.fly(FLIP.program(DESIGN.p_nominal))
    assert again.ok, again.message


def test_the_step_interface_over_shared_memory(firmware: tuple[Path, Path]) -> None:
    binary, eeprom = firmware
    with SitlProcess(binary, eeprom, exchange="shm") as sitl:
        assert step_at_rest(sitl, lambda: False, 2000) == 2000 and sitl.steps == 2000
        with pytest.raises(ValueError):
            sitl.step(AT_REST_LEVEL._replace(time_s=125e-6))  # time must increase
    with pytest.raises(FirmwareExited):
        sitl.step(AT_REST_LEVEL._replace(time_s=1.0))  # closed: no write to an unmapped region


@pytest.fixture
def fake_shm(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FAKE_SITL_SHM_LIB", str(ensure_library()))


def _fake_flight(params: BetaflightParams) -> Flight:
    return Flight(FAKE, None, params, airframe_plant(params), np.zeros(3),  # type: ignore[arg-type]
                  np.random.default_rng(0), 9.81)


@pytest.mark.usefixtures("fake_shm")
def test_the_compiled_loop_over_shared_memory_with_a_stand_in_firmware() -> None:
    with _fake_flight(SHM) as flight:
        for _ in range(3):
            flight.frame(tuple([1500] * 16))
        assert flight.sitl.steps == flight.tick == 3 * flight.frame_steps
        assert flight.motors[2] == pytest.approx((flight.tick - 1) * flight.step_s)  # the last step's answer
        delivered = flight.frames_sent - flight.frames_dropped - flight.frames_queued
        assert flight.motors[0] == delivered and flight.motors[1] == pytest.approx(1.5)


@pytest.mark.usefixtures("fake_shm")
def test_a_mute_firmware_trips_the_watchdog_over_shared_memory(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FAKE_SITL_MODE", "mute")
    with _fake_flight(SHM.replace(firmware__step_timeout_s=0.3)) as flight:
        started = time.monotonic()
        with pytest.raises(FirmwareNotResponding, match="no motor packet within 0.3 s"):
            flight.frame(tuple([1500] * 16))
        assert time.monotonic() - started < 0.3 + 0.2
        assert flight.tick == 0 and flight.sitl.steps == 0


@pytest.mark.parametrize("spin_us", [0.0, 7.0])
def test_the_declared_spin_reaches_the_firmware_and_the_driver(firmware: tuple[Path, Path], spin_us: float) -> None:
    plant = BetaflightPlant(FPV, SHM.replace(firmware__spin_us=spin_us), seed=3)
    with plant.open_flight() as flight:
        flight.frame(tuple([1500] * 16))
        assert flight.sitl._resources.shm.spin_s == pytest.approx(spin_us * 1e-6)
        assert flight.sitl.log_path is not None
        started = flight.sitl.log_path.read_text(errors="replace")
    assert f"spin up to {spin_us:.0f} us" in started, started[-2000:]


def test_a_spin_out_of_range_is_refused_naming_the_field() -> None:
    with pytest.raises(ConfigError, match="spin_us"):
        BetaflightParams().replace(firmware__spin_us=5000.0)
