"""Frames on the wall clock to a board on a serial port, and the safety stops only the board can cause.

The board is the far end of a pseudo-terminal answering MSP as Betaflight does (:mod:`fake_board`):
the real serial and MSP code paths, with answers the SITL cannot give (its build has no battery
sensor, so a low battery reported by MSP is tested here).
"""

from __future__ import annotations

import struct
import time

import numpy as np
import pytest

pytest.importorskip("serial", reason="pyserial is not installed (pip install 'aerobat[fc]')")
pytestmark = pytest.mark.xdist_group("real_time")  # flights on the wall clock: one at a time (tests/README.md)

from fake_board import FakeBoard  # noqa: E402

from aerobat.firmware.betaflight.msp import (  # noqa: E402
    MSP_BATTERY_STATE,
    MSP_SET_RAW_RC,
    MSP_STATUS_EX,
    BatteryAlert,
    MspClient,
)
from aerobat.plants.fc import Pose, SafetyLimits, SafetyMonitor, SerialTransport, StopReason  # noqa: E402
from aerobat.plants.fc.wall_clock import SafetyStop, WallClockFlight  # noqa: E402

CHANNELS = [1500, 1500, 1000, 1500] + [1000] * 12


def _battery(volts: float, alert: BatteryAlert = BatteryAlert.OK) -> bytes:
    return struct.pack("<BHBHhBH", 4, 1500, round(volts * 10), 100, 800, int(alert), round(volts * 100))


class StillVehicle:
    """A motion-capture source that sees the vehicle standing still, a fresh pose at every call."""

    def __init__(self) -> None:
        self.frame = 0

    def wait(self, timeout_s: float) -> list[Pose]:
        self.frame += 1
        now = time.monotonic()
        return [Pose((0.0, 0.0, 1.0), (1.0, 0.0, 0.0, 0.0), now, now - 0.005, self.frame)]

    def close(self) -> None:
        pass


def _flight(port: SerialTransport, limits: SafetyLimits | None = None, battery_period_s: float = 0.05):
    now = time.monotonic()
    monitor = SafetyMonitor(limits or SafetyLimits(), now)
    return WallClockFlight(MspClient(port, timeout_s=1.0), StillVehicle(), monitor, rate_hz=100.0, time_zero_s=now,
                           start_m=np.zeros(3), floor_z_m=0.0, command_latency_s=0.005,
                           battery_period_s=battery_period_s)


def test_frames_keep_their_deadlines_and_reach_the_board():
    board = FakeBoard({MSP_SET_RAW_RC: b"", MSP_BATTERY_STATE: _battery(16.2)})
    try:
        with SerialTransport(board.device) as port:
            flight = _flight(port)
            started = time.monotonic()
            for _ in range(50):
                flight.frame(CHANNELS)
            elapsed = time.monotonic() - started
            jitter = flight.jitter()
        assert 0.45 < elapsed < 1.5  # 50 frames at 100 Hz (the first is sent at once)
        assert jitter["frames"] == 50 and jitter["lateness_median_ms"] < 5.0
        deadlines, sent = np.array(flight.deadlines).T
        # the schedule does not drift: each deadline is one period after the last, unless that frame went a
        # whole period late (a loaded machine), when the schedule starts again a period after it was sent
        late = sent[:-1] - deadlines[:-1] >= 0.01
        expected = np.where(late, sent[:-1], deadlines[:-1]) + 0.01
        assert np.allclose(deadlines[1:], expected, rtol=0.0, atol=1e-9)
        deadline = time.monotonic() + 2.0  # the board reads on its own thread: the last frame may be in flight
        while sum(1 for c, _ in board.received if c == MSP_SET_RAW_RC) < 50 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert sum(1 for c, _ in board.received if c == MSP_SET_RAW_RC) == 50
        assert flight.battery is not None and flight.battery.voltage_v == pytest.approx(16.2)
    finally:
        board.unplug()


def test_acknowledgements_stay_paired_with_their_frames_when_a_request_reads_some_in_between():
    """A request (status, motors) reads and drops the acknowledgements that arrive before its answer; the
    flight counts them, so later acknowledgements are still paired with their own frames, not older ones."""
    status = struct.pack("<HHHIBH", 125, 0, 0, 0, 0, 0) + bytes((3, 0, 0, 29)) + struct.pack("<I", 0)
    board = FakeBoard({MSP_SET_RAW_RC: b"", MSP_BATTERY_STATE: _battery(16.2), MSP_STATUS_EX: status})
    try:
        with SerialTransport(board.device) as port:
            flight = _flight(port, SafetyLimits(link_timeout_s=2.0), battery_period_s=60.0)
            # each frame's acknowledgement comes just before the status answer, so the status request reads
            # and drops it (left to the scheduler, the frame's own read could take it first on a busy machine)
            board.hold = {MSP_SET_RAW_RC, MSP_BATTERY_STATE}  # the first frame asks for the battery too
            for _ in range(10):
                flight.frame(CHANNELS)
                time.sleep(0.02)
                flight.msp.status_ex()
            assert flight.msp.discarded[MSP_SET_RAW_RC] == 10
            board.hold = set()
            for _ in range(20):
                flight.frame(CHANNELS)
            time.sleep(0.5)  # every acknowledgement has come
            flight.frame(CHANNELS)
        sent = [s for _, s in flight.deadlines]
        assert flight.msp.discarded[MSP_SET_RAW_RC] >= 1
        assert len(flight.acks) + flight.msp.discarded[MSP_SET_RAW_RC] >= len(sent) - 1
        # the last acknowledgement read answers one of the last two frames (unpaired, it would be an older
        # frame's by as many as were dropped)
        assert flight.acks[-1][0] in sent[-2:]
        assert all(ack >= frame for frame, ack in flight.acks)
    finally:
        board.unplug()


@pytest.mark.parametrize("battery", [_battery(13.4), _battery(15.0, BatteryAlert.CRITICAL)], ids=["volts", "alert"])
def test_a_low_battery_reported_over_msp_stops_the_flight(battery):
    board = FakeBoard({MSP_SET_RAW_RC: b"", MSP_BATTERY_STATE: battery})
    try:
        with SerialTransport(board.device) as port:
            flight = _flight(port)
            with pytest.raises(SafetyStop) as stop:
                for _ in range(100):
                    flight.frame(CHANNELS)
        assert stop.value.reason is StopReason.LOW_BATTERY
    finally:
        board.unplug()


def test_a_board_unplugged_mid_flight_is_a_link_loss():
    board = FakeBoard({MSP_SET_RAW_RC: b""})
    with SerialTransport(board.device) as port:
        flight = _flight(port)
        for _ in range(5):
            flight.frame(CHANNELS)
        board.unplug()
        with pytest.raises(SafetyStop) as stop:
            for _ in range(20):
                flight.frame(CHANNELS)
    assert stop.value.reason is StopReason.LINK_LOST


def test_a_board_that_stops_answering_is_a_link_loss_after_the_timeout():
    board = FakeBoard({MSP_SET_RAW_RC: b""})
    try:
        with SerialTransport(board.device) as port:
            flight = _flight(port, SafetyLimits(link_timeout_s=0.1))
            for _ in range(5):
                flight.frame(CHANNELS)
            board.answers.clear()  # alive but silent: a hung flight controller
            silent_at = time.monotonic()
            with pytest.raises(SafetyStop) as stop:
                for _ in range(100):
                    flight.frame(CHANNELS)
        stopped_at = time.monotonic()
        assert stop.value.reason is StopReason.LINK_LOST
        # the timeout counts from the last answer read, which may have come a moment before the board fell silent
        assert stopped_at - flight.msp.answered_at_s >= 0.1 and stopped_at - silent_at < 0.5
    finally:
        board.unplug()
