"""Compile aerobat's kernels ahead of the first command: ``python -m aerobat.experiments.warmup``.

aerobat's simulation kernels are compiled by numba on first use and cached on disk
(in ``__pycache__`` next to the sources, or under ``NUMBA_CACHE_DIR`` when it is set).
Compiling them all takes one to two minutes of CPU (the arena's supervisor, with the onboard
feedback inlined, about half of it; two processes side by side take about a minute), which the
first ``aerobat learn`` would otherwise spend silently before its first trial. ``make setup``
runs this module once, so every later command loads the compiled code from the cache.

It runs each compiled entry point once, on tiny inputs, through the public functions
the commands use, so it compiles exactly the variants (argument types) they need:
continuous playback (with and without rate-loop latency) and sampled playback, the parallel
batch, a complete arena trial with the onboard feedback (the arena's default, tracking) and
one in the open loop, and the kernels the RotorPy and Betaflight plants call one by one from
Python (the onboard feedback, the supervisor's estimate and PD controller, motion capture,
the Betaflight world and pilot), with the argument types those plants pass, and the Betaflight
blackbox decoder (:mod:`aerobat.logs.blackbox_decode`).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import numpy as np

__all__ = ["warm_up"]


_HEARTBEAT_S = 15.0


def warm_up(workers: int = 2, progress: Callable[[str], None] | None = None,
            parts: tuple[str, ...] | None = None) -> float:
    """Compile (or load from numba's cache) every kernel a command uses; returns the seconds it took.

    The kernels fall into four groups (:data:`PARTS`), compiled in ``workers`` processes
    side by side (numba writes each cache file atomically, so a kernel two need is safe). ``parts``
    compiles only those groups (``make demo``: playback and arena; default: all). ``progress`` gets a
    line as each group is ready and, while any is still compiling, one every 15 s naming them.
    """
    say = progress or (lambda line: None)
    chosen = PARTS if parts is None else tuple(p for p in PARTS if p in parts)
    unknown = sorted(set(parts or ()) - set(PARTS))
    if unknown:
        raise ValueError(f"unknown kernel group(s) {', '.join(unknown)}; allowed: {', '.join(PARTS)}")
    start = time.perf_counter()
    if workers > 1:
        from concurrent.futures import FIRST_COMPLETED, wait

        from aerobat.experiments.lifetime import process_pool

        with process_pool(min(workers, len(chosen))) as pool:  # its workers die with this process
            pending = {pool.submit(_warm_part, part): part for part in chosen}
            while pending:
                done, _ = wait(pending, timeout=_HEARTBEAT_S, return_when=FIRST_COMPLETED)
                for future in done:
                    future.result()  # a failed compile raises here
                    say(f"  {pending.pop(future)} kernels ready ({time.perf_counter() - start:.0f} s)")
                if not done:
                    say(f"  still compiling: {', '.join(sorted(pending.values()))} "
                        f"({time.perf_counter() - start:.0f} s)")
    else:
        for part in chosen:
            _warm_part(part)
            say(f"  {part} kernels ready ({time.perf_counter() - start:.0f} s)")
    return time.perf_counter() - start


PARTS = ("playback", "arena", "plants", "firmware")
"""The kernel groups: playback (simulate, the batch, the nominal model), the arena's trial, the kernels the
RotorPy and Betaflight plants call from Python with the blackbox decoder, and the firmware design model."""


def _warm_part(part: str) -> None:
    from aerobat.quadrotor.program import Program, Switch
    from aerobat.quadrotor.simulate import NominalModel, simulate, simulate_batch
    from aerobat.quadrotor.vehicle import ModelEffects, hummingbird

    config = hummingbird()
    program = Program(switches=(Switch(time_s=0.0, channel="rate_p", value=1.0),), duration_s=0.05)
    if part == "firmware":  # the Betaflight plants' design model (quadrotor.firmware), both fidelities
        from aerobat.plants.betaflight.design_model import firmware_design_model
        from aerobat.plants.betaflight.params import BetaflightParams
        from aerobat.quadrotor.firmware.sticks import frames_of
        from aerobat.quadrotor.vehicle import vehicle_from_name_or_file

        frames_of(program.compile(), 0.004, 16)  # the plant's frames of a program
        fpv5 = vehicle_from_name_or_file("fpv5")
        for fidelity in ("design", "exact"):
            model = firmware_design_model(fpv5, BetaflightParams(), fidelity=fidelity)
            model.final_states([program])
            model.trajectory(program)
        return
    if part == "arena":
        from aerobat.plants.arena import Arena

        Arena(config, seed=0, feedback="tracking").fly(program)
        Arena(config, seed=0, feedback="none").fly(program)
        return
    if part == "plants":  # what RotorPy and Betaflight call from Python, and the blackbox decoder
        from aerobat.logs.blackbox_decode import warm_up as blackbox_decoder

        _plant_kernels(simulate(program, config))
        blackbox_decoder()  # `log info` and `identify --log` on a Betaflight log
        return
    # an identified vehicle's rate-loop latency runs its own continuous kernel
    lagging = dataclasses.replace(config, effects=ModelEffects(rate_latency_s=(0.005, 0.005, 0.005)))
    simulate(program, config, mode="sampled")
    simulate(program, lagging)
    simulate_batch([program, program], config)
    NominalModel(config).final_states([program])


def _plant_kernels(nominal: object) -> None:
    """The kernels RotorPy and Betaflight call from Python, once each with the types they pass."""
    from aerobat.plants.lab_kernels import MOCAP_COLUMNS, estimate_pose, mocap_sample, pd_command
    from aerobat.quadrotor.feedback import (
        apply_feedback,
        as_feedback,
        feedback_vector,
        onboard_propagate,
        onboard_receive,
        onboard_state,
        reference_from_trajectory,
        relay_deviation,
    )

    feedback = as_feedback("tracking")
    reference = reference_from_trajectory(nominal.times_s, nominal.states,  # type: ignore[attr-defined]
                                          feedback.gains.reference_rate_hz)
    gains = feedback_vector(feedback)
    x = nominal.states[-1].copy()  # type: ignore[attr-defined]
    rows = np.zeros((8, MOCAP_COLUMNS))
    noise = np.zeros((8, 6))
    for k in range(rows.shape[0]):
        mocap_sample(x, 0.01 * k, noise[k], rows[k])
    pos, vel, quat = np.zeros(3), np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
    estimate_pose(rows, rows.shape[0], pos, vel, quat)
    cmd = np.array([9.81, 0.0, 0.0, 0.0])
    pd_command(pos, vel, quat, np.zeros(3), np.zeros(3), np.array([4.0, 3.0, 10.0, 2.0, 1.0]),
               np.array([0.0, 20.0, 5.0, 10.0, 9.81]), 1.0 / 70.0, cmd)
    onboard, history = onboard_state()
    scratch, relay = np.empty(10), np.empty(6)
    moved = relay_deviation(rows, rows.shape[0], 0.0, np.zeros(3), reference.samples, reference.dt_s, scratch, relay)
    onboard_receive(onboard, history, gains, float(rows[-1, 0]), rows[-1, 4:8].copy(), relay[0:3], relay[3:6], moved)
    apply_feedback(cmd, onboard, gains, reference.samples, 0.0, 0.07, scratch)
    onboard_propagate(onboard, history, 0.07, 0.0, 0.0, 0.0, 1.0 / 800.0)
    _betaflight_kernels(x, cmd)


def _betaflight_kernels(x: np.ndarray, cmd: np.ndarray) -> None:
    """The Betaflight world's step and the pilot's sticks (no firmware needed to compile them)."""
    from aerobat.plants.betaflight.params import BetaflightParams
    from aerobat.plants.betaflight.physics import (
        C_CONTACT,
        C_DELAY,
        N_COUNTERS,
        PACKET_DOUBLES,
        airframe_plant,
        aux_vector,
        ground_state,
        prime,
        step,
    )
    from aerobat.plants.betaflight.pilot import N_LIMITS, angle_sticks, program_sticks

    params = BetaflightParams()
    step_s = 1.0 / params.firmware.gyro_rate_hz
    world = ground_state((0.0, 0.0, -2.5))
    plant = airframe_plant(params)
    aux = aux_vector(params, step_s=step_s, ground_z_m=-2.5, gravity_m_s2=9.81)
    counters = np.zeros(N_COUNTERS, dtype=np.int64)
    counters[C_DELAY] = 1
    counters[C_CONTACT] = 1
    noise = np.zeros((2, 6))
    packet = np.zeros(PACKET_DOUBLES)
    from aerobat.plants.betaflight.frames import HELD_ROW

    scratch = np.zeros((HELD_ROW + 1, x.shape[0]))  # the physics' six rows and the shared-memory loop's held sample
    prime(world, plant, aux, counters, noise[0], packet, scratch)
    step(world, np.zeros(4, dtype=np.float32), plant, aux, np.zeros((2, 4)), counters, noise[1], packet, scratch)
    # the compiled lockstep loop (a run of no steps: nothing is sent)
    from aerobat.firmware.betaflight.packets import MOTOR_STRUCT
    from aerobat.plants.betaflight.lockstep import N_IO, run_steps
    from aerobat.plants.lab_kernels import MOCAP_COLUMNS

    block = np.zeros(MOTOR_STRUCT.size, dtype=np.uint8)
    run_steps(-1, -1, 0, 0, 0, 0, 8, step_s, world, block, block[:16].view(np.float32), plant, aux,
              np.zeros((2, 4)), counters, noise, np.zeros((2, 6)), np.zeros((2, MOCAP_COLUMNS)),
              np.zeros(N_IO, dtype=np.int64), packet, scratch)
    # and its shared-memory twin, where the exchange's C helper can be compiled (no compiler: skipped)
    from aerobat.firmware.betaflight.errors import FirmwareUnavailable

    try:
        from aerobat.plants.betaflight.lockstep_shm import run_steps_shm
    except FirmwareUnavailable:
        pass
    else:
        # the frame loop around both (a run of no frames), with the argument types Flight passes
        from aerobat.plants.betaflight import frames as fr

        run_steps_shm(0, 0, 0, 0, 0, 0, 0, 8, step_s, world, block, block[:16].view(np.float32), plant, aux,
                      np.zeros((2, 4)), counters, noise, np.zeros((2, 6)), np.zeros((2, MOCAP_COLUMNS)),
                      np.zeros(fr.N_ST, dtype=np.int64), packet, scratch, np.random.default_rng(0),
                      np.zeros(fr.N_CFG, dtype=np.int64), np.zeros(fr.N_FCFG))
        from aerobat.plants.betaflight.frame_loop import fly_frames

        rc_block = np.zeros(40, dtype=np.uint8)
        fly_frames(0, 0, 32, 0, 0, False, 0, np.random.default_rng(0), np.zeros(fr.N_CFG, dtype=np.int64),
                   np.zeros(fr.N_FCFG), np.zeros(fr.N_ST, dtype=np.int64), np.zeros(fr.N_FST), world, block,
                   block.view(np.float32), plant, aux, np.zeros((2, 4)), counters, packet, scratch, np.zeros((2, 6)),
                   np.zeros((2, 6)), np.zeros((2, MOCAP_COLUMNS)), np.zeros(4, dtype=np.int64),
                   np.zeros((4, 16), dtype=np.int64), rc_block, rc_block.view(np.uint16),
                   np.zeros((1, 16), dtype=np.int64), np.zeros(fr.N_PILOT), np.zeros(3), np.zeros(3), np.zeros(4),
                   np.zeros(N_LIMITS), np.zeros(3), np.zeros((3, 2)), np.empty((0, 1 + x.shape[0])), np.zeros(22),
                   np.zeros((1, 4)), np.zeros(1), np.zeros((1, 3)), np.zeros(12), np.zeros(10), np.zeros(6))
    limits = np.zeros(N_LIMITS)
    limits[:] = 1.0
    sticks = np.zeros(4)
    program_sticks(cmd, limits, sticks)
    angle_sticks(np.zeros(3), np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), np.zeros(3),
                 np.ones(4), limits, 1.0 / 50.0, sticks)


def main() -> None:
    seconds = warm_up(progress=lambda line: print(line, flush=True))
    print(f"aerobat: compiled kernels ready ({seconds:.1f} s)", flush=True)


if __name__ == "__main__":
    main()
