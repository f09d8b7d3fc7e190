"""The lockstep exchange and the physics in one compiled loop: the steps of a frame in one call.

:func:`run_steps` does, step after step, what a Python loop would — sample motion capture, send the
state packet, receive the firmware's motor packet, advance the physics one gyro period
(:func:`.physics.step`) — for a run of steps in which no RC frame is due. The packets travel over
the flight's exchange (``cfg[K_EXCHANGE]``, :class:`~aerobat.plants.fpv.params.Firmware`'s
``exchange``), called directly from the compiled code:

* shared memory (:mod:`aerobat.firmware.betaflight.shm`): the region's C functions
  (``shm_exchange.c``) publish the state packet and spin, then futex-wait, for the answer with a
  timeout (``wait_ns``). The frame's noise is drawn as the steps need it and, the rest, while the
  firmware computes its answer (:mod:`.frame_noise`), so the firmware does not wait for the
  draws. A motion-capture sample needs the frame's last draws: its state is held in
  ``scratch[HELD_ROW]`` and sampled once they are taken (before this returns, whatever it
  returns), the same sample the step would have taken at once.
* UDP: the C library's ``send`` and ``recv`` on the sockets of a
  :class:`~aerobat.firmware.betaflight.sitl.SitlProcess`. ``recv`` returns after the motor
  socket's kernel receive timeout (``SO_RCVTIMEO``, 50 ms) at the latest. The frame's noise is
  drawn before the first step (there is no wait to hide it in).

With an output delay of a step or more the physics runs between the send and the receive, while
the firmware works (:func:`.physics.advance`). It returns whenever the exchange does not complete
at once:

* an answer that does not come within the timeout stops it with :data:`NO_ANSWER`; the caller
  finishes that step's exchange with the process's watchdog
  (:meth:`aerobat.firmware.betaflight.sitl.SitlProcess.receive_into`), which raises when the
  firmware is gone or silent for the step timeout, and calls again with ``resume =
  io[IO_RESUME]``. No read waits without a timeout.
* A state packet that cannot be sent stops it with :data:`SEND_FAILED` (the caller retries in
  Python, which raises the right error); a non-finite state with :data:`NON_FINITE`.

The firmware→driver packet is received whole into one byte block of
:data:`~aerobat.firmware.betaflight.packets.MOTOR_STRUCT`'s size (its layout is defined there only); the motor commands
are its first four floats. The steps are the same arithmetic, and the noise the same draws, over
either exchange, so a seed repeats a flight bit for bit whichever exchange flies it. Importing this
module builds (once) and loads the shared-memory library, whose symbols the compiled code calls
by name.
"""

from __future__ import annotations

import numba as nb
from numba.core import types

from aerobat.firmware.betaflight.shm import library
from aerobat.plants.betaflight.frame_noise import ALL, draw_noise, sensor_draws_through
from aerobat.plants.betaflight.physics import C_DELAY, advance, step, store_motors
from aerobat.plants.fpv.frames import (
    HELD_ROW,
    K_EVERY,
    K_EXCHANGE,
    K_MOTOR_FD,
    K_SHM,
    K_SPIN_NS,
    K_STATE_FD,
    K_WAIT_NS,
    S_DRAW_TOTAL,
    S_DRAWN,
    S_HELD,
    X_SHM,
)
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
# the C library's calls and the shared-memory region's, resolved by name when the compiled code is loaded (so it
# caches); the region's symbols must be loaded before the compiled code links
library()
_send = types.ExternalFunction("send", types.intp(types.int32, types.uintp, types.uintp, types.int32))
_recv = types.ExternalFunction("recv", types.intp(types.int32, types.uintp, types.uintp, types.int32))
_publish_state = types.ExternalFunction("aerobat_shm_publish_state", types.int64(types.uintp, types.uintp, types.int64))
_wait_motor = types.ExternalFunction(
    "aerobat_shm_wait_motor", types.int64(types.uintp, types.uintp, types.int64, types.int64, types.int64))
_poll_motor = types.ExternalFunction("aerobat_shm_poll_motor", types.int64(types.uintp, types.uintp, types.int64))


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _send_state(cfg, packet):  # pragma: no cover - compiled
    """Send the state packet over the flight's exchange; whether it went."""
    if cfg[K_EXCHANGE] == X_SHM:
        return _publish_state(cfg[K_SHM], packet.ctypes.data, packet.nbytes) >= 0
    return _send(cfg[K_STATE_FD], packet.ctypes.data, packet.nbytes, 0) == packet.nbytes


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _receive_motors(cfg, block):  # pragma: no cover - compiled
    """Wait (with the exchange's timeout) for the firmware's answer into ``block``; whether it came whole."""
    size = block.shape[0]
    if cfg[K_EXCHANGE] == X_SHM:
        return _wait_motor(cfg[K_SHM], block.ctypes.data, size, cfg[K_SPIN_NS], cfg[K_WAIT_NS]) == size
    return _recv(cfg[K_MOTOR_FD], block.ctypes.data, size, _MSG_TRUNC) == size


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def _take_held_sample(step_s, rng, cfg, fcfg, io, noise, mocap_noise, log, scratch):  # pragma: no cover - compiled
    """The held motion-capture sample, if one is held, once the frame's draws up to its noise are taken (all)."""
    if io[S_HELD] == 0:
        return
    draw_noise(ALL, rng, cfg, fcfg, io, noise, mocap_noise)
    row = io[IO_LOG]
    mocap_sample(scratch[HELD_ROW], (io[S_HELD] - 1) * step_s, mocap_noise[io[IO_MOCAP_USED]], log[row])
    io[IO_LOG] = row + 1
    io[IO_MOCAP_USED] += 1
    io[S_HELD] = 0


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def run_steps(cfg, first, stop, resume, tick0, step_s, x, block, motors, plant, aux, pending, counters, noise,
              mocap_noise, log, io, packet, scratch, rng, fcfg):  # pragma: no cover - compiled
    """Steps ``first`` … ``stop - 1`` of a run starting at tick ``tick0``; returns (status, the step it stopped at).

    ``cfg``, ``fcfg``: the flight's constants (:mod:`aerobat.plants.fpv.frames`: the exchange, its
    sockets or region, the motion-capture period in steps); ``io`` is the frame loop's ``st``; the
    frame's noise comes from ``rng`` (:mod:`.frame_noise`). ``resume`` (0, :data:`RESUME_STEP`,
    :data:`RESUME_STORE`): how much of step ``first`` is done; its motor packet is then in
    ``block``. ``block`` (uint8, the firmware→driver packet's size) receives each packet;
    ``motors`` is the float32 view of its first 16 bytes. With an output delay of a step or more,
    each step's physics runs while the firmware computes its answer (:func:`.physics.advance`), and
    the answer is stored when it comes.
    """
    size = block.shape[0]
    ahead = counters[C_DELAY] >= 1
    shm = cfg[K_EXCHANGE] == X_SHM
    if not shm:
        draw_noise(ALL, rng, cfg, fcfg, io, noise, mocap_noise)
    every = cfg[K_EVERY]
    for i in range(first, stop):
        tick = tick0 + i
        if resume != 0 and i == first:
            if resume == RESUME_STORE:
                store_motors(motors, pending, tick)
                continue
        else:
            sent = _send_state(cfg, packet)
            if tick % every == 0:
                _take_held_sample(step_s, rng, cfg, fcfg, io, noise, mocap_noise, log, scratch)
                scratch[HELD_ROW, :] = x
                io[S_HELD] = tick + 1
                if io[S_DRAWN] >= io[S_DRAW_TOTAL]:
                    _take_held_sample(step_s, rng, cfg, fcfg, io, noise, mocap_noise, log, scratch)
            if not sent:
                _take_held_sample(step_s, rng, cfg, fcfg, io, noise, mocap_noise, log, scratch)
                return SEND_FAILED, i
            draw_noise(sensor_draws_through(i), rng, cfg, fcfg, io, noise, mocap_noise)
            if ahead and advance(x, plant, aux, pending, counters, noise[i], packet, scratch):
                _take_held_sample(step_s, rng, cfg, fcfg, io, noise, mocap_noise, log, scratch)
                return NON_FINITE, i
            answered = False
            while shm and io[S_DRAWN] < io[S_DRAW_TOTAL]:  # the frame's other draws while the firmware works
                if _poll_motor(cfg[K_SHM], block.ctypes.data, size) == size:
                    answered = True
                    break
                draw_noise(io[S_DRAWN] + 6, rng, cfg, fcfg, io, noise, mocap_noise)
            if io[S_HELD] != 0 and io[S_DRAWN] >= io[S_DRAW_TOTAL]:
                _take_held_sample(step_s, rng, cfg, fcfg, io, noise, mocap_noise, log, scratch)
            if not answered and not _receive_motors(cfg, block):
                _take_held_sample(step_s, rng, cfg, fcfg, io, noise, mocap_noise, log, scratch)
                io[IO_RESUME] = RESUME_STORE if ahead else RESUME_STEP
                return NO_ANSWER, i
            io[IO_EXCHANGES] += 1
            if ahead:
                store_motors(motors, pending, tick)
                continue
        draw_noise(sensor_draws_through(i), rng, cfg, fcfg, io, noise, mocap_noise)
        if step(x, motors, plant, aux, pending, counters, noise[i], packet, scratch):
            _take_held_sample(step_s, rng, cfg, fcfg, io, noise, mocap_noise, log, scratch)
            return NON_FINITE, i
    _take_held_sample(step_s, rng, cfg, fcfg, io, noise, mocap_noise, log, scratch)
    return DONE, stop
