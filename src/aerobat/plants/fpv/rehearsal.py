"""What a rehearsal's world process and its ground station say to each other, and how the world is paced.

A rehearsal flies the real firmware in real time: the world (the lockstep Betaflight plant's SITL and
physics, :mod:`aerobat.plants.betaflight.paced_world`, a process of its own paced to the wall clock)
and the ground station (:class:`aerobat.plants.fc.world.RealTimeWorld`, the ``fc`` plant's side) meet
only over a pipe, the firmware's UART and UDP motion capture, as a ground station meets a real vehicle.
This module is their shared vocabulary: the pose datagram, the report, and the world's settings.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from aerobat.plants.fpv.params import BetaflightParams

__all__ = ["POSE_DATAGRAM", "READY_TIMEOUT_S", "SET_POINT_JUMP_DEG_S", "WORLD_FIFO_PRIORITY", "WORLD_MODULE",
           "WORLD_NICENESS", "WorldReport", "world_params"]

WORLD_MODULE = "aerobat.plants.betaflight.paced_world"
"""The world's program (``python -m WORLD_MODULE FD``): the ground starts it by name, never imports it."""

READY_TIMEOUT_S = 120.0
"""How long the ground waits for the world's firmware to start (it is built and configured on first use)."""

POSE_DATAGRAM = struct.Struct("<Id3d4d?3d")
"""One motion-capture sample: frame number, measurement time [s since start], position (3) [m],
quaternion (w, x, y, z), then the rehearsal's truth: on the floor, true position (3) [m]."""

WORLD_NICENESS = -10
"""How much ahead of other processes the world and its firmware run, where the user may raise priority."""

WORLD_FIFO_PRIORITY = 10
"""The real-time priority (``SCHED_FIFO``) of the world and its firmware while they fly, where the user may
set it (root): they then never wait for a core behind the machine's other work. Both block between steps
(lockstep) and pace themselves to the wall clock, and the kernel keeps 5 % of every second for the rest
(``sched_rt_runtime_us``)."""

SET_POINT_JUMP_DEG_S = 200.0
"""A rate set point no hover asks for: the world notes when the firmware's rises above it (a maneuver's
first rotation frame has taken effect)."""


@dataclass(frozen=True)
class WorldReport:
    """How well the world kept to the wall clock.

    Attributes
    ----------
    simulated_s : the flight's time when stopped.
    wall_s : wall time from start to stop.
    chunks, late_chunks : chunks flown, and those that ended after their wall-clock deadline.
    max_lag_s : the most the world fell behind the wall clock.
    poses_sent : motion-capture datagrams sent.
    gyro_rate_hz, chunk_s : the firmware's loop rate and the pacing chunk.
    motors : the firmware's last motor commands (0: stopped; ``motor_idle`` and up: armed).
    firmware_pid : the firmware process's id (it ends with the world).
    set_point_jumps_s : world times at which the firmware's rate set point rose above 200 °/s after
        being below it (a maneuver's first frames taking effect), to 1 chunk.
    set_point_jumps_wall_s : the same moments on the wall clock (seconds since
        :meth:`aerobat.plants.fc.world.RealTimeWorld.start`, read when the chunk that saw the jump ended):
        later than the world times by the world's lag.
    peak_motor : the highest motor command of the run (0: the motors never spun, e.g. a dry run).
    error : what ended the world early ("" when it was stopped).
    scheduling : how the world and its firmware were scheduled while flying: ``"fifo"`` (real-time,
        :data:`WORLD_FIFO_PRIORITY`), ``"nice"`` (:data:`WORLD_NICENESS` only) or ``"normal"``.
    """

    simulated_s: float
    wall_s: float
    chunks: int
    late_chunks: int
    max_lag_s: float
    poses_sent: int
    gyro_rate_hz: int
    chunk_s: float
    motors: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    firmware_pid: int | None = None
    set_point_jumps_s: tuple[float, ...] = ()
    set_point_jumps_wall_s: tuple[float, ...] = ()
    peak_motor: float = 0.0
    error: str = ""
    scheduling: str = "normal"

    @property
    def disarmed(self) -> bool:
        """The firmware's motors were stopped when the world stopped (disarmed, or failsafe's DROP)."""
        return max(self.motors) == 0.0


def world_params(params: BetaflightParams | None) -> BetaflightParams:
    """The world's plant settings: ``params`` (default: the plant's) with the exchange's spin off.

    Paced to the wall clock, the world idles most of each chunk; its firmware and driver sleep while
    they wait for each other (``firmware.spin_us = 0``) instead of spinning, which under
    ``SCHED_FIFO`` held both cores from the ground station, whose link to the firmware then went
    silent (``link_lost`` in the rehearsal's drills).
    """
    return (params or BetaflightParams()).replace(firmware__spin_us=0.0)
