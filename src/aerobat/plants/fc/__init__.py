"""``--plant fc``: a Betaflight flight controller over MSP on the wall clock (docs/real-vehicle.md).

The modules, from the plant down:

* :mod:`.plant` — :class:`~.plant.FlightControllerPlant`, the Betaflight plant's Fig. 8 supervisor
  flying a :class:`~.wall_clock.WallClockFlight`, over a :class:`~.plant.BoardConnection` (a board
  and the room's motion capture) or a :class:`~.plant.RehearsalConnection` (the real firmware in real
  time); :func:`~.plant.build_fc_plant` from a ``--fc`` file (:mod:`.settings`).
* :mod:`.wall_clock` — RC frames as MSP at their deadlines, poses as they arrive, the safety
  monitor at every frame; frame timing and acknowledgements kept for the trial's report.
* :mod:`.world`, :mod:`.simulated_source` — the rehearsal: the SITL and the physics in a process
  of their own paced to the wall clock, and its motion capture over UDP.
* :mod:`.pty_bridge` — :class:`PtyBridge`, the SITL's TCP UART as a pseudo-terminal, so the
  rehearsal runs the serial code path.
* :mod:`.pose_source` — :class:`PoseSource` and :class:`MotionCaptureSource` (libmotioncapture:
  Vicon, OptiTrack, Qualisys, VRPN, ...), every pose stamped on arrival and latency-corrected.
* :mod:`.safety` — :class:`SafetyLimits`, :func:`preflight`, :func:`configuration_problems` and
  :class:`SafetyMonitor`: kill, geofence, motion-capture loss, link loss and low battery, each a
  :class:`StopReason`.

The firmware's side (MSP with its battery state, feature and mode-range queries and ``MSP_SET_RAW_RC``,
the serial port as a transport, RC channels, settings, tunes) is the library :mod:`aerobat.firmware.betaflight`
(:class:`SerialTransport` is re-exported here). This package imports no plant at import time (the world
process starts from :mod:`.world`); ``from aerobat.plants.fc.plant import FlightControllerPlant``.
"""

from __future__ import annotations

from aerobat.firmware.betaflight.serial_link import DEFAULT_BAUDRATE_BD, SerialTransport

from .pose_source import MOTION_CAPTURE_SYSTEMS, MotionCaptureSource, Pose, PoseSource
from .pty_bridge import PtyBridge
from .safety import Preflight, SafetyLimits, SafetyMonitor, StopReason, configuration_problems, preflight
from .spec import SPEC

__all__ = [
    "SPEC",
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
