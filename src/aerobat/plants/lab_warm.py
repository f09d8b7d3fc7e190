"""Compile the lab's shared kernels with the argument types the RotorPy and Betaflight plants pass.

Motion capture (:mod:`.lab_kernels`: a sample, the pose estimate, the supervisor's PD command) and the
onboard feedback (:mod:`aerobat.quadrotor.feedback`), which those plants call one by one from Python.
Both plants' specs declare it (:attr:`aerobat.plants.PlantSpec.kernels`); ``aerobat setup`` runs it once.
"""

from __future__ import annotations

import numpy as np

__all__ = ["warm_lab_kernels"]


def warm_lab_kernels() -> None:
    """Motion capture, the pose estimate, the settle test, the PD command and the onboard feedback, once each."""
    from aerobat.plants.lab_kernels import MOCAP_COLUMNS, estimate_pose, mocap_sample, pd_command, settled
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
    from aerobat.quadrotor.program import Program, Switch
    from aerobat.quadrotor.simulate import simulate
    from aerobat.quadrotor.vehicle import hummingbird

    program = Program(switches=(Switch(time_s=0.0, channel="rate_p", value=1.0),), duration_s=0.05)
    nominal = simulate(program, hummingbird())
    feedback = as_feedback("tracking")
    reference = reference_from_trajectory(nominal.times_s, nominal.states, feedback.gains.reference_rate_hz)
    gains = feedback_vector(feedback)
    x = nominal.states[-1].copy()
    rows = np.zeros((8, MOCAP_COLUMNS))
    noise = np.zeros((8, 6))
    for k in range(rows.shape[0]):
        mocap_sample(x, 0.01 * k, noise[k], rows[k])
    pos, vel, quat = np.zeros(3), np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
    estimate_pose(rows, rows.shape[0], pos, vel, quat)
    settled(pos, vel, quat, np.zeros(3), 0.02, 0.05, 0.03)  # the settle test, as RotorPy and a board's pilot call it
    cmd = np.array([9.81, 0.0, 0.0, 0.0])
    pd_command(pos, vel, quat, np.zeros(3), np.zeros(3), np.array([4.0, 3.0, 10.0, 2.0, 1.0]),
               np.array([0.0, 20.0, 5.0, 10.0, 9.81]), 1.0 / 70.0, cmd)
    onboard, history = onboard_state()
    scratch, relay = np.empty(10), np.empty(6)
    moved = relay_deviation(rows, rows.shape[0], 0.0, np.zeros(3), reference.samples, reference.dt_s, scratch, relay)
    onboard_receive(onboard, history, gains, float(rows[-1, 0]), rows[-1, 4:8].copy(), relay[0:3], relay[3:6], moved)
    apply_feedback(cmd, onboard, gains, reference.samples, 0.0, 0.07, scratch)
    onboard_propagate(onboard, history, 0.07, 0.0, 0.0, 0.0, 1.0 / 800.0)
