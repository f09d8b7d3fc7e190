"""The plant on a board (a pseudo-terminal answering MSP as Betaflight does): it refuses to take off for
every reason it must, naming them, and a dry run streams the program with nothing armed."""

from __future__ import annotations

import math
import os
import struct
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("serial", reason="pyserial is not installed (pip install 'aerobat[fc]')")
pytestmark = pytest.mark.xdist_group("real_time")  # flights on the wall clock: one at a time (tests/README.md)

from fake_board import FakeBoard  # noqa: E402

from aerobat.core.design import design  # noqa: E402
from aerobat.core.plant import TrialStatus  # noqa: E402
from aerobat.errors import ConfigError  # noqa: E402
from aerobat.firmware.betaflight.msp import (  # noqa: E402
    FEATURE_RX_MSP,
    MSP_BATTERY_STATE,
    MSP_FAILSAFE_CONFIG,
    MSP_FEATURE_CONFIG,
    MSP_MODE_RANGES,
    MSP_MOTOR,
    MSP_SET_RAW_RC,
    MSP_STATUS_EX,
    BatteryAlert,
)
from aerobat.plants.fc import Pose  # noqa: E402
from aerobat.plants.fc.plant import BoardConnection, FlightControllerPlant, build_fc_plant  # noqa: E402
from aerobat.plants.fc.settings import FcSettings, LinkKind, LinkSettings  # noqa: E402
from aerobat.quadrotor.maneuvers import MultiFlip  # noqa: E402
from aerobat.quadrotor.simulate import NominalModel  # noqa: E402
from aerobat.quadrotor.vehicle import fpv5  # noqa: E402

FPV = fpv5()
FLIP = MultiFlip(vehicle=FPV.vehicle, flips=1, max_rate_rad_s=math.radians(800.0), dims=2)
P0 = design(FLIP, NominalModel(FPV)).p_nominal


def _status(mask: int = 0, *, armed: bool = False) -> bytes:
    return struct.pack("<HHHIBH", 125, 0, 0, int(armed), 0, 0) + bytes((3, 0, 0, 29)) + struct.pack("<I", mask)


def _ranges(arm_aux: int = 1) -> bytes:
    used = bytes((0, arm_aux - 1, (1700 - 900) // 25, (2100 - 900) // 25, 1, 1, 32, 48))
    return used + bytes(4 * 18)


def _battery(volts: float = 16.4, cells: int = 4, alert: BatteryAlert = BatteryAlert.OK) -> bytes:
    return struct.pack("<BHBHhBH", cells, 1500, round(volts * 10), 0, 0, int(alert), round(volts * 100))


def _failsafe(delay_ds: int = 15, procedure: int = 1) -> bytes:
    """MSP_FAILSAFE_CONFIG as Betaflight 4.6 frames it (msp.c); procedure 1 is DROP, 2 GPS_RESCUE."""
    return struct.pack("<BBHBHB", delay_ds, 60, 1000, 0, 100, procedure)


def _answers(**change: bytes) -> dict[int, bytes]:
    answers = {MSP_SET_RAW_RC: b"", MSP_STATUS_EX: _status(), MSP_BATTERY_STATE: _battery(),
               MSP_FEATURE_CONFIG: struct.pack("<I", FEATURE_RX_MSP), MSP_MODE_RANGES: _ranges(),
               MSP_FAILSAFE_CONFIG: _failsafe()}
    names = {"status": MSP_STATUS_EX, "battery": MSP_BATTERY_STATE, "features": MSP_FEATURE_CONFIG,
             "ranges": MSP_MODE_RANGES, "failsafe": MSP_FAILSAFE_CONFIG}
    answers.update({names[k]: v for k, v in change.items()})
    return answers


class OnTheFloor:
    """Motion capture of a vehicle standing still on the floor below the start (z = start + volume low)."""

    def __init__(self, z_m: float) -> None:
        self.z_m, self.frame = z_m, 0

    def wait(self, timeout_s: float) -> list[Pose]:
        self.frame += 1
        now = time.monotonic()
        return [Pose((0.0, 0.0, self.z_m), (1.0, 0.0, 0.0, 0.0), now, now - 0.005, self.frame)]

    def close(self) -> None:
        pass


def _plant(board: FakeBoard, *, dry_run: bool = False) -> FlightControllerPlant:
    poses = OnTheFloor(0.0)  # a room's floor at z = 0, the start above it (the default volume: 2.5 m)
    return FlightControllerPlant(FPV, BoardConnection(board.device, poses), dry_run=dry_run,
                                 binary=Path(os.devnull), eeprom=Path(os.devnull))


@pytest.mark.parametrize("change, problem", [
    ({"features": struct.pack("<I", 1 << 3)}, "firmware: the receiver is not MSP"),
    ({"ranges": _ranges(arm_aux=3)}, "firmware: ARM is not on AUX1 1700–2100 µs"),
    ({"failsafe": _failsafe(procedure=2)}, "firmware: failsafe_procedure is GPS_RESCUE; a room needs DROP"),
    ({"failsafe": _failsafe(delay_ds=50)}, "firmware: failsafe_delay is 5 s, above max_failsafe_delay_s 2 s"),
    ({"battery": _battery(13.6)}, "battery: 3.40 V per cell, below min_cell_voltage_v 3.5 V"),
    ({"battery": _battery(0.0, cells=0, alert=BatteryAlert.NOT_PRESENT)}, "battery: none detected"),
    ({"status": _status(mask=1 << 2)}, "arming: the firmware refuses to arm (RXLOSS)"),
])
def test_a_take_off_is_refused_naming_the_problem_and_nothing_is_armed(change, problem):
    board = FakeBoard(_answers(**change))
    try:
        trial = _plant(board).fly(FLIP.program(P0))
        assert trial.status is TrialStatus.ABORTED and trial.message.startswith("pre-flight refused: ")
        assert any(p.startswith(problem) for p in trial.info["preflight"]), trial.info["preflight"]
        frames = [p for c, p in board.received if c == MSP_SET_RAW_RC]
        assert frames and all(struct.unpack_from("<5H", p)[4] < 1700 for p in frames)  # AUX1 (ARM) never on
    finally:
        board.unplug()


def test_a_dry_run_streams_the_program_disarmed_and_measures_nothing():
    board = FakeBoard(_answers())
    try:
        trial = _plant(board, dry_run=True).fly(FLIP.program(P0))
        assert trial.status is TrialStatus.ABORTED and trial.message.startswith("dry run: pre-flight passed")
        streamed = trial.info["dry_run"]
        assert streamed["frames"] >= FLIP.program(P0).compile().duration_s * 250.0 - 1
        frames = [p for c, p in board.received if c == MSP_SET_RAW_RC]
        assert all(struct.unpack_from("<5H", p)[4] < 1700 for p in frames)  # ARM never on
        assert any(abs(struct.unpack_from("<H", p)[0] - 1500) > 100 for p in frames)  # the program's sticks went
    finally:
        board.unplug()


def test_a_board_that_is_not_there_is_refused_when_the_plant_is_built():
    settings = FcSettings(link=LinkSettings(kind=LinkKind.SERIAL, port="/dev/ttyACM96"))
    with pytest.raises(ConfigError, match=r"^--port /dev/ttyACM96: no such device"):
        build_fc_plant(FPV, settings)


def test_a_serial_link_without_a_port_is_refused_in_the_settings():
    with pytest.raises(ConfigError, match=r"port = '': required with kind = 'serial'"):
        LinkSettings(kind="serial")


def test_a_battery_going_critical_in_flight_stops_the_flight_and_disarms():
    board = FakeBoard({**_answers(), MSP_MOTOR: struct.pack("<8H", *([1100] * 4 + [0] * 4))})  # armed at idle
    plant = _plant(board)

    def critical_once_armed() -> None:
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and not any(
                c == MSP_SET_RAW_RC and struct.unpack_from("<5H", p)[4] >= 1700 for c, p in board.received):
            time.sleep(0.01)
        board.answers[MSP_BATTERY_STATE] = _battery(15.0, alert=BatteryAlert.CRITICAL)

    watcher = threading.Thread(target=critical_once_armed, daemon=True)
    watcher.start()
    try:
        trial = plant.fly(FLIP.program(P0))
        assert trial.status is TrialStatus.ABORTED and trial.info["safety_stop"] == "low_battery", trial.message
        frames = [p for c, p in board.received if c == MSP_SET_RAW_RC]
        assert any(struct.unpack_from("<5H", p)[4] >= 1700 for p in frames)  # it had armed
        assert struct.unpack_from("<5H", frames[-1])[4] < 1700  # and the last frame it sent disarms
    finally:
        board.unplug()


def test_a_board_that_stays_armed_after_a_stop_is_named_and_sent_disarmed_frames_again():
    board = FakeBoard({**_answers(), MSP_MOTOR: struct.pack("<8H", *([1100] * 4 + [0] * 4))})
    plant = _plant(board)

    def armed_for_good() -> None:  # once the ARM switch is on, the board says armed whatever it is sent
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and not any(
                c == MSP_SET_RAW_RC and struct.unpack_from("<5H", p)[4] >= 1700 for c, p in board.received):
            time.sleep(0.01)
        board.answers[MSP_STATUS_EX] = _status(armed=True)
        board.answers[MSP_BATTERY_STATE] = _battery(15.0, alert=BatteryAlert.CRITICAL)

    watcher = threading.Thread(target=armed_for_good, daemon=True)
    watcher.start()
    try:
        trial = plant.fly(FLIP.program(P0))
        assert trial.info["safety_stop"] == "low_battery" and trial.info["disarm_confirmed"] is False
        assert trial.message.endswith("THE BOARD STILL REPORTS ITSELF ARMED"), trial.message
        asked = [i for i, (c, _) in enumerate(board.received) if c == MSP_STATUS_EX]
        frames_after_stop = [p for c, p in board.received[asked[-3]:] if c == MSP_SET_RAW_RC]
        assert frames_after_stop and all(struct.unpack_from("<5H", p)[4] < 1700 for p in frames_after_stop)
    finally:
        board.unplug()
