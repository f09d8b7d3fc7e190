"""Compile the Betaflight plant's kernels ahead of its first trial, with the argument types it passes.

:func:`warm_world` compiles the world's step, the lockstep loops (UDP and, where the exchange's C helper
can be built, shared memory), the frame loop and the pilot's sticks: no firmware is needed to compile
them. :func:`warm_design_model` compiles the firmware design model (both fidelities). The plant's spec
declares both (:attr:`aerobat.plants.PlantSpec.kernels`); ``aerobat setup`` runs them.
"""

from __future__ import annotations

import numpy as np

__all__ = ["warm_design_model", "warm_world"]


def warm_world() -> None:
    """The Betaflight world's step, its lockstep and frame loops, and the pilot's sticks
    (:func:`~aerobat.plants.fpv.warm.warm_sticks`)."""
    from aerobat.firmware.betaflight.errors import FirmwareUnavailable
    from aerobat.firmware.betaflight.packets import MOTOR_STRUCT
    from aerobat.plants.betaflight.physics import (
        C_CONTACT,
        C_DELAY,
        N_COUNTERS,
        PACKET_DOUBLES,
        SCRATCH_ROWS,
        airframe_plant,
        aux_vector,
        ground_state,
        prime,
        step,
    )
    from aerobat.plants.fpv import frames as fr
    from aerobat.plants.fpv.params import BetaflightParams
    from aerobat.plants.fpv.pilot import N_LIMITS
    from aerobat.plants.fpv.warm import warm_sticks
    from aerobat.plants.lab_kernels import MOCAP_COLUMNS
    from aerobat.quadrotor.dynamics import N_STATE

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
    scratch = np.zeros((SCRATCH_ROWS, N_STATE))  # the physics' rows, the held sample, the rotors' angles
    prime(world, plant, aux, counters, noise[0], packet, scratch)
    step(world, np.zeros(4, dtype=np.float32), plant, aux, np.zeros((2, 4)), counters, noise[1], packet, scratch)
    block = np.zeros(MOTOR_STRUCT.size, dtype=np.uint8)
    # the compiled lockstep loop, where the shared-memory exchange's C helper can be compiled (no compiler: skipped)
    try:
        from aerobat.plants.betaflight.lockstep import run_steps
    except FirmwareUnavailable:
        pass
    else:
        # a run of no steps (nothing is sent), then the frame loop around it (a run of no frames), with the
        # argument types Flight passes
        run_steps(np.zeros(fr.N_CFG, dtype=np.int64), 0, 0, 0, 0, step_s, world, block, block[:16].view(np.float32),
                  plant, aux, np.zeros((2, 4)), counters, noise, np.zeros((2, 6)), np.zeros((2, MOCAP_COLUMNS)),
                  np.zeros(fr.N_ST, dtype=np.int64), packet, scratch, np.random.default_rng(0), np.zeros(fr.N_FCFG))
        from aerobat.plants.betaflight.frame_loop import fly_frames

        rc_block = np.zeros(40, dtype=np.uint8)
        fly_frames(0, 0, 32, 0, 0, False, 0, np.random.default_rng(0), np.zeros(fr.N_CFG, dtype=np.int64),
                   np.zeros(fr.N_FCFG), np.zeros(fr.N_ST, dtype=np.int64), np.zeros(fr.N_FST), world, block,
                   block.view(np.float32), plant, aux, np.zeros((2, 4)), counters, packet, scratch, np.zeros((2, 6)),
                   np.zeros((2, 6)), np.zeros((2, MOCAP_COLUMNS)), np.zeros(4, dtype=np.int64),
                   np.zeros((4, 16), dtype=np.int64), rc_block, rc_block.view(np.uint16),
                   np.zeros((1, 16), dtype=np.int64), np.zeros(fr.N_PILOT), np.zeros(3), np.zeros(3), np.zeros(4),
                   np.zeros(N_LIMITS), np.zeros(3), np.zeros((3, 2)), np.empty((0, 1 + N_STATE)), np.zeros(22),
                   np.zeros((1, 4)), np.zeros(1), np.zeros((1, 3)), np.zeros(12), np.zeros(10), np.zeros(6))
    warm_sticks()


def warm_design_model() -> None:
    """The firmware design model of the Betaflight plants (:mod:`aerobat.quadrotor.firmware`), both fidelities."""
    from aerobat.plants.fpv.design_model import firmware_design_model
    from aerobat.plants.fpv.params import BetaflightParams
    from aerobat.quadrotor.firmware.sticks import frames_of
    from aerobat.quadrotor.program import Program, Switch
    from aerobat.quadrotor.vehicle import vehicle_from_name_or_file

    program = Program(switches=(Switch(time_s=0.0, channel="rate_p", value=1.0),), duration_s=0.05)
    frames_of(program.compile(), 0.004, 16)  # the plant's frames of a program
    fpv5 = vehicle_from_name_or_file("fpv5")
    for fidelity in ("design", "exact"):
        model = firmware_design_model(fpv5, BetaflightParams(), fidelity=fidelity)
        model.final_states([program])
        model.trajectory(program)
