"""The serial port of a flight controller: pyserial on a pseudo-terminal, MSP through it, and its failures.

A pseudo-terminal is a real serial device to pyserial and termios; a thread on its other end
answers MSP as Betaflight does (frame layouts of msp.c), so the whole path — open, raw mode,
exclusive lock, framed reads with a deadline — runs here as it would on /dev/ttyACM0.
"""

from __future__ import annotations

import struct
import time

import pytest
from fake_board import FakeBoard

pytest.importorskip("serial", reason="pyserial is not installed (pip install 'aerobat[fc]')")

from aerobat.errors import ConfigError  # noqa: E402
from aerobat.firmware.betaflight.errors import LinkClosed  # noqa: E402
from aerobat.firmware.betaflight.msp import (  # noqa: E402
    MSP_API_VERSION,
    MSP_BATTERY_STATE,
    MSP_SET_RAW_RC,
    BatteryAlert,
    MspClient,
    crc8_dvb_s2,
)
from aerobat.plants.fc import SerialTransport  # noqa: E402


@pytest.fixture
def board():
    battery = struct.pack("<BHBHhBH", 4, 1500, 160, 37, 1250, int(BatteryAlert.OK), 1598)
    fake = FakeBoard({MSP_API_VERSION: bytes((0, 1, 47)), MSP_BATTERY_STATE: battery, MSP_SET_RAW_RC: b""})
    yield fake
    if not fake._stop.is_set():
        fake.unplug()


def test_msp_over_the_serial_port(board):
    with SerialTransport(board.device) as port:
        msp = MspClient(port, timeout_s=2.0)
        version = msp.api_version()
        assert (version.protocol, version.major, version.minor) == (0, 1, 47)
        battery = msp.battery()
        assert (battery.cell_count, battery.capacity_mah, battery.drawn_mah) == (4, 1500, 37)
        assert battery.voltage_v == pytest.approx(15.98) and battery.current_a == pytest.approx(12.5)
        assert battery.cell_voltage_v == pytest.approx(15.98 / 4) and battery.alert is BatteryAlert.OK
        msp.set_raw_rc([1500, 1500, 1000, 1500, 1800, 1000, 1000, 1000])
    assert board.received[-1] == (MSP_SET_RAW_RC, struct.pack("<8H", 1500, 1500, 1000, 1500, 1800, 1000, 1000, 1000))


def test_a_read_returns_what_came_without_waiting_out_its_timeout(board):
    with SerialTransport(board.device) as port:
        started = time.monotonic()
        assert port.read(64, 0.2) == b""  # nothing sent: the timeout, and no longer
        assert 0.15 < time.monotonic() - started < 1.0
        port.write(b"$X<" + struct.pack("<BHH", 0, MSP_API_VERSION, 0) + bytes((crc8_dvb_s2(
            struct.pack("<BHH", 0, MSP_API_VERSION, 0)),)))
        started = time.monotonic()
        data = port.read(4096, 5.0)
        assert data.startswith(b"n") and time.monotonic() - started < 1.0


def test_a_second_program_cannot_open_the_same_port(board):
    with SerialTransport(board.device):
        with pytest.raises(ConfigError, match=rf"^--port {board.device}: cannot open it as a serial port"):
            SerialTransport(board.device)


def test_a_port_that_does_not_exist_or_is_no_serial_device_is_refused_in_one_line(tmp_path):
    with pytest.raises(ConfigError, match=r"^--port /dev/ttyACM97: no such device") as info:
        SerialTransport("/dev/ttyACM97")
    assert "\n" not in str(info.value)
    not_a_tty = tmp_path / "file"
    not_a_tty.write_text("")
    with pytest.raises(ConfigError, match=r"cannot open it as a serial port"):
        SerialTransport(not_a_tty)


def test_an_unplugged_board_raises_link_closed(board):
    with SerialTransport(board.device) as port:
        msp = MspClient(port, timeout_s=1.0)
        assert msp.api_version().minor == 47
        board.unplug()
        with pytest.raises(LinkClosed):
            for _ in range(3):  # the first read after the hang-up sees it
                msp.api_version()
