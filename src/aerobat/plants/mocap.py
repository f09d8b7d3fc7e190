"""Motion capture as a lab has it: samples in, measured states and final-state estimates out.

Shared by every plant that measures with a motion-capture system (the arena,
RotorPy, Betaflight's firmware in the loop). A sample row is ``[t, x, y, z, qw,
qx, qy, qz]`` (world position [m], body→world attitude quaternion); velocities
and rates are never measured, only estimated from positions and attitudes.
"""

from __future__ import annotations

import numpy as np

from aerobat.quadrotor.dynamics import (
    N_STATE,
    QUAT,
    euler_zyx,
    quaternion_from_rotation_vector,
    quaternion_multiply,
    rotation_matrices,
)

__all__ = ["estimate_final_state", "measured_states", "relative_rotation_angles"]


def relative_rotation_angles(quats: np.ndarray) -> np.ndarray:
    """Accumulated body-axis rotation between consecutive attitude samples, (M, 3) [rad]."""
    states = np.zeros((quats.shape[0], N_STATE))
    states[:, QUAT] = quats
    R = rotation_matrices(states)
    dR = np.einsum("kji,kjl->kil", R[:-1], R[1:])  # R_kᵀ R_{k+1}
    cos = np.clip((np.trace(dR, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos)
    axis = np.stack([dR[:, 2, 1] - dR[:, 1, 2], dR[:, 0, 2] - dR[:, 2, 0], dR[:, 1, 0] - dR[:, 0, 1]], axis=1)
    sin = np.sin(angle)
    scale = np.where(sin > 1e-9, angle / (2.0 * np.where(sin > 1e-9, sin, 1.0)), 0.5)
    rotvec = axis * scale[:, None]
    return np.vstack([np.zeros(3), np.cumsum(rotvec, axis=0)])


def measured_states(rows: np.ndarray, t0: float, t1: float, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Motion-capture samples in [t0, t1] as states (velocity by central differences)."""
    sel = rows[(rows[:, 0] >= t0 - 1e-9) & (rows[:, 0] <= t1 + 1e-9)]
    states = np.zeros((sel.shape[0], N_STATE))
    if sel.shape[0] == 0:
        return np.empty(0), states
    states[:, 0:3] = sel[:, 1:4] - start
    states[:, 6:10] = sel[:, 4:8]
    if sel.shape[0] > 2:
        states[:, 3:6] = np.gradient(sel[:, 1:4], sel[:, 0], axis=0)
    states[:, 17:20] = relative_rotation_angles(sel[:, 4:8])
    states[:, 13:17] = np.nan  # motor thrusts are not measured
    states[:, 10:13] = np.nan  # nor body rates
    return sel[:, 0] - t0, states


def estimate_final_state(rows: np.ndarray, t_start: float, t_end: float, start: np.ndarray) -> np.ndarray | None:
    """The state at ``t_end`` from mocap samples only.

    Position and velocity: quadratic least-squares fit over [t_end − 40 ms, t_end + 10 ms].
    Attitude: the sample nearest ``t_end`` rotated by the fitted body rate; whole turns
    counted by accumulating relative rotations from ``t_start``.
    """
    window = rows[(rows[:, 0] >= t_end - 0.040 - 1e-9) & (rows[:, 0] <= t_end + 0.010 + 1e-9)]
    if window.shape[0] < 5:
        return None
    t = window[:, 0] - t_end
    A = np.stack([np.ones_like(t), t, t * t], axis=1)
    coef, *_ = np.linalg.lstsq(A, window[:, 1:4], rcond=None)
    state = np.zeros(N_STATE)
    state[0:3] = coef[0] - start
    state[3:6] = coef[1]
    track = rows[(rows[:, 0] >= t_start - 1e-9) & (rows[:, 0] <= t_end + 0.010 + 1e-9)]
    turns = relative_rotation_angles(track[:, 4:8])
    # attitude at t_end: fit each accumulated body angle linearly over the window and apply the
    # residual rotation to the nearest sample
    k = int(np.argmin(np.abs(track[:, 0] - t_end)))
    in_window = track[:, 0] >= t_end - 0.040 - 1e-9
    tw = track[in_window, 0] - t_end
    Aw = np.stack([np.ones_like(tw), tw], axis=1)
    angle_fit, *_ = np.linalg.lstsq(Aw, turns[in_window], rcond=None)
    rates = angle_fit[1]
    dt = t_end - track[k, 0]
    q = quaternion_multiply(track[k, 4:8], quaternion_from_rotation_vector(rates * dt))
    q = q / np.linalg.norm(q)
    state[6:10] = q
    state[10:13] = rates
    state[13:17] = np.nan
    integral = turns[k] + rates * dt
    state[17:20] = integral
    euler = euler_zyx(state)
    state[17:20] = euler + 2.0 * np.pi * np.round((integral - euler) / (2.0 * np.pi))
    return state


