"""Initial-state compensation for quadrocopters: what the generic rule needs from the vehicle layer.

The learning core (:mod:`aerobat.core.learning`, :mod:`aerobat.core.rules`) knows nothing
about quadrocopters. Initial-state compensation (Sect. 11) needs the model's
sensitivity of the final-state error to the initial state, and a way to turn a
measured start state into a deviation vector; both are built here, from the
nominal model and the state layout of :mod:`aerobat.quadrotor.dynamics`, and handed to
:class:`aerobat.core.rules.InitialStateCompensation` as an
:class:`~aerobat.core.rules.IscModel` (a plain matrix and a plain function).

Deviation vector (12 components, :data:`DEVIATION_NAMES`): position [m],
velocity [m/s], attitude as a small body-frame rotation vector relative to the
nominal initial attitude [rad], body rates [rad/s]. The measured state's motor
thrusts (``THRUST``, not measured: NaN) and ``RATE_INT`` (a revolution counter,
meaningless at the start) are ignored.
"""

from __future__ import annotations

import numpy as np

from aerobat.core.design import FinalStateModel
from aerobat.core.maneuver import Maneuver
from aerobat.core.rules.registry import IscModel
from aerobat.errors import ConfigError
from aerobat.quadrotor.dynamics import (
    OMEGA,
    POS,
    QUAT,
    VEL,
    quaternion_from_rotation_vector,
    quaternion_multiply,
    rotation_vector_from_quaternion,
)

__all__ = [
    "DEVIATION_NAMES",
    "DEVIATION_SCALES",
    "initial_state_sensitivity",
    "quadrotor_isc",
    "start_state_deviation",
]

DEVIATION_NAMES = ("x", "y", "z", "vx", "vy", "vz", "rot_x", "rot_y", "rot_z", "p", "q", "r")
#: finite-difference steps per component (small against the arena's start-state scatter)
DEVIATION_SCALES = np.array([0.01] * 3 + [0.02] * 3 + [0.005] * 3 + [0.02] * 3)


def apply_deviation(nominal: np.ndarray, deviation: np.ndarray) -> np.ndarray:
    """The state ``nominal`` moved by a 12-component deviation (attitude: body-frame rotation)."""
    x = np.array(nominal, dtype=float)
    x[POS] += deviation[0:3]
    x[VEL] += deviation[3:6]
    x[QUAT] = quaternion_multiply(x[QUAT], quaternion_from_rotation_vector(deviation[6:9]))
    x[OMEGA] += deviation[9:12]
    return x


def start_state_deviation(measured: np.ndarray, nominal: np.ndarray) -> np.ndarray:
    """12-component deviation of a measured start state from the nominal initial state.

    NaN entries (unmeasured) become zero deviation; thrust and RATE_INT entries are never used.
    """
    m = np.asarray(measured, dtype=float)
    d = np.zeros(12)
    d[0:3] = m[POS] - nominal[POS]
    d[3:6] = m[VEL] - nominal[VEL]
    q = m[QUAT]
    if np.all(np.isfinite(q)) and np.linalg.norm(q) > 0.5:
        conjugate = nominal[QUAT] * np.array([1.0, -1.0, -1.0, -1.0])
        d[6:9] = rotation_vector_from_quaternion(quaternion_multiply(conjugate, q))
    else:
        d[6:9] = np.nan
    d[9:12] = m[OMEGA] - nominal[OMEGA]
    return np.where(np.isfinite(d), d, 0.0)


def initial_state_sensitivity(
    maneuver: Maneuver,
    model: FinalStateModel,
    p: np.ndarray,
    *,
    initial_state: np.ndarray | None = None,
    steps: np.ndarray | None = None,
) -> np.ndarray:
    """S = ∂e/∂δx₀ (n_err × 12) at parameters ``p`` by central differences of the model.

    ``model`` is any :class:`~aerobat.core.design.FinalStateModel` (e.g.
    ``aerobat.quadrotor.simulate.NominalModel(config)``); the 25 simulations run as one batch.
    """
    x0 = np.array(maneuver.initial_state() if initial_state is None else initial_state, dtype=float)
    h = DEVIATION_SCALES if steps is None else np.asarray(steps, dtype=float)
    n = h.size
    program = maneuver.program(np.asarray(p, dtype=float))
    states = [x0]
    for k in range(n):
        for sign in (1.0, -1.0):
            dev = np.zeros(n)
            dev[k] = sign * h[k]
            states.append(apply_deviation(x0, dev))
    finals = model.final_states([program] * len(states), np.stack(states))
    errors = np.stack([maneuver.error(f) for f in finals])
    return (errors[1::2] - errors[2::2]).T / (2.0 * h)[None, :]


def quadrotor_isc(
    maneuver: Maneuver,
    config,
    p: np.ndarray,
    *,
    source: str = "early",
    components: str = "pos,vel,att,rate",
    window_s: float = 0.1,
) -> IscModel:
    """S and the deviation function for :class:`aerobat.core.rules.InitialStateCompensation`.

    Parameters
    ----------
    maneuver : a maneuver with ``initial_state()`` and ``program(p)`` (e.g. a flip).
    config : the design model's :class:`~aerobat.quadrotor.vehicle.VehicleConfig`.
    p : parameters at which S is evaluated (normally the design's p⁰).
    source : where the start deviation comes from: ``"start_state"`` — the trial's
        measured start state (a few motion-capture samples; velocity and rates by
        differentiation, so noisy); ``"early"`` — fitted from the first ``window_s``
        of the measured maneuver against the model's prediction
        (:func:`early_trajectory_deviation`; much less noisy).
    components : which groups are compensated (``pos``, ``vel``, ``att``, ``rate``):
        a group measured more noisily than the true scatter it would explain is
        better left out. The columns of the other groups are zeroed.

    The deviation function has the signature ``(trial, params) -> (12,)``.
    """
    from aerobat.quadrotor.simulate import NominalModel

    S = initial_state_sensitivity(maneuver, NominalModel(config), p)
    groups = {"pos": slice(0, 3), "vel": slice(3, 6), "att": slice(6, 9), "rate": slice(9, 12)}
    chosen = [c.strip() for c in components.split(",") if c.strip()]
    unknown = sorted(set(chosen) - set(groups))
    if unknown:
        raise ConfigError(f"components {unknown}: allowed {sorted(groups)}")
    mask = np.zeros(12, dtype=bool)
    for c in chosen:
        mask[groups[c]] = True
    S = S * mask[None, :]
    nominal = np.array(maneuver.initial_state(), dtype=float)
    if source == "start_state":
        def deviation(trial, params: np.ndarray) -> np.ndarray:
            return start_state_deviation(trial.start_state, nominal)
    elif source == "early":
        def deviation(trial, params: np.ndarray) -> np.ndarray:
            return early_trajectory_deviation(maneuver, config, trial, params, window_s=window_s)
    else:
        raise ConfigError(f"source = {source!r}: allowed 'start_state' or 'early'")
    return IscModel(sensitivity=S, deviation=deviation)


def early_trajectory_deviation(
    maneuver: Maneuver,
    config,
    trial,
    params: np.ndarray,
    *,
    window_s: float = 0.1,
) -> np.ndarray:
    """12-component start deviation fitted from the first ``window_s`` of the measured maneuver.

    The measured trajectory minus the nominal model's prediction for the same
    program, fitted by a straight line in time: intercept = position and attitude
    deviation at the start, slope = velocity and rate deviation. Averaging many
    motion-capture samples makes this far less noisy than a start state estimated
    from a handful of samples (velocity by differentiation), at the price of also
    picking up disturbances during the window (which the final state feels too).
    Returns NaN if the trial has too few samples.
    """
    from aerobat.quadrotor.simulate import simulate

    times = np.asarray(trial.times_s, dtype=float)
    states = np.asarray(trial.states, dtype=float)
    sel = (times >= -1e-9) & (times <= window_s + 1e-9)
    if sel.sum() < 4:
        return np.full(12, np.nan)
    t, meas = times[sel], states[sel]
    traj = simulate(maneuver.program(np.asarray(params, dtype=float)), config)
    nom_pos = np.stack([np.interp(t, traj.times_s, traj.states[:, k]) for k in range(3)], axis=1)
    idx = np.clip(np.searchsorted(traj.times_s, t), 0, len(traj.times_s) - 1)
    nom_q = traj.states[idx][:, QUAT]
    conj = np.array([1.0, -1.0, -1.0, -1.0])
    rot = np.stack([rotation_vector_from_quaternion(quaternion_multiply(nq * conj, mq))
                    for nq, mq in zip(nom_q, meas[:, QUAT], strict=True)])
    A = np.stack([np.ones_like(t), t], axis=1)
    pos_fit, *_ = np.linalg.lstsq(A, meas[:, POS] - nom_pos, rcond=None)
    rot_fit, *_ = np.linalg.lstsq(A, rot, rcond=None)
    d = np.empty(12)
    d[0:3], d[3:6] = pos_fit[0], pos_fit[1]
    d[6:9], d[9:12] = rot_fit[0], rot_fit[1]
    return d
