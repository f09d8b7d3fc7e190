"""A flight controller's far end on a pseudo-terminal: answers MSP v2 requests as Betaflight frames them (msp.c)."""

from __future__ import annotations

import os
import select
import struct
import threading
import tty

from aerobat.firmware.betaflight.msp import crc8_dvb_s2


def _response(command: int, payload: bytes) -> bytes:
    body = struct.pack("<BHH", 0, command, len(payload)) + payload
    return b"$X>" + body + bytes((crc8_dvb_s2(body),))


class FakeBoard:
    """The far end of a pseudo-terminal answering MSP v2 requests; records what it was sent."""

    def __init__(self, answers: dict[int, bytes]) -> None:
        """``answers``: the payload answered to each command (others get no answer); may be changed live."""
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.device = os.ttyname(slave)
        self._slave = slave
        self.answers = answers
        self.hold: set[int] = set()
        """Commands whose answers wait until another command is answered (may be changed live): a test
        decides which side reads an acknowledgement, whatever the scheduler does."""
        self._held = bytearray()
        self.received: list[tuple[int, bytes]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        buffer = bytearray()
        while not self._stop.is_set():
            ready, _, _ = select.select([self.master], [], [], 0.05)
            if not ready:
                continue
            try:
                buffer += os.read(self.master, 4096)
            except OSError:
                return
            while (start := buffer.find(b"$X<")) >= 0 and len(buffer) - start >= 9:
                _flag, command, size = struct.unpack_from("<BHH", buffer, start + 3)
                end = start + 8 + size + 1
                if len(buffer) < end:
                    break
                payload = bytes(buffer[start + 8:end - 1])
                assert buffer[end - 1] == crc8_dvb_s2(bytes(buffer[start + 3:end - 1]))
                del buffer[:end]
                self.received.append((command, payload))
                if command in self.answers:
                    answer = b"noise" + _response(command, self.answers[command])
                    if command in self.hold:
                        self._held += answer
                    else:
                        os.write(self.master, bytes(self._held) + answer)
                        self._held.clear()

    def unplug(self) -> None:
        """Close the board's side, as a USB board that reboots does."""
        self._stop.set()
        self._thread.join(2.0)
        os.close(self.master)
        os.close(self._slave)
