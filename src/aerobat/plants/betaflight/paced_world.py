"""The rehearsal's world: the lockstep plant's SITL and physics in a process of their own, on the wall clock.

``python -m aerobat.plants.betaflight.paced_world FD`` is started by the ``fc`` plant's ground station
(:class:`aerobat.plants.fc.world.RealTimeWorld`), which talks to it only through the pipe ``FD``, the
firmware's UART and the motion-capture datagrams (:mod:`aerobat.plants.fpv.rehearsal`): the ground never
imports this module, as a ground station never runs a vehicle's code. Here a
:class:`~aerobat.plants.betaflight.flight.Flight` (the lockstep SITL and the physics around it) advances in
chunks paced to the wall clock, so the firmware's time is the wall's time since the ground said "start".

When the world falls behind the wall clock (a loaded machine), it does not skip: it counts the chunk
as late and keeps the largest lag, which the report gives (:class:`~aerobat.plants.fpv.rehearsal.WorldReport`).
Where it may (as root), the world raises its priority and, while it flies, puts itself and its firmware
under real-time scheduling, as a real vehicle never waits for a CPU. The world process dies with its
owner (``PR_SET_PDEATHSIG``), and the firmware with the world; it ignores the terminal's Ctrl-C, which is
the ground's (it disarms the flight).
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import socket
import sys
import time
from multiprocessing.connection import Connection
from typing import Any

from aerobat.plants.fpv.priority import fifo
from aerobat.plants.fpv.rehearsal import (
    POSE_DATAGRAM,
    READY_TIMEOUT_S,
    SET_POINT_JUMP_DEG_S,
    WORLD_FIFO_PRIORITY,
    WORLD_NICENESS,
    WorldReport,
    world_params,
)

__all__ = ["world_main"]

_MAX_EVENTS = 1000
_PR_SET_PDEATHSIG = 1


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


def world_main(conn: Any, parent_pid: int, plant_args: dict[str, Any], pose_port: int, chunk_s: float) -> None:
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
        if not conn.poll(READY_TIMEOUT_S) or conn.recv() != "start":
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


if __name__ == "__main__":  # python -m aerobat.plants.betaflight.paced_world FD
    from aerobat.plants.betaflight import paced_world as _module  # its classes, not this __main__'s, cross the pipe

    _connection = Connection(int(sys.argv[1]))
    _owner, _plant_args, _pose_port, _chunk_s = _connection.recv()
    _module.world_main(_connection, _owner, _plant_args, _pose_port, _chunk_s)
