"""The rehearsal's world as its ground station sees it: a process to start, stop and ask how it kept time.

A real flight controller runs on its own clock while the ground station talks to it over a serial
port and watches it through motion capture. :class:`RealTimeWorld` gives the ground station exactly
that, with the real firmware: it starts the world (:data:`~aerobat.plants.fpv.rehearsal.WORLD_MODULE`, the
lockstep plant's SITL and physics paced to the wall clock, in a process of its own) and talks to it only
through a pipe, the firmware's UART and UDP motion capture (:mod:`aerobat.plants.fpv.rehearsal`). It sends
no radio frame: the ground's sticks reach the firmware as ``MSP_SET_RAW_RC`` over its UART (the
firmware's default receiver is MSP), through a serial device (:class:`~.pty_bridge.PtyBridge`).

Motion capture leaves the world as UDP datagrams, one per sample of the flight's motion-capture log
(its rate and noise), each sent once its latency has passed on the wall clock, to the ground's
:class:`~.simulated_source.SimulatedSource`. Each carries the true position and floor contact for the
rehearsal's reports (a real system has neither).

When the world falls behind the wall clock it counts the chunk as late and keeps the largest lag,
which :meth:`RealTimeWorld.stop` reports (:class:`~aerobat.plants.fpv.rehearsal.WorldReport`). Where it may
(as root), the world and its firmware run under real-time scheduling (``scripts/results_fc.py lag``
with three busy loops on the 2 cores: chunks late 0.1 % and the largest lag 10–12 ms with
``SCHED_FIFO``; 5–9 % and 17–24 ms with the niceness alone). The world process dies with its owner,
and the firmware with the world. It runs in a session of its own, so the operator's Ctrl-C in the
terminal reaches the ground (which disarms the flight) and not the world, which flies on until the
ground stops it.
"""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from aerobat.plants.fpv.rehearsal import (
    POSE_DATAGRAM,
    READY_TIMEOUT_S,
    SET_POINT_JUMP_DEG_S,
    WORLD_FIFO_PRIORITY,
    WORLD_MODULE,
    WORLD_NICENESS,
    WorldReport,
    world_params,
)

# the shared vocabulary, where the ground station's modules and its users have always found it
__all__ = ["POSE_DATAGRAM", "SET_POINT_JUMP_DEG_S", "WORLD_FIFO_PRIORITY", "WORLD_NICENESS", "RealTimeWorld",
           "WorldReport", "world_params"]


class RealTimeWorld:
    """A Betaflight SITL and the physics of its vehicle, flying on the wall clock in a process of their own.

    Parameters
    ----------
    plant_args : the arguments of :class:`~aerobat.plants.betaflight.plant.BetaflightPlant` that build
        the world (``config``, ``params``, ``seed``, ``binary``, ``eeprom``, ``settings``): the vehicle, its
        disturbances, motion capture (rate, noise, latency) and the firmware's settings.
    pose_port : the UDP port on 127.0.0.1 the motion-capture datagrams go to.
    chunk_s : the pacing chunk: the world checks the wall clock after each (default 1 ms).

    Attributes
    ----------
    uart1_port : the firmware's UART1 (MSP) TCP port.
    gyro_period_us : the firmware's loop period.
    firmware_pid : the firmware process's id.
    started_at_s : ``time.monotonic()`` at the world's time zero (after :meth:`start`).
    """

    def __init__(self, plant_args: dict[str, Any], pose_port: int, *, chunk_s: float = 1e-3) -> None:
        ours, theirs = socket.socketpair()
        # a process of its own (not multiprocessing's spawn, which re-runs the caller's main script)
        self._process = subprocess.Popen([sys.executable, "-m", WORLD_MODULE, str(theirs.fileno())],
                                         pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL,
                                         start_new_session=True)
        theirs.close()
        self._conn = Connection(ours.detach())
        self._conn.send((os.getpid(), plant_args, pose_port, chunk_s))
        self.started_at_s: float | None = None
        self.report: WorldReport | None = None
        message = self._receive(READY_TIMEOUT_S, "start the firmware")
        _, self.uart1_port, self.gyro_period_us, self.firmware_pid = message

    def _receive(self, timeout_s: float, what: str) -> Any:
        if not self._conn.poll(timeout_s):
            self.close()
            raise TimeoutError(f"the rehearsal's world did not {what} within {timeout_s:g} s")
        try:
            return self._conn.recv()
        except EOFError:
            self.close()
            raise RuntimeError(f"the rehearsal's world process ended before it could {what} "
                               f"(exit code {self._process.poll()})") from None

    def start(self) -> float:
        """Start the clock: the firmware's time zero is now; returns ``time.monotonic()`` then."""
        self._conn.send("start")
        _, self.started_at_s = self._receive(10.0, "start its clock")
        return self.started_at_s

    @property
    def alive(self) -> bool:
        """The world process is running."""
        return self._process.poll() is None

    @property
    def pid(self) -> int:
        """The world process's id."""
        return self._process.pid

    def describe(self) -> str:
        """Whether the world and its firmware still run, in words (for a failure that needs explaining)."""
        code = self._process.poll()
        world = "the world runs" if code is None else f"the world exited with {code}"
        try:
            proc_letter = Path(f"/proc/{self.firmware_pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except (OSError, IndexError, TypeError):
            proc_letter = ""
        gone = proc_letter in {"", "Z", "X"}  # zombie or dead: /proc's one-letter process states
        firmware = "is gone" if gone else "runs"
        return f"{world}; its firmware (pid {self.firmware_pid}) {firmware}"

    def stop(self, timeout_s: float = 10.0) -> WorldReport | None:
        """Stop flying and return how the world kept time (None if it was never started or is gone)."""
        if self.report is None and self.started_at_s is not None:
            alive = self.alive
            if alive:
                with contextlib.suppress(OSError):  # it may be ending on its own just now
                    self._conn.send("stop")
            # a world whose firmware died has sent its report already and ended: it waits in the pipe
            with contextlib.suppress(OSError, EOFError):
                if self._conn.poll(timeout_s if alive else 0.5):
                    _, self.report = self._conn.recv()
        self.close()
        return self.report

    def close(self) -> None:
        """End the world process and with it the firmware (idempotent).

        Closing the pipe ends the process cleanly (it closes the firmware and its files); one that
        does not end within 5 s is killed, and the firmware with it (its parent-death signal).
        """
        self._conn.close()
        try:
            self._process.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.wait(timeout=5.0)

    def __enter__(self) -> RealTimeWorld:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()
