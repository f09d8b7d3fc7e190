"""The lockstep exchange and the physics in one compiled loop: the steps of a frame in one call.

:func:`run_steps` does, step after step, what a Python loop would — sample motion capture, send the
state packet, receive the firmware's motor packet, advance the physics one gyro period
(:func:`.physics.step`) — for a run of steps in which no RC frame is due, calling the C library's
``send`` and ``recv`` directly on the UDP sockets of a
:class:`~aerobat.firmware.betaflight.sitl.SitlProcess`. With an output delay of a step or more the
physics runs between the send and the receive, while the firmware works (:func:`.physics.advance`).
The frame loop (:mod:`.frame_loop`) calls it between RC frames; it returns whenever the exchange
does not complete at once:

* ``recv`` returns after the motor socket's kernel receive timeout (``SO_RCVTIMEO``, 50 ms) at
  the latest: the loop stops with :data:`NO_ANSWER` and the caller finishes that step's
  exchange with the process's watchdog (:meth:`aerobat.firmware.betaflight.sitl.SitlProcess.receive_into`), which raises
  when the firmware is gone or silent for the step timeout, and calls again with ``resume =
  io[IO_RESUME]``. No read waits without a timeout.
* A failed ``send`` stops it with :data:`SEND_FAILED` (the caller retries in Python, which
  raises the right error); a non-finite state with :data:`NON_FINITE`.

The firmware→driver packet is received whole into one byte block of
:data:`~aerobat.firmware.betaflight.packets.MOTOR_STRUCT`'s size (its layout is defined there only); the motor commands
are its first four floats. The steps are the same arithmetic as the Python loop, so a seed
repeats a flight bit for bit whichever path flies it.
"""

from __future__ import annotations

import numba as nb
from numba.core import types

from aerobat.plants.betaflight.physics import C_DELAY, advance, step, store_motors
from aerobat.plants.lab_kernels import mocap_sample

__all__ = ["DONE", "IO_EXCHANGES", "IO_LOG", "IO_MOCAP_USED", "IO_RESUME", "N_IO", "NON_FINITE", "NO_ANSWER",
           "RESUME_STEP", "RESUME_STORE", "SEND_FAILED", "run_steps"]

DONE = 0
"""All steps of the run were taken."""
NO_ANSWER = 1
"""The state packet of the step went out, its answer did not come within the socket timeout."""
SEND_FAILED = 2
"""The state packet of the step could not be sent (the step has not begun)."""
NON_FINITE = 3
"""The physics step went non-finite (the step was taken)."""

# io: integers shared with the caller
IO_LOG = 0  # rows in the motion-capture log
IO_MOCAP_USED = 1  # rows of mocap noise consumed
IO_EXCHANGES = 2  # motor packets received by the loop (added up)
IO_RESUME = 3  # after NO_ANSWER: how to resume the step once the watchdog has its packet (RESUME_*)
N_IO = 4

RESUME_STEP = 1
"""Resume a step whose exchange is done: store its motor packet and run its physics."""
RESUME_STORE = 2
"""Resume a step whose exchange and physics are done (run ahead): store its motor packet."""

_MSG_TRUNC = 0x20  # recv returns the datagram's real length: a packet of another size is never taken
# the C library's calls, resolved by name when the compiled code is loaded (so it caches)
_send = types.ExternalFunction("send", types.intp(types.int32, types.uintp, types.uintp, types.int32))
_recv = types.ExternalFunction("recv", types.intp(types.int32, types.uintp, types.uintp, types.int32))


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def run_steps(state_fd, motor_fd, first, stop, resume, tick0, every, step_s, x, block, motors, plant, aux, pending,
              counters, noise, mocap_noise, log, io, packet, scratch):  # pragma: no cover - compiled
    """Steps ``first`` … ``stop - 1`` of a run starting at tick ``tick0``; returns (status, the step it stopped at).

    ``resume`` (0, :data:`RESUME_STEP`, :data:`RESUME_STORE`): how much of step ``first`` is done;
    its motor packet is then in ``block``. ``block`` (uint8, the firmware→driver packet's size)
    receives each packet; ``motors`` is the float32 view of its first 16 bytes. With an output
    delay of a step or more, each step's physics runs while the firmware computes its answer
    (:func:`.physics.advance`), and the answer is stored when it comes.
    """
    size = block.shape[0]
    ahead = counters[C_DELAY] >= 1
    for i in range(first, stop):
        tick = tick0 + i
        if resume != 0 and i == first:
            if resume == RESUME_STORE:
                store_motors(motors, pending, tick)
                continue
        else:
            if tick % every == 0:
                row = io[IO_LOG]
                mocap_sample(x, tick * step_s, mocap_noise[io[IO_MOCAP_USED]], log[row])
                io[IO_LOG] = row + 1
                io[IO_MOCAP_USED] += 1
            if _send(state_fd, packet.ctypes.data, packet.nbytes, 0) != packet.nbytes:
                return SEND_FAILED, i
            if ahead and advance(x, plant, aux, pending, counters, noise[i], packet, scratch):
                return NON_FINITE, i
            if _recv(motor_fd, block.ctypes.data, size, _MSG_TRUNC) != size:
                io[IO_RESUME] = RESUME_STORE if ahead else RESUME_STEP
                return NO_ANSWER, i
            io[IO_EXCHANGES] += 1
            if ahead:
                store_motors(motors, pending, tick)
                continue
        if step(x, motors, plant, aux, pending, counters, noise[i], packet, scratch):
            return NON_FINITE, i
    return DONE, stop
