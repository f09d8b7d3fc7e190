"""Lockstep SITL behaviour at the packet level (needs the firmware; seconds)."""

from __future__ import annotations

import hashlib
import os
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest
from bf_processes import running, wait_gone

from aerobat.firmware.betaflight.configure import AT_REST_LEVEL, step_at_rest
from aerobat.firmware.betaflight.errors import FirmwareExited, FirmwareNotResponding
from aerobat.firmware.betaflight.packets import SitlState
from aerobat.firmware.betaflight.rc import RADIO_LOST_US, RcCommand
from aerobat.firmware.betaflight.settings import load_settings
from aerobat.firmware.betaflight.sitl import SitlProcess

SETTINGS = load_settings()
PERIOD_S = 125e-6


def arm_and_spin(sitl: SitlProcess, roll_stick: float) -> bytes:
    """Calibrate at rest, arm in ACRO, apply a roll stick with a little gyro motion; hash the motor stream."""
    digest = hashlib.sha256()
    sitl.set_rc(RcCommand(aux_us=SETTINGS.aux_us(ARM=False, ANGLE=False)).channels_us())
    step_at_rest(sitl, lambda: False, 12000)  # 1.5 s: gyro calibration
    sitl.set_rc(RcCommand(roll=roll_stick, aux_us=SETTINGS.aux_us(ARM=True, ANGLE=False)).channels_us())
    for k in range(4000):
        gyro = (0.3 * (k % 50) / 50.0, 0.0, 0.0)
        state = SitlState((sitl.steps + 1) * PERIOD_S, gyro, (0.0, 0.0, -9.80665), (1.0, 0.0, 0.0, 0.0))
        digest.update(repr(sitl.step(state)).encode())
    return digest.digest()


def test_one_motor_packet_per_state_packet(firmware: tuple[Path, Path]) -> None:
    binary, eeprom = firmware
    with SitlProcess(binary, eeprom) as sitl:
        assert step_at_rest(sitl, lambda: False, 2000) == 2000
        assert sitl.steps == 2000
        time.sleep(0.05)
        with pytest.raises(BlockingIOError):  # no extra motor packet is waiting
            sitl._motor_socket.recv(64, socket.MSG_DONTWAIT)
        with pytest.raises(ValueError):
            sitl.step(AT_REST_LEVEL._replace(time_s=PERIOD_S))  # time must increase


def test_arms_and_is_deterministic(firmware: tuple[Path, Path]) -> None:
    binary, eeprom = firmware
    hashes = []
    for _ in range(2):
        with SitlProcess(binary, eeprom) as sitl:
            hashes.append(arm_and_spin(sitl, 0.3))
            assert max(sitl.step(AT_REST_LEVEL._replace(time_s=(sitl.steps + 1) * PERIOD_S))) > 0.0  # armed
    assert hashes[0] == hashes[1]


def test_two_instances_concurrently_without_cross_talk(firmware: tuple[Path, Path]) -> None:
    binary, eeprom = firmware
    with SitlProcess(binary, eeprom) as reference:
        expected = {0.3: arm_and_spin(reference, 0.3)}
    with SitlProcess(binary, eeprom) as reference:
        expected[-0.5] = arm_and_spin(reference, -0.5)
    results: dict[float, bytes] = {}
    with SitlProcess(binary, eeprom) as first, SitlProcess(binary, eeprom) as second:
        assert first.ports != second.ports
        threads = [
            threading.Thread(target=lambda: results.__setitem__(0.3, arm_and_spin(first, 0.3))),
            threading.Thread(target=lambda: results.__setitem__(-0.5, arm_and_spin(second, -0.5))),
        ]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
    assert results == expected


def test_radio_lost_fails_safe(firmware: tuple[Path, Path]) -> None:
    binary, eeprom = firmware
    with SitlProcess(binary, eeprom) as sitl:
        arm_and_spin(sitl, 0.0)
        # (a link lost within ~3 s of boot takes longer to fail safe: ~2.4 s, measured)
        step_at_rest(sitl, lambda: False, 16000)
        sitl.set_rc(RADIO_LOST_US)
        motors = None
        disarmed_after_steps = None
        for k in range(3 * 8000):
            motors = sitl.step(AT_REST_LEVEL._replace(time_s=(sitl.steps + 1) * PERIOD_S))
            if max(motors) == 0.0:
                disarmed_after_steps = k
                break
        assert disarmed_after_steps is not None
        assert 1.5 < disarmed_after_steps * PERIOD_S < 2.1  # 0.3 s hold + 1.5 s failsafe_delay


def test_watchdog_detects_a_killed_firmware(firmware: tuple[Path, Path]) -> None:
    binary, eeprom = firmware
    # the exit is seen by polling the process between receive slices, long before the step timeout
    # (a wide timeout, so a loaded machine cannot turn this into a timing test)
    with SitlProcess(binary, eeprom, step_timeout_s=20.0) as sitl:
        step_at_rest(sitl, lambda: False, 100)
        assert sitl.pid is not None
        os.kill(sitl.pid, signal.SIGKILL)
        started = time.monotonic()
        with pytest.raises(FirmwareExited) as caught:
            step_at_rest(sitl, lambda: False, 100)
        assert time.monotonic() - started < 10.0
        assert caught.value.returncode == -signal.SIGKILL
        sitl.restart()
        assert step_at_rest(sitl, lambda: False, 100) == 100


def test_watchdog_detects_a_stalled_firmware(firmware: tuple[Path, Path]) -> None:
    binary, eeprom = firmware
    with SitlProcess(binary, eeprom, step_timeout_s=0.3) as sitl:
        step_at_rest(sitl, lambda: False, 100)
        assert sitl.pid is not None
        os.kill(sitl.pid, signal.SIGSTOP)
        try:
            with pytest.raises(FirmwareNotResponding):
                step_at_rest(sitl, lambda: False, 100)
        finally:
            os.kill(sitl.pid, signal.SIGCONT)


def test_close_kills_and_cleans_up(firmware: tuple[Path, Path]) -> None:
    binary, eeprom = firmware
    sitl = SitlProcess(binary, eeprom)
    pid, workdir = sitl.pid, sitl.workdir
    assert pid is not None and workdir is not None and workdir.is_dir()
    sitl.close()
    assert wait_gone(pid) and not workdir.exists()
    sitl.close()  # idempotent


def test_a_sweep_leaves_a_directory_being_set_up_and_removes_a_dead_owners(tmp_path: Path,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    # found by two trials starting side by side: a sweep read an owner file the other process had
    # created but not yet written, and failed on its empty text. The owner file is now written under
    # another name and renamed, so a sweep sees a whole one or none.
    from aerobat.firmware.betaflight import sitl as sitl_module

    monkeypatch.setattr(sitl_module.tempfile, "gettempdir", lambda: str(tmp_path))
    being_set_up = tmp_path / (sitl_module._WORKDIR_PREFIX + "new")
    being_set_up.mkdir()
    (being_set_up / "owner.partial").write_text("")
    dead = tmp_path / (sitl_module._WORKDIR_PREFIX + "dead")
    dead.mkdir()
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    (dead / "owner").write_text(f"{gone.pid} 1\n")
    mine = tmp_path / (sitl_module._WORKDIR_PREFIX + "mine")
    mine.mkdir()
    (mine / "owner").write_text(f"{sitl_module._process_identity(os.getpid())}\n")
    sitl_module._sweep_stale_workdirs()
    assert being_set_up.is_dir() and mine.is_dir() and not dead.exists()


@pytest.mark.parametrize("ending", ["exit", "sigkill"])
def test_firmware_never_outlives_its_owner(firmware: tuple[Path, Path], ending: str) -> None:
    binary, eeprom = firmware
    owner_code = textwrap.dedent(
        f"""
        import sys
        from pathlib import Path
        from aerobat.firmware.betaflight.sitl import SitlProcess
        sitl = SitlProcess(Path({str(binary)!r}), Path({str(eeprom)!r}))
        print(sitl.pid, sitl.workdir, flush=True)
        sys.stdin.readline()  # exit (atexit finalizer) when told
        """
    )
    owner = subprocess.Popen(
        [sys.executable, "-c", owner_code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    assert owner.stdout is not None and owner.stdin is not None
    pid_text, workdir_text = owner.stdout.readline().split()
    sitl_pid, workdir = int(pid_text), Path(workdir_text)
    assert running(sitl_pid)
    if ending == "sigkill":
        owner.kill()  # no atexit: PR_SET_PDEATHSIG must do it
    else:
        owner.stdin.write("\n")
        owner.stdin.flush()
    owner.wait(timeout=10)
    assert wait_gone(sitl_pid)
    if ending == "sigkill":
        assert workdir.exists()  # a SIGKILLed owner cannot clean up ...
        SitlProcess(binary, eeprom).close()  # ... the next owner sweeps it
    assert not workdir.exists()
