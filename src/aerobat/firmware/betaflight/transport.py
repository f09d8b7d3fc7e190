"""Byte transports to a flight controller's MSP/CLI port.

:class:`Transport` is what the MSP and CLI clients need: write bytes, read
whatever arrived within a timeout, close. :class:`TcpTransport` reaches the
SITL's UART1, which Betaflight serves over TCP (5761 by default, per instance
in the lockstep build).

The serial transport of a real flight controller is
:class:`aerobat.firmware.betaflight.serial_link.SerialTransport` (pyserial): exclusive, no DTR/RTS edge
(some boards reset on one), stale input dropped after opening, ``read`` returning what arrived
within its timeout, and :class:`LinkClosed` when the port disappears (``save``, ``exit`` and
``reboot`` reset the MCU, and the USB device re-enumerates, possibly under another name: the
owner re-opens it). Long CLI pastes may need small chunks on a hardware UART without flow control.
"""

from __future__ import annotations

import socket
import time
from typing import Protocol, runtime_checkable

from .errors import LinkClosed, LinkTimeout

__all__ = ["TcpTransport", "Transport"]


@runtime_checkable
class Transport(Protocol):
    """A bidirectional byte stream with timeouts."""

    def write(self, data: bytes) -> None:
        """Send all of ``data``."""

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        """Return up to ``max_bytes`` that arrive within ``timeout_s``; ``b""`` on timeout.

        Raises :class:`LinkClosed` when the other end has closed the stream.
        """

    def close(self) -> None:
        """Release the transport; further calls fail."""


class TcpTransport:
    """A TCP connection, e.g. to the SITL's UART1.

    Parameters
    ----------
    host : str
        Address to connect to (the SITL listens on 127.0.0.1).
    port : int
        TCP port.
    connect_timeout_s : float
        How long to keep retrying a refused connection (the SITL opens its
        ports a little after it starts).
    """

    def __init__(self, host: str, port: int, connect_timeout_s: float = 5.0) -> None:
        deadline = time.monotonic() + connect_timeout_s
        last_error: OSError | None = None
        while True:
            remaining_s = deadline - time.monotonic()
            if remaining_s <= 0:
                raise LinkTimeout(f"cannot connect to {host}:{port} within {connect_timeout_s} s: {last_error}")
            try:
                self._sock = socket.create_connection((host, port), timeout=remaining_s)
                break
            except (ConnectionRefusedError, TimeoutError) as error:
                last_error = error
                time.sleep(0.05)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.address = (host, port)

    def write(self, data: bytes) -> None:
        """Send all of ``data`` (2 s timeout)."""
        self._sock.settimeout(2.0)
        try:
            self._sock.sendall(data)
        except TimeoutError as error:
            raise LinkTimeout(f"sending to {self.address} timed out") from error
        except (BrokenPipeError, ConnectionResetError) as error:
            raise LinkClosed(f"{self.address} closed the connection") from error

    def read(self, max_bytes: int, timeout_s: float) -> bytes:
        """Return up to ``max_bytes`` received within ``timeout_s`` (``b""`` on timeout)."""
        self._sock.settimeout(max(timeout_s, 1e-6))
        try:
            data = self._sock.recv(max_bytes)
        except TimeoutError:
            return b""
        except ConnectionResetError as error:
            raise LinkClosed(f"{self.address} reset the connection") from error
        if not data:
            raise LinkClosed(f"{self.address} closed the connection")
        return data

    def close(self) -> None:
        """Close the socket."""
        self._sock.close()

    def __enter__(self) -> TcpTransport:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
