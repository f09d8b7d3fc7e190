"""A serial port as a :class:`~aerobat.firmware.betaflight.transport.Transport`: the flight controller's MSP port.

:class:`SerialTransport` opens a port with pyserial the way a flight controller needs it:

* exclusively (a second program on the same port would interleave its bytes with ours);
* without toggling DTR or RTS (on some boards a DTR edge resets the MCU): both lines are set
  low *before* the port opens, so opening leaves them as they were;
* raw 8N1 at ``baudrate_bd`` (over USB VCP the rate is ignored; on a hardware UART it must be
  the port's MSP rate, the ``serial`` CLI command);
* stale input dropped after opening (a board may still be answering a previous owner).

``read(max_bytes, timeout_s)`` waits at most ``timeout_s`` for the first byte and then returns
whatever else has arrived, so an MSP reply is not held back for the full timeout. A port that
disappears (a USB board that reboots re-enumerates, possibly under another name) raises
:class:`~aerobat.firmware.betaflight.errors.LinkClosed`; the owner re-opens it.
"""

from __future__ import annotations

from pathlib import Path

from aerobat.errors import ConfigError, MissingDependency
from aerobat.firmware.betaflight.errors import LinkClosed, LinkTimeout

__all__ = ["DEFAULT_BAUDRATE_BD", "SerialTransport"]

DEFAULT_BAUDRATE_BD = 115_200
"""Betaflight's default MSP baud rate on a hardware UART (ignored over USB VCP)."""

_WRITE_TIMEOUT_S = 2.0


def _serial_module():  # type: ignore[no-untyped-def]
    try:
        import serial
    except ImportError as error:
        raise MissingDependency("serial", extra="fc", purpose="a flight controller on a serial port",
                                detail=str(error)) from None
    return serial


class SerialTransport:
    """The byte stream of a serial port (a USB VCP ``/dev/ttyACM0``, a UART, or a pseudo-terminal).

    Parameters
    ----------
    port : the device path (``/dev/ttyACM0``).
    baudrate_bd : the line rate in baud (ignored by USB VCP).

    Raises
    ------
    ConfigError
        The port does not exist, is not a serial device, or another program holds it (one line naming the port).
    """

    def __init__(self, port: str | Path, baudrate_bd: int = DEFAULT_BAUDRATE_BD) -> None:
        serial = _serial_module()
        self.port = str(port)
        if not Path(self.port).exists():
            raise ConfigError(f"--port {self.port}: no such device (is the flight controller plugged in? "
                              f"ls /dev/ttyACM* /dev/ttyUSB*)")
        handle = serial.Serial()
        handle.port = self.port
        handle.baudrate = baudrate_bd
        handle.bytesize, handle.parity, handle.stopbits = serial.EIGHTBITS, serial.PARITY_NONE, serial.STOPBITS_ONE
        handle.xonxoff = handle.rtscts = handle.dsrdtr = False
        handle.dtr = False  # applied as the port opens: no DTR edge, no reset
        handle.rts = False
        handle.exclusive = True
        handle.write_timeout = _WRITE_TIMEOUT_S
        try:
            handle.open()
        except (serial.SerialException, OSError, ValueError) as error:
            raise ConfigError(f"--port {self.port}: cannot open it as a serial port ({error})") from None
        handle.reset_input_buffer()
        self._serial = handle
        self._exceptions = (serial.SerialException, OSError)
        self._write_timeout = serial.SerialTimeoutException

    def write(self, data: bytes) -> None:
        """Send all of ``data`` (2 s timeout)."""
        try:
            self._serial.write(data)
            self._serial.flush()
        except self._write_timeout as error:
            raise LinkTimeout(f"writing to {self.port} timed out") from error
        except self._exceptions as error:
            raise LinkClosed(f"{self.port} is gone: {error}") from error

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        """Up to ``max_bytes`` that arrive within ``timeout_s`` (``b""`` when none do)."""
        try:
            self._serial.timeout = max(timeout_s, 0.0)
            first = self._serial.read(1)
            if not first:
                return b""
            waiting = min(self._serial.in_waiting, max_bytes - 1)
            return first + (self._serial.read(waiting) if waiting > 0 else b"")
        except self._exceptions as error:
            raise LinkClosed(f"{self.port} is gone: {error}") from error

    def close(self) -> None:
        """Close the port (the lines stay as they were)."""
        self._serial.close()

    def __enter__(self) -> SerialTransport:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
