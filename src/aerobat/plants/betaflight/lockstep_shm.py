"""The compiled lockstep loop over the shared-memory exchange (:mod:`.shm`) instead of UDP.

:func:`run_steps_shm` is :func:`.lockstep.run_steps` with each step's exchange through the
region's C functions (``shm_exchange.c``: publish the state packet, spin then futex-wait for the
answer with a timeout) instead of ``send``/``recv``. Importing this module builds (once) and
loads that library, whose symbols the compiled code calls by name. Statuses, ``io`` and the
arithmetic are those of :mod:`.lockstep`, so a seed repeats a flight bit for bit over either
exchange; a wait that times out (:data:`~.lockstep.NO_ANSWER`, after ``wait_ns``) hands the step
to the process's watchdog, and a state packet that cannot be published
(:data:`~.lockstep.SEND_FAILED`) to its Python exchange.
"""

from __future__ import annotations

import numba as nb
from numba.core import types

from aerobat.plants.betaflight.lockstep import (
    DONE,
    IO_EXCHANGES,
    IO_LOG,
    IO_MOCAP_USED,
    IO_RESUME,
    NO_ANSWER,
    NON_FINITE,
    RESUME_STEP,
    RESUME_STORE,
    SEND_FAILED,
)
from aerobat.plants.betaflight.physics import C_DELAY, advance, step, store_motors
from aerobat.plants.betaflight.shm import library
from aerobat.plants.lab_kernels import mocap_sample

__all__ = ["run_steps_shm"]

library()  # the symbols below must be loaded before the compiled code links
_publish_state = types.ExternalFunction("aerobat_shm_publish_state", types.int64(types.uintp, types.uintp, types.int64))
_wait_motor = types.ExternalFunction(
    "aerobat_shm_wait_motor", types.int64(types.uintp, types.uintp, types.int64, types.int64, types.int64))


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def run_steps_shm(shm, spin_ns, wait_ns, first, stop, resume, tick0, every, step_s, x, block, motors,
                  plant, aux, pending, counters, noise, mocap_noise, log, io, packet,
                  scratch):  # pragma: no cover - compiled
    """:func:`.lockstep.run_steps` over the region at ``shm`` (spin at most ``spin_ns``, wait up to ``wait_ns``)."""
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
            if _publish_state(shm, packet.ctypes.data, packet.nbytes) < 0:
                return SEND_FAILED, i
            if ahead and advance(x, plant, aux, pending, counters, noise[i], packet, scratch):
                return NON_FINITE, i
            if _wait_motor(shm, block.ctypes.data, size, spin_ns, wait_ns) != size:
                io[IO_RESUME] = RESUME_STORE if ahead else RESUME_STEP
                return NO_ANSWER, i
            io[IO_EXCHANGES] += 1
            if ahead:
                store_motors(motors, pending, tick)
                continue
        if step(x, motors, plant, aux, pending, counters, noise[i], packet, scratch):
            return NON_FINITE, i
    return DONE, stop
