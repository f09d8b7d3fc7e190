"""A pseudo-terminal wired to a TCP port: the SITL's UART as a serial device.

The Betaflight SITL serves its UARTs over TCP; a real flight controller is a serial device.
:class:`PtyBridge` makes the first look like the second, so the code that will talk to a real
board (:class:`~aerobat.firmware.betaflight.serial_link.SerialTransport`, pyserial, termios) is the code a
rehearsal runs: it opens a pseudo-terminal in raw mode (binary MSP passes unchanged), connects to the TCP port
and copies bytes both ways on a background thread, with every wait bounded.

When the TCP side closes (the firmware exited), the bridge closes the terminal too, so a reader
of the device sees what it would see when a USB board disappears: the port fails
(:class:`~aerobat.firmware.betaflight.errors.LinkClosed` through the transport). :meth:`PtyBridge.close`
does the same on purpose, which is how the tests cut the link.
"""

from __future__ import annotations

import os
import select
import socket
import threading
import time
import tty

from aerobat.firmware.betaflight.errors import LinkTimeout

__all__ = ["PtyBridge"]

_POLL_S = 0.1
_CHUNK_BYTES = 4096


class PtyBridge:
    """A pseudo-terminal (``.device``) whose bytes go to and come from ``host:port`` over TCP.

    Parameters
    ----------
    host, port : the TCP server (the SITL's UART1: 127.0.0.1 and its ``uart1_port``).
    connect_timeout_s : how long to keep retrying a refused connection.

    Attributes
    ----------
    device : the terminal's path (``/dev/pts/N``), to open as a serial port.
    bytes_to_tcp, bytes_from_tcp : bytes copied each way so far.
    """

    def __init__(self, host: str, port: int, connect_timeout_s: float = 5.0) -> None:
        self._sock = self._connect(host, port, connect_timeout_s)
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.device = os.ttyname(self._slave)
        self.bytes_to_tcp = 0
        self.bytes_from_tcp = 0
        self._wake_r, self._wake_w = os.pipe()
        self._closed = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, name=f"pty-bridge-{port}", daemon=True)
        self._thread.start()

    @staticmethod
    def _connect(host: str, port: int, timeout_s: float) -> socket.socket:
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                sock = socket.create_connection((host, port), timeout=max(deadline - time.monotonic(), 0.01))
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                sock.settimeout(2.0)
                return sock
            except (ConnectionRefusedError, TimeoutError) as error:
                if time.monotonic() >= deadline:
                    raise LinkTimeout(f"cannot connect to {host}:{port} within {timeout_s:g} s: {error}") from None
                time.sleep(0.05)

    @property
    def alive(self) -> bool:
        """Both sides are connected and bytes flow."""
        return not self._closed.is_set()

    def _run(self) -> None:
        try:
            while not self._closed.is_set():
                ready, _, _ = select.select([self._master, self._sock.fileno(), self._wake_r], [], [], _POLL_S)
                if self._sock.fileno() in ready:
                    data = self._sock.recv(_CHUNK_BYTES)
                    if not data:
                        break
                    os.write(self._master, data)
                    self.bytes_from_tcp += len(data)
                if self._master in ready:
                    data = os.read(self._master, _CHUNK_BYTES)
                    self._sock.sendall(data)
                    self.bytes_to_tcp += len(data)
                if self._wake_r in ready:
                    break
        except OSError:  # either side failed: the link is gone, as a real port would be
            pass
        finally:
            self._shut()

    def _shut(self) -> None:
        with self._lock:
            if self._closed.is_set():
                return
            self._closed.set()
            for fd in (self._master, self._slave):
                try:
                    os.close(fd)
                except OSError:
                    pass
            self._sock.close()

    @property
    def thread_id(self) -> int | None:
        """The native id of the thread that carries the bytes (the ground gives it real-time priority in flight)."""
        return self._thread.native_id

    def close(self) -> None:
        """Cut the link: the terminal and the TCP connection close, the thread ends (within 2 s)."""
        if not self._closed.is_set():
            try:
                os.write(self._wake_w, b"x")
            except OSError:
                pass
        self._thread.join(timeout=2.0)
        self._shut()
        for fd in (self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass

    def __enter__(self) -> PtyBridge:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
