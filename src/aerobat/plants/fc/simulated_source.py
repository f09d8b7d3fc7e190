"""Motion capture from the rehearsal's world: its samples over UDP, as a real system's frames arrive.

:class:`SimulatedSource` binds a UDP port on 127.0.0.1 and hands out the datagrams
:class:`~.world.RealTimeWorld` sends (:data:`~.world.POSE_DATAGRAM`) as :class:`~.pose_source.Pose`
values: stamped with the ground's monotonic clock on arrival, with the measurement time the
world knows exactly (its time zero plus the sample's time), and with the truth a real system
cannot give (true position, floor contact) for the rehearsal's reports.
"""

from __future__ import annotations

import select
import socket
import time

from .pose_source import Pose
from .world import POSE_DATAGRAM

__all__ = ["SimulatedSource"]


class SimulatedSource:
    """The poses the rehearsal's world sends to ``port`` (:attr:`port`: a free one, bound on 127.0.0.1).

    Call :meth:`set_time_zero` with the world's :attr:`~.world.RealTimeWorld.started_at_s` before reading.
    """

    def __init__(self) -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(("127.0.0.1", 0))
        self._sock.setblocking(False)
        self.port: int = self._sock.getsockname()[1]
        self._t0_s = 0.0
        self._closed = False
        self._blind_until_s = -1.0
        self.received = 0
        self.dropped = 0

    def set_time_zero(self, started_at_s: float) -> None:
        """The world's time zero on this machine's monotonic clock (its samples' times count from it)."""
        self._t0_s = started_at_s

    def blind(self, seconds: float) -> None:
        """Drop every pose for the next ``seconds``: a motion-capture dropout (for tests and drills)."""
        self._blind_until_s = time.monotonic() + seconds

    def _drain(self) -> list[Pose]:
        poses: list[Pose] = []
        while True:
            try:
                data = self._sock.recv(POSE_DATAGRAM.size + 1)
            except BlockingIOError:
                return poses
            if len(data) != POSE_DATAGRAM.size:
                continue  # not a pose datagram: never taken
            received_s = time.monotonic()
            if received_s < self._blind_until_s:
                self.dropped += 1
                continue
            frame, t, x, y, z, qw, qx, qy, qz, on_floor, tx, ty, tz = POSE_DATAGRAM.unpack(data)
            poses.append(Pose((x, y, z), (qw, qx, qy, qz), received_s, self._t0_s + t, frame, (tx, ty, tz),
                              bool(on_floor)))
            self.received += 1

    def wait(self, timeout_s: float) -> list[Pose]:
        """Every pose since the last call, oldest first; waits up to ``timeout_s`` when none is pending."""
        if self._closed:
            return []
        poses = self._drain()
        if poses or timeout_s <= 0:
            return poses
        ready, _, _ = select.select([self._sock], [], [], timeout_s)
        return self._drain() if ready else []

    def close(self) -> None:
        """Release the port."""
        self._closed = True
        self._sock.close()

    def __enter__(self) -> SimulatedSource:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
