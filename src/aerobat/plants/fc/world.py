"""The rehearsal's world: the Betaflight SITL and aerobat's physics in a process of their own, on the wall clock.

A real flight controller runs on its own clock while the ground station talks to it over a serial
port and watches it through motion capture. :class:`RealTimeWorld` gives the ground station exactly
that, with the real firmware: a separate process owns a :class:`~aerobat.plants.betaflight.flight.Flight`
(the lockstep SITL and the physics around it) and advances it in chunks paced to the wall clock, so
the firmware's time is the wall's time since :meth:`RealTimeWorld.start`. It sends no radio frame:
the ground's sticks reach the firmware as ``MSP_SET_RAW_RC`` over its UART (the firmware's default
receiver is MSP), through a serial device (:class:`~.pty_bridge.PtyBridge`).

Motion capture leaves the world as UDP datagrams, one per sample of the flight's motion-capture log
(its rate and noise), each sent once its latency has passed on the wall clock, to the ground's
:class:`~.simulated_source.SimulatedSource`. Each carries the true position and floor contact for the
rehearsal's reports (a real system has neither).

When the world falls behind the wall clock (a loaded machine), it does not skip: it counts the chunk
as late and keeps the largest lag, which :meth:`RealTimeWorld.stop` reports (:class:`WorldReport`).
Where it may (as root), the world raises its priority (:data:`WORLD_NICENESS`) and, while it flies, puts
itself and its firmware under real-time scheduling (:data:`WORLD_FIFO_PRIORITY`), as a real vehicle never
waits for a CPU (``scripts/results_fc.py lag`` with three busy loops on the 2 cores: chunks late 0.1 %
and the largest lag 10–12 ms with ``SCHED_FIFO``; 5–9 % and 17–24 ms with the niceness alone, measured
with :func:`_real_time_scheduling` taken out by hand).
The world process dies with its owner (``PR_SET_PDEATHSIG``), and the firmware with the world. It runs
in a session of its own, so the operator's Ctrl-C in the terminal reaches the ground (which disarms the
flight) and not the world, which flies on until the ground stops it.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import socket
import struct
import subprocess
import sys
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .priority import fifo

if TYPE_CHECKING:
    from aerobat.plants.fpv.params import BetaflightParams

__all__ = ["POSE_DATAGRAM", "SET_POINT_JUMP_DEG_S", "WORLD_FIFO_PRIORITY", "WORLD_NICENESS", "RealTimeWorld",
           "WorldReport", "world_params"]

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
_MAX_EVENTS = 1000
_PR_SET_PDEATHSIG = 1
_READY_TIMEOUT_S = 120.0  # the firmware is built and configured on first use


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
    set_point_jumps_wall_s : the same moments on the wall clock (seconds since :meth:`RealTimeWorld.start`,
        read when the chunk that saw the jump ended): later than the world times by the world's lag.
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


def _die_with(parent_pid: int) -> None:
    try:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent_pid:
        os._exit(1)


def _real_time_scheduling(firmware_pid: int | None) -> str:
    """Put this process and every thread of the firmware under ``SCHED_FIFO`` where allowed; returns how it went."""
    if not fifo(0, WORLD_FIFO_PRIORITY):
        return "nice" if os.getpriority(os.PRIO_PROCESS, 0) < 0 else "normal"
    with contextlib.suppress(OSError, TypeError):  # no firmware process (None): only the world is real-time
        for task in os.listdir(f"/proc/{firmware_pid}/task"):
            fifo(int(task), WORLD_FIFO_PRIORITY)
    return "fifo"


def world_params(params: BetaflightParams | None) -> BetaflightParams:
    """The world's plant settings: ``params`` (default: the plant's) with the exchange's spin off.

    Paced to the wall clock, the world idles most of each chunk; its firmware and driver sleep while
    they wait for each other (``firmware.spin_us = 0``) instead of spinning, which under
    ``SCHED_FIFO`` held both cores from the ground station, whose link to the firmware then went
    silent (``link_lost`` in the rehearsal's drills).
    """
    from aerobat.plants.fpv.params import BetaflightParams

    return (params or BetaflightParams()).replace(firmware__spin_us=0.0)


def _world_main(conn: Any, parent_pid: int, plant_args: dict[str, Any], pose_port: int, chunk_s: float) -> None:
    """The world process: build the flight, report its UART port, fly paced until told to stop."""
    _die_with(parent_pid)
    # the operator's Ctrl-C is the ground's (it disarms the flight); the world, in a session of its own, never
    # sees the terminal's signal, and ignores one sent to it anyway: it ends when its owner says so or dies
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # a real vehicle never waits for a CPU: ahead of the machine's other work where allowed (root),
    # and the firmware, started from here, inherits it; elsewhere the lag is measured and reported
    with contextlib.suppress(PermissionError):
        os.nice(WORLD_NICENESS)
    from aerobat.plants.betaflight.plant import BetaflightPlant

    plant = BetaflightPlant(**{**plant_args, "params": world_params(plant_args.get("params"))})
    flight = plant.open_flight()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        conn.send(("ready", flight.sitl.ports.uart1_port, flight.sitl.gyro_period_us, flight.sitl.pid))
        if not conn.poll(_READY_TIMEOUT_S) or conn.recv() != "start":
            return
        scheduling = _real_time_scheduling(flight.sitl.pid)
        latency_s = plant.params.motion_capture.latency_s
        steps = max(1, round(chunk_s / flight.step_s))
        t0 = time.monotonic()
        conn.send(("started", t0))
        chunks = late = published = 0
        max_lag_s = 0.0
        error = ""
        moved: list[float] = []  # when the firmware's rate set point first jumped, after each quiet spell
        moved_wall: list[float] = []  # the same, on the wall clock
        peak = 0.0  # the highest motor command of the whole run (0: the motors never spun)
        quiet = True
        try:
            while not conn.poll():
                flight.advance(steps)
                chunks += 1
                now_s = time.monotonic() - t0
                # the set point the firmware's rate loop flies (its RC input through the rates): the moment
                # a program's first frame took effect, for the command-to-firmware latency
                peak = max(peak, float(flight.motors[0]), float(flight.motors[1]), float(flight.motors[2]),
                           float(flight.motors[3]))
                jumped = max(abs(float(v)) for v in flight.motors[4:7]) > SET_POINT_JUMP_DEG_S
                if jumped and quiet and len(moved) < _MAX_EVENTS:
                    moved.append(flight.time_s)
                    moved_wall.append(now_s)
                quiet = not jumped
                rows = flight.log[: flight.log_count]
                while published < rows.shape[0] and rows[published, 0] + latency_s <= now_s:
                    r = rows[published]
                    truth = flight.x
                    sock.sendto(POSE_DATAGRAM.pack(published + 1, r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7],
                                                   flight.on_floor, truth[0], truth[1], truth[2]),
                                ("127.0.0.1", pose_port))
                    published += 1
                lag_s = now_s - flight.time_s
                if lag_s > steps * flight.step_s:
                    late += 1
                max_lag_s = max(max_lag_s, lag_s)
                if lag_s < 0:
                    time.sleep(-lag_s)
            conn.recv()
        except EOFError:  # the owner closed the pipe: stop
            error = "the owner closed the world"
        except Exception as failure:  # the firmware died or hung: the ground sees the link go silent
            error = f"{type(failure).__name__}: {str(failure).splitlines()[0] if str(failure) else ''}"
        report = WorldReport(flight.time_s, time.monotonic() - t0, chunks, late, max_lag_s, published,
                             round(1e6 / flight.sitl.gyro_period_us), steps * flight.step_s,
                             flight.motor_commands(), flight.sitl.pid, tuple(moved), tuple(moved_wall), peak, error,
                             scheduling)
        try:
            conn.send(("stopped", report))
        except OSError:  # the owner closed the pipe: nobody to tell
            pass
    finally:
        sock.close()
        flight.close()


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
        self._process = subprocess.Popen([sys.executable, "-m", "aerobat.plants.fc.world", str(theirs.fileno())],
                                         pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL,
                                         start_new_session=True)
        theirs.close()
        self._conn = Connection(ours.detach())
        self._conn.send((os.getpid(), plant_args, pose_port, chunk_s))
        self.started_at_s: float | None = None
        self.report: WorldReport | None = None
        message = self._receive(_READY_TIMEOUT_S, "start the firmware")
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


if __name__ == "__main__":  # the world process: python -m aerobat.plants.fc.world FD
    from aerobat.plants.fc import world as _module  # its classes, not this __main__'s copies, cross the pipe

    _connection = Connection(int(sys.argv[1]))
    _owner, _plant_args, _pose_port, _chunk_s = _connection.recv()
    _module._world_main(_connection, _owner, _plant_args, _pose_port, _chunk_s)
