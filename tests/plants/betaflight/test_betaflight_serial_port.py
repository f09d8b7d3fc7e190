"""The real firmware through a serial device: the SITL's UART1 (TCP) as a pseudo-terminal.

What a flight controller on /dev/ttyACM0 will take, the firmware takes here through the same
code (:class:`~aerobat.firmware.betaflight.serial_link.SerialTransport` on a :class:`~aerobat.plants.fc.PtyBridge`):
MSP status, arming flags, attitude, battery and ``MSP_SET_RAW_RC``; a cut link raises LinkClosed.
"""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("serial", reason="pyserial is not installed (pip install 'aerobat[fc]')")

from aerobat.firmware.betaflight.configure import AtRestStepper  # noqa: E402
from aerobat.firmware.betaflight.errors import LinkClosed  # noqa: E402
from aerobat.firmware.betaflight.msp import BatteryAlert, MspClient  # noqa: E402
from aerobat.firmware.betaflight.sitl import SitlProcess  # noqa: E402
from aerobat.plants.fc import PtyBridge, SerialTransport  # noqa: E402


def test_msp_reaches_the_firmware_through_a_serial_device_and_a_cut_link_is_seen(firmware: tuple[Path, Path]) -> None:
    binary, eeprom = firmware
    with SitlProcess(binary, eeprom) as sitl:
        stepper = AtRestStepper(sitl)  # the firmware answers only while it is stepped
        try:
            with PtyBridge("127.0.0.1", sitl.ports.uart1_port) as bridge, SerialTransport(bridge.device) as port:
                assert bridge.device.startswith("/dev/pts/")
                msp = MspClient(port, timeout_s=20.0)  # a loaded machine steps slowly
                version = msp.api_version()
                assert (version.major, version.minor) == (1, 47)  # Betaflight 4.6
                status = msp.status_ex()
                assert not status.armed and status.pid_cycle_time_us == sitl.gyro_period_us
                attitude = msp.attitude()
                assert abs(attitude.roll_deg) < 1.0 and abs(attitude.pitch_deg) < 1.0  # level at rest
                battery = msp.battery()
                # the SITL has no battery ADC: the firmware reports none, which preflight refuses
                assert battery.alert is BatteryAlert.NOT_PRESENT or battery.cell_count == 0, battery
                msp.set_raw_rc([1500, 1500, 1000, 1500] + [1000] * 4)  # acknowledged (taken only with receiver MSP)
                assert bridge.bytes_to_tcp > 0 and bridge.bytes_from_tcp > 0
                bridge.close()  # the link is cut, as a USB cable pulled
                with pytest.raises(LinkClosed):
                    for _ in range(3):
                        msp.api_version()
        finally:
            stepper.stop()
