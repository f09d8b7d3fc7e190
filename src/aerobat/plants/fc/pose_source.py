"""Motion capture of the vehicle: one source interface, libmotioncapture behind it.

A :class:`PoseSource` hands out the tracked body's newest :class:`Pose`, each stamped with the
ground computer's monotonic clock when it arrived and with the measurement time that arrival
implies (arrival less the system's latency). The flight-controller plant reads poses only
through it, so a real system and a simulated one are interchangeable.

:class:`MotionCaptureSource` reaches real systems through the ``motioncapture`` package
(libmotioncapture, the library Crazyswarm uses: ``vicon``, ``optitrack``, ``optitrack_closed_source``,
``qualisys``, ``vrpn``, ``nokov``, ``fzmotion``, ``motionanalysis``, and ``mock`` for a static
body). Its ``waitForNextFrame`` blocks without a timeout, so a daemon thread waits on it and
:meth:`MotionCaptureSource.wait` waits on that thread with one. The Python binding (1.1) gives
no frame timestamp, so the latency is the system's as the user gives it (``latency_s``): Vicon and
OptiTrack report theirs in their own software, typically 3–10 ms.
"""

from __future__ import annotations

import atexit
import collections
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

from aerobat.errors import ConfigError, MissingDependency

__all__ = ["MOTION_CAPTURE_SYSTEMS", "MotionCaptureSource", "Pose", "PoseSource"]

MOTION_CAPTURE_SYSTEMS = ("vicon", "optitrack", "optitrack_closed_source", "qualisys", "vrpn", "nokov",
                          "fzmotion", "motionanalysis", "mock")
"""The ``type`` names libmotioncapture's ``connect`` knows (those compiled into the PyPI wheel may be fewer)."""

_MAX_UNREAD = 10_000  # poses kept for a reader that falls behind (50 s at 200 Hz); older ones are dropped


@dataclass(frozen=True)
class Pose:
    """One pose of the tracked body.

    Attributes
    ----------
    position_m : (x, y, z) in the motion-capture frame.
    quaternion_wxyz : the body's attitude, scalar first.
    received_s : ``time.monotonic()`` when the frame reached the ground computer.
    measured_s : when it was measured: ``received_s`` less the system's latency (a simulated source
        knows it exactly).
    frame : the frame's number since the source opened (1, 2, …; a gap means frames were missed).
    true_position_m, on_floor : the truth, from a simulated source only (None from a real system).
    """

    position_m: tuple[float, float, float]
    quaternion_wxyz: tuple[float, float, float, float]
    received_s: float
    measured_s: float
    frame: int
    true_position_m: tuple[float, float, float] | None = None
    on_floor: bool | None = None


@runtime_checkable
class PoseSource(Protocol):
    """Where the poses of the vehicle come from."""

    def wait(self, timeout_s: float) -> list[Pose]:
        """Every pose that arrived since the last call, oldest first.

        When none is pending, waits at most ``timeout_s`` for the first; ``[]`` if none came (or the
        source is closed).
        """

    def close(self) -> None:
        """Stop listening."""


class MotionCaptureSource:
    """Poses of rigid body ``body`` from a motion-capture system, through libmotioncapture.

    Parameters
    ----------
    system : the system's ``type`` for libmotioncapture (:data:`MOTION_CAPTURE_SYSTEMS`).
    body : the rigid body's name in the system.
    latency_s : the system's latency, from the camera exposure to the frame's arrival.
    options : passed to ``motioncapture.connect`` (``{"hostname": "192.168.1.10"}``; for ``mock``,
        ``{"rigid_bodies": "cf1(x,y,z,qw,qx,qy,qz)"}``).

    Raises
    ------
    ConfigError
        An unknown system, a connection refused, or no frame with ``body`` within ``first_frame_timeout_s``.
    """

    def __init__(self, system: str, body: str, *, latency_s: float = 0.005,
                 options: Mapping[str, str] | None = None, first_frame_timeout_s: float = 5.0) -> None:
        if system not in MOTION_CAPTURE_SYSTEMS:
            raise ConfigError(f"--mocap {system!r}: allowed {', '.join(map(repr, MOTION_CAPTURE_SYSTEMS))}")
        if not 0.0 <= latency_s <= 1.0:
            raise ConfigError(f"latency_s = {latency_s!r} out of range: allowed [0, 1] (s)")
        try:
            import motioncapture
        except ImportError as error:
            raise MissingDependency("motioncapture", extra="fc", purpose="motion capture of a real vehicle",
                                    detail=str(error)) from None
        try:
            self._mocap: Any = motioncapture.connect(system, dict(options or {}))
        except RuntimeError as error:
            raise ConfigError(f"--mocap {system}: cannot connect ({error})") from None
        self.system, self.body, self.latency_s = system, body, latency_s
        self._condition = threading.Condition()
        self._unread: collections.deque[Pose] = collections.deque(maxlen=_MAX_UNREAD)
        self._frames = 0
        self._closed = False
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._listen, name=f"mocap-{system}", daemon=True)
        self._thread.start()
        atexit.register(self.close)  # libmotioncapture aborts the process if it exits inside waitForNextFrame
        if not self.wait(first_frame_timeout_s):
            self.close()
            raise ConfigError(f"--mocap {system}: no frame with rigid body {body!r} within {first_frame_timeout_s:g} s"
                              + (f" ({self._error})" if self._error else ""))

    def _listen(self) -> None:
        try:
            while not self._closed:
                self._mocap.waitForNextFrame()
                received_s = time.monotonic()
                bodies = self._mocap.rigidBodies
                if self.body not in bodies:
                    continue
                rb = bodies[self.body]
                p, q = rb.position, rb.rotation
                with self._condition:
                    self._frames += 1
                    self._unread.append(Pose((float(p[0]), float(p[1]), float(p[2])),
                                             (float(q.w), float(q.x), float(q.y), float(q.z)),
                                             received_s, received_s - self.latency_s, self._frames))
                    self._condition.notify_all()
        except Exception as error:  # the system went away: no more poses, and wait() says so by timing out
            self._error = error

    def wait(self, timeout_s: float) -> list[Pose]:
        """Every pose since the last call, oldest first; waits up to ``timeout_s`` when none is pending."""
        deadline = time.monotonic() + timeout_s
        with self._condition:
            while not self._unread and not self._closed:
                remaining_s = deadline - time.monotonic()
                if remaining_s <= 0:
                    return []
                self._condition.wait(remaining_s)
            if self._closed:
                return []
            poses = list(self._unread)
            self._unread.clear()
            return poses

    @property
    def thread_id(self) -> int | None:
        """The native id of the thread that receives the poses (the ground gives it real-time priority in flight)."""
        return self._thread.native_id

    def close(self, timeout_s: float = 1.0) -> None:
        """Stop handing out poses, and wait up to ``timeout_s`` for the listening thread to end (with the next frame).

        The system's connection is released once the thread has ended; a system that sends no more frames
        keeps the thread waiting inside libmotioncapture until the process exits.
        """
        atexit.unregister(self.close)
        with self._condition:
            self._closed = True
            self._condition.notify_all()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout_s)
        if not self._thread.is_alive():
            self._mocap = None

    def __enter__(self) -> MotionCaptureSource:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
