"""The compiled lockstep loop over the shared-memory exchange (:mod:`aerobat.firmware.betaflight.shm`) instead of UDP.

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

from aerobat.firmware.betaflight.shm import library
from aerobat.plants.betaflight.frame_noise import ALL, draw_noise, sensor_draws_through
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
from aerobat.plants.fpv.frames import HELD_ROW, S_DRAW_TOTAL, S_DRAWN, S_HELD
from aerobat.plants.lab_kernels import mocap_sample

__all__ = ["run_steps_shm"]

library()  # the symbols below must be loaded before the compiled code links
_publish_state = types.ExternalFunction("aerobat_shm_publish_state", types.int64(types.uintp, types.uintp, types.int64))
_wait_motor = types.ExternalFunction(
    "aerobat_shm_wait_motor", types.int64(types.uintp, types.uintp, types.int64, types.int64, types.int64))
_poll_motor = types.ExternalFunction("aerobat_shm_poll_motor", types.int64(types.uintp, types.uintp, types.int64))


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
def run_steps_shm(shm, spin_ns, wait_ns, first, stop, resume, tick0, every, step_s, x, block, motors,
                  plant, aux, pending, counters, noise, mocap_noise, log, io, packet,
                  scratch, rng, cfg, fcfg):  # pragma: no cover - compiled
    """:func:`.lockstep.run_steps` over the region at ``shm`` (spin at most ``spin_ns``, wait up to ``wait_ns``).

    ``io`` is the frame loop's ``st``. The frame's noise is drawn from ``rng`` as the steps need
    it (:mod:`.frame_noise`: a step's sensor row before its physics) and, the rest, a row at a
    time while the firmware computes its answer, so the firmware does not wait for the frame's
    draws. A motion-capture sample needs the frame's last draws: its state is held in
    ``scratch[HELD_ROW]`` and sampled once they are taken (before this returns, whatever it
    returns), the same sample the step would have taken at once.
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
            published = _publish_state(shm, packet.ctypes.data, packet.nbytes) >= 0
            if tick % every == 0:
                _take_held_sample(step_s, rng, cfg, fcfg, io, noise, mocap_noise, log, scratch)
                scratch[HELD_ROW, :] = x
                io[S_HELD] = tick + 1
                if io[S_DRAWN] >= io[S_DRAW_TOTAL]:
                    _take_held_sample(step_s, rng, cfg, fcfg, io, noise, mocap_noise, log, scratch)
            if not published:
                _take_held_sample(step_s, rng, cfg, fcfg, io, noise, mocap_noise, log, scratch)
                return SEND_FAILED, i
            draw_noise(sensor_draws_through(i), rng, cfg, fcfg, io, noise, mocap_noise)
            if ahead and advance(x, plant, aux, pending, counters, noise[i], packet, scratch):
                _take_held_sample(step_s, rng, cfg, fcfg, io, noise, mocap_noise, log, scratch)
                return NON_FINITE, i
            answered = False
            while io[S_DRAWN] < io[S_DRAW_TOTAL]:  # the frame's other draws while the firmware works
                if _poll_motor(shm, block.ctypes.data, size) == size:
                    answered = True
                    break
                draw_noise(io[S_DRAWN] + 6, rng, cfg, fcfg, io, noise, mocap_noise)
            if io[S_HELD] != 0 and io[S_DRAWN] >= io[S_DRAW_TOTAL]:
                _take_held_sample(step_s, rng, cfg, fcfg, io, noise, mocap_noise, log, scratch)
            if not answered and _wait_motor(shm, block.ctypes.data, size, spin_ns, wait_ns) != size:
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
