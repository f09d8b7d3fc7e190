"""Faults: a firmware killed or hung mid-trial, and SITL processes that must never outlive their owner."""

from __future__ import annotations

import math
import os
import signal
import socket
import struct
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from bf_processes import sitl_processes, wait_gone

from aerobat.core.design import design
from aerobat.core.learning import IterationStatus, learn
from aerobat.core.plant import TrialStatus
from aerobat.firmware.betaflight.sitl import SitlProcess
from aerobat.firmware.betaflight.transport import TcpTransport
from aerobat.plants.betaflight.flight import Flight
from aerobat.plants.betaflight.plant import BetaflightPlant
from aerobat.plants.fpv.params import BetaflightParams
from aerobat.quadrotor.maneuvers import MultiFlip
from aerobat.quadrotor.simulate import NominalModel
from aerobat.quadrotor.vehicle import fpv5

FPV = fpv5()
FLIP = MultiFlip(vehicle=FPV.vehicle, flips=1, max_rate_rad_s=math.radians(800), dims=2)
DESIGN = design(FLIP, NominalModel(FPV))
UDP = BetaflightParams().replace(firmware__exchange="udp")  # sockets; shared memory (default): test_betaflight_shm.py
FAKE = Path(__file__).with_name("fake_sitl.py")


def sabotage(monkeypatch: pytest.MonkeyPatch, trials: set[int], at_s: float, how: signal.Signals,
             seen: list[int]) -> None:
    """Send ``how`` to the firmware of the given trials (1-based) once it has flown ``at_s``.

    Checked before each compiled run of frames: the signal goes out at most
    :data:`~aerobat.plants.betaflight.flight.CHUNK_FRAMES` frames after ``at_s``.
    """
    original = Flight.run_frames
    state = {"trial": 0, "flight": None}

    def run_frames(self: Flight, *args: Any, **kwargs: Any) -> Any:
        if state["flight"] is not self:
            state["flight"], state["trial"], state["done"] = self, state["trial"] + 1, False
        if state["trial"] in trials and not state["done"] and self.time_s >= at_s:
            state["done"] = True
            assert self.sitl.pid is not None
            seen.append(self.sitl.pid)
            os.kill(self.sitl.pid, how)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(Flight, "run_frames", run_frames)


def test_firmware_killed_mid_trial_is_a_lost_trial_and_learning_goes_on(
        firmware: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch) -> None:
    killed: list[int] = []
    sabotage(monkeypatch, {2}, at_s=5.0, how=signal.SIGKILL, seen=killed)  # during the second trial
    plant = BetaflightPlant(FPV, UDP, seed=11)  # shared memory (the default): test_betaflight_shm.py
    session = learn(FLIP, DESIGN, plant, iterations=3)
    statuses = [it.status for it in session.iterations]
    assert statuses == [IterationStatus.OK, IterationStatus.LOST, IterationStatus.OK, IterationStatus.OK]
    lost = session.iterations[1]
    assert "firmware lost" in lost.message and "exited with status -9" in lost.message
    assert np.array_equal(lost.params, session.iterations[2].params)  # the lost parameters are flown again
    assert len(killed) == 1 and wait_gone(killed[0])


def test_watchdog_restarts_a_firmware_that_stops_answering(
        firmware: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch) -> None:
    stopped: list[int] = []
    sabotage(monkeypatch, {1}, at_s=3.0, how=signal.SIGSTOP, seen=stopped)
    plant = BetaflightPlant(FPV, UDP.replace(firmware__step_timeout_s=0.5), seed=12)
    started = time.monotonic()
    trial = plant.fly(FLIP.program(DESIGN.p_nominal))
    assert trial.status is TrialStatus.LOST and "no motor packet within 0.5 s" in trial.message
    assert time.monotonic() - started < 10.0
    assert stopped and wait_gone(stopped[0])  # the hung process was killed, not left stopped
    again = plant.fly(FLIP.program(DESIGN.p_nominal))  # a new firmware
    assert again.ok, again.message


def test_our_sockets_never_wait_without_a_timeout() -> None:
    with SitlProcess(FAKE, None) as sitl:
        sockets = [sitl._motor_socket, sitl._state_socket, sitl._rc_socket]
        receive = struct.unpack("ll", sitl._motor_socket.getsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, 16))
        assert 0 < receive[0] * 1e6 + receive[1] <= 100_000  # the motor socket wakes the watchdog
        for sock in sockets:
            sent = struct.unpack("ll", sock.getsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, 16))
            assert sent != (0, 0) or sock is sitl._motor_socket
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        transport = TcpTransport("127.0.0.1", server.getsockname()[1], connect_timeout_s=1.0)
        started = time.monotonic()
        assert transport.read(16, 0.2) == b""  # a silent flight controller: the read returns
        assert time.monotonic() - started < 1.0
        transport.close()


def _owner_script(body: str) -> str:
    return textwrap.dedent(body)


def test_no_firmware_outlives_a_killed_learning_session(firmware: tuple[Path, Path], tmp_path: Path) -> None:
    exe = Path(sys.executable).with_name("aerobat")
    command = [str(exe), "learn", "flip", "--flips", "1", "--max-rate-deg-s", "800", "--dims", "2", "--vehicle",
               "fpv5", "--plant", "betaflight", "--iterations", "5", "--db", str(tmp_path / "s.sqlite"),
               "--out", str(tmp_path / "out")]
    session = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60.0
        children: list[int] = []
        while not children and time.monotonic() < deadline:
            children = sitl_processes(session.pid)
            time.sleep(0.05)
        assert children, "the session never started a firmware"
        session.kill()  # SIGKILL: no cleanup code runs in the session
        session.wait(timeout=10)
        assert all(wait_gone(pid) for pid in children)
    finally:
        if session.poll() is None:
            session.kill()
            session.wait()


def test_no_firmware_outlives_a_failed_test(firmware: tuple[Path, Path], tmp_path: Path) -> None:
    pid_file = tmp_path / "pid"
    test_file = tmp_path / "test_leaks.py"
    test_file.write_text(_owner_script(f"""
        from pathlib import Path
        from aerobat.firmware.betaflight.sitl import SitlProcess

        def test_fails_with_a_firmware_running():
            sitl = SitlProcess(Path({str(firmware[0])!r}), Path({str(firmware[1])!r}))
            Path({str(pid_file)!r}).write_text(str(sitl.pid))
            assert False, "this test fails on purpose and never closes its firmware"
        """))
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(test_file)],
                            capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert result.returncode == 1, result.stdout[-2000:]
    assert wait_gone(int(pid_file.read_text()))


def test_no_firmware_outlives_its_plant(firmware: tuple[Path, Path]) -> None:
    plant = BetaflightPlant(FPV, seed=13)
    flight = plant.open_flight()
    pid = flight.sitl.pid
    assert pid is not None and pid in sitl_processes()
    del flight  # dropped without close(): the finalizer kills it
    import gc

    gc.collect()
    assert wait_gone(pid)
