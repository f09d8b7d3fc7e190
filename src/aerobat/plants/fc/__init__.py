"""A Betaflight flight controller on a serial port: the parts a real vehicle needs (issue 30, in progress).

The plant itself (``--plant fc``: the Fig. 8 supervisor on the wall clock) is not here yet; these
are the parts it stands on, each usable and tested on its own:

* :mod:`.serial_link` — :class:`SerialTransport`, the flight controller's MSP port with pyserial
  (exclusive, no DTR/RTS edge, stale input dropped, a vanished port raises ``LinkClosed``).
* :mod:`.pty_bridge` — :class:`PtyBridge`, the SITL's TCP UART as a pseudo-terminal, so the
  rehearsal against the firmware runs the serial code path.
* :mod:`.pose_source` — :class:`PoseSource` and :class:`MotionCaptureSource` (libmotioncapture:
  Vicon, OptiTrack, Qualisys, VRPN, ...), every pose stamped on arrival and latency-corrected.
* :mod:`.safety` — :class:`SafetyLimits`, :func:`preflight` and :class:`SafetyMonitor`: kill,
  geofence, motion-capture loss, link loss and low battery, each a :class:`StopReason`.

MSP's battery state and ``MSP_SET_RAW_RC`` are in :mod:`aerobat.plants.betaflight.msp`.
"""

from __future__ import annotations

from .pose_source import MOTION_CAPTURE_SYSTEMS, MotionCaptureSource, Pose, PoseSource
from .pty_bridge import PtyBridge
from .safety import Preflight, SafetyLimits, SafetyMonitor, StopReason, configuration_problems, preflight
from .serial_link import DEFAULT_BAUDRATE_BD, SerialTransport

__all__ = [
    "DEFAULT_BAUDRATE_BD",
    "MOTION_CAPTURE_SYSTEMS",
    "MotionCaptureSource",
    "Pose",
    "PoseSource",
    "Preflight",
    "PtyBridge",
    "SafetyLimits",
    "SafetyMonitor",
    "SerialTransport",
    "StopReason",
    "configuration_problems",
    "preflight",
]
