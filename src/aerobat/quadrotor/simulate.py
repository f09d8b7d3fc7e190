"""Simulation: play a program on a vehicle and return its trajectory.

Two playback modes of the same compiled program:

* ``"continuous"`` — the paper's continuous-time model (Sect. 6): the rate
  controller acts continuously and the program is evaluated exactly at every
  RK4 stage. Integration steps land exactly on every breakpoint (switch times,
  ramp starts). This is the design model.
* ``"sampled"`` — what an onboard command generator does: every ``tick_s``
  (1/800 s by default) the program is sampled, the controller computes motor
  commands from the gyro, and both are held (zero-order hold) until the next tick.

A vehicle's :class:`~aerobat.quadrotor.vehicle.ModelEffects` are part of the model:
damping, drag and thrust-proportional moments through the plant vector, and the
rate-loop latency as a delay of the rate the controller acts on (the body rate
``L`` seconds ago, interpolated linearly in a history of the integration steps;
the rate at the start before that). With zero latency the kernels run exactly the
arithmetic they always did.

The kernels are compiled with numba and allocate nothing inside their loops;
:func:`simulate_batch` runs many (program, vehicle) pairs in parallel threads.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numba as nb
import numpy as np

from aerobat.config import as_float_array, check_int, check_real, check_type
from aerobat.errors import ConfigError
from aerobat.quadrotor.dynamics import (
    N_PLANT,
    N_STATE,
    POS,
    VEL,
    controller_thrusts,
    controller_vector,
    euler_zyx,
    hover_state,
    model_plant_vector,
    normalize_quaternion,
    plant_derivative,
    rotation_angles,
)
from aerobat.quadrotor.program import CompiledProgram, Program
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["NominalModel", "Trajectory", "final_state_summary", "simulate", "simulate_batch"]

Mode = Literal["continuous", "sampled"]
DEFAULT_MAX_STEP_S = 5e-4
DEFAULT_TICK_S = 1.0 / 800.0


# --------------------------------------------------------------------- kernels


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _command(coeffs, k, tau, cmd):  # pragma: no cover - compiled
    for ch in range(4):
        cmd[ch] = coeffs[k, ch, 0] + tau * (coeffs[k, ch, 1] + tau * coeffs[k, ch, 2])


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _closed_loop_derivative(t, x, cmd, plant, ctrl, ft, dx):  # pragma: no cover - compiled
    controller_thrusts(cmd, x[10], x[11], x[12], ctrl, ft)
    plant_derivative(t, x, ft, plant, dx)


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _delayed_rates(hist_t, hist_w, count, t, x, delay, out):  # pragma: no cover - compiled
    """Body rates ``delay`` seconds before ``t`` (per axis): from the history, or between its end and ``x`` at ``t``."""
    for a in range(3):
        lag = delay[a]
        now = x[10 + a]
        if lag <= 0.0 or count == 0:
            out[a] = now
            continue
        s = t - lag
        last = hist_t[count - 1]
        if s >= last:
            span = t - last
            out[a] = now if span <= 0.0 else hist_w[count - 1, a] + (s - last) / span * (now - hist_w[count - 1, a])
        elif s <= hist_t[0]:
            out[a] = hist_w[0, a]
        else:
            j = count - 2
            while j > 0 and hist_t[j] > s:
                j -= 1
            w = (s - hist_t[j]) / (hist_t[j + 1] - hist_t[j])
            out[a] = hist_w[j, a] + w * (hist_w[j + 1, a] - hist_w[j, a])


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _loop_derivative(t, x, cmd, plant, ctrl, ft, dx, hist_t, hist_w, count, delay, rates):  # pragma: no cover
    """The closed loop with the controller acting on delayed rates (latency), or on ``x``'s if there is none."""
    if count == 0:
        _closed_loop_derivative(t, x, cmd, plant, ctrl, ft, dx)
    else:
        _delayed_rates(hist_t, hist_w, count, t, x, delay, rates)
        controller_thrusts(cmd, rates[0], rates[1], rates[2], ctrl, ft)
        plant_derivative(t, x, ft, plant, dx)


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def _run_continuous(x, bp, coeffs, nseg, plant, ctrl, max_step, rec_t, rec_x, rec_u):  # pragma: no cover
    """Continuous-time playback without latency; ``x`` is advanced in place. Records every step if rec_t has room."""
    return _run_continuous_delayed(x, bp, coeffs, nseg, plant, ctrl, max_step, rec_t, rec_x, rec_u, np.zeros(3))


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def _run_continuous_delayed(x, bp, coeffs, nseg, plant, ctrl, max_step, rec_t, rec_x, rec_u,
                            delay):  # pragma: no cover - compiled
    """Continuous-time playback with per-axis rate-loop latency ``delay`` [s] (zeros: none)."""
    n = x.shape[0]
    k1 = np.empty(n)
    k2 = np.empty(n)
    k3 = np.empty(n)
    k4 = np.empty(n)
    tmp = np.empty(n)
    cmd0 = np.empty(4)
    cmdm = np.empty(4)
    cmd1 = np.empty(4)
    ft = np.empty(4)
    rates = np.empty(3)
    delayed = delay[0] > 0.0 or delay[1] > 0.0 or delay[2] > 0.0
    steps = 0
    if delayed:
        for k in range(nseg):
            steps += max(1, int(math.ceil((bp[k + 1] - bp[k]) / max_step - 1e-9)))
    hist_t = np.empty(steps + 1 if delayed else 0)
    hist_w = np.empty((steps + 1 if delayed else 0, 3))
    count = 0
    if delayed:
        hist_t[0] = bp[0]
        hist_w[0, 0] = x[10]
        hist_w[0, 1] = x[11]
        hist_w[0, 2] = x[12]
        count = 1
    record = rec_t.shape[0] > 0
    idx = 0
    if record:
        _command(coeffs, 0, 0.0, cmd0)
        rec_t[0] = bp[0]
        rec_x[0, :] = x
        rec_u[0, :] = cmd0
        idx = 1
    for k in range(nseg):
        t0 = bp[k]
        length = bp[k + 1] - t0
        m = max(1, int(math.ceil(length / max_step - 1e-9)))
        h = length / m
        for i in range(m):
            tau = i * h
            t = t0 + tau
            _command(coeffs, k, tau, cmd0)
            _command(coeffs, k, tau + 0.5 * h, cmdm)
            _command(coeffs, k, tau + h, cmd1)
            _loop_derivative(t, x, cmd0, plant, ctrl, ft, k1, hist_t, hist_w, count, delay, rates)
            for j in range(n):
                tmp[j] = x[j] + 0.5 * h * k1[j]
            _loop_derivative(t + 0.5 * h, tmp, cmdm, plant, ctrl, ft, k2, hist_t, hist_w, count, delay, rates)
            for j in range(n):
                tmp[j] = x[j] + 0.5 * h * k2[j]
            _loop_derivative(t + 0.5 * h, tmp, cmdm, plant, ctrl, ft, k3, hist_t, hist_w, count, delay, rates)
            for j in range(n):
                tmp[j] = x[j] + h * k3[j]
            _loop_derivative(t + h, tmp, cmd1, plant, ctrl, ft, k4, hist_t, hist_w, count, delay, rates)
            for j in range(n):
                x[j] += h / 6.0 * (k1[j] + 2.0 * (k2[j] + k3[j]) + k4[j])
            normalize_quaternion(x)
            t_end = t0 + (i + 1) * h if i + 1 < m else bp[k + 1]
            if delayed:
                hist_t[count] = t_end
                hist_w[count, 0] = x[10]
                hist_w[count, 1] = x[11]
                hist_w[count, 2] = x[12]
                count += 1
            if record:
                rec_t[idx] = t_end
                rec_x[idx, :] = x
                rec_u[idx, :] = cmd1
                idx += 1
    return idx


@nb.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def rk4_plant_step(t, x, ft, plant, h, k1, k2, k3, k4, tmp):  # pragma: no cover - compiled
    """One RK4 step of the plant with motor commands ``ft`` held constant."""
    n = x.shape[0]
    plant_derivative(t, x, ft, plant, k1)
    for j in range(n):
        tmp[j] = x[j] + 0.5 * h * k1[j]
    plant_derivative(t + 0.5 * h, tmp, ft, plant, k2)
    for j in range(n):
        tmp[j] = x[j] + 0.5 * h * k2[j]
    plant_derivative(t + 0.5 * h, tmp, ft, plant, k3)
    for j in range(n):
        tmp[j] = x[j] + h * k3[j]
    plant_derivative(t + h, tmp, ft, plant, k4)
    for j in range(n):
        x[j] += h / 6.0 * (k1[j] + 2.0 * (k2[j] + k3[j]) + k4[j])
    normalize_quaternion(x)


@nb.njit(cache=True, fastmath=True, error_model="numpy")
def _run_sampled(x, bp, coeffs, nseg, plant, ctrl, tick, substeps, rec_t, rec_x, rec_u, delay):  # pragma: no cover
    """Onboard playback: sample the program and run the controller every ``tick``; ZOH between.

    With latency the controller acts on the rates ``delay`` ago, interpolated in the tick history.
    """
    delayed = delay[0] > 0.0 or delay[1] > 0.0 or delay[2] > 0.0
    ticks = int(math.ceil(bp[nseg] / tick - 1e-9)) + 2 if delayed else 0
    hist_t = np.empty(ticks)
    hist_w = np.empty((ticks, 3))
    count = 0
    rates = np.empty(3)
    n = x.shape[0]
    k1 = np.empty(n)
    k2 = np.empty(n)
    k3 = np.empty(n)
    k4 = np.empty(n)
    tmp = np.empty(n)
    cmd = np.empty(4)
    ft = np.empty(4)
    end = bp[nseg]
    record = rec_t.shape[0] > 0
    idx = 0
    k = 0
    tick_index = 0
    t = 0.0
    while t < end - 1e-12:
        while k < nseg - 1 and bp[k + 1] <= t + 1e-12:
            k += 1
        _command(coeffs, k, t - bp[k], cmd)
        if record:
            rec_t[idx] = t
            rec_x[idx, :] = x
            rec_u[idx, :] = cmd
            idx += 1
        if delayed:
            hist_t[count] = t
            hist_w[count, 0] = x[10]
            hist_w[count, 1] = x[11]
            hist_w[count, 2] = x[12]
            count += 1
            _delayed_rates(hist_t, hist_w, count, t, x, delay, rates)
            controller_thrusts(cmd, rates[0], rates[1], rates[2], ctrl, ft)
        else:
            controller_thrusts(cmd, x[10], x[11], x[12], ctrl, ft)
        t_next = min((tick_index + 1) * tick, end)
        h = (t_next - t) / substeps
        for s in range(substeps):
            rk4_plant_step(t + s * h, x, ft, plant, h, k1, k2, k3, k4, tmp)
        tick_index += 1
        t = t_next
    if record:
        rec_t[idx] = end
        rec_x[idx, :] = x
        rec_u[idx, :] = cmd
        idx += 1
    return idx


@nb.njit(cache=True, fastmath=True, error_model="numpy", parallel=True)
def _batch_continuous(x0, bp, coeffs, nseg, plant, ctrl, max_step, out):  # pragma: no cover - compiled
    empty_t = np.empty(0)
    empty_x = np.empty((0, x0.shape[1]))
    empty_u = np.empty((0, 4))
    for b in nb.prange(x0.shape[0]):
        x = x0[b].copy()
        _run_continuous(x, bp[b], coeffs[b], nseg[b], plant[b], ctrl[b], max_step, empty_t, empty_x, empty_u)
        out[b, :] = x


@nb.njit(cache=True, fastmath=True, error_model="numpy", parallel=True)
def _batch_continuous_delayed(x0, bp, coeffs, nseg, plant, ctrl, max_step, delays, out):  # pragma: no cover
    empty_t = np.empty(0)
    empty_x = np.empty((0, x0.shape[1]))
    empty_u = np.empty((0, 4))
    for b in nb.prange(x0.shape[0]):
        x = x0[b].copy()
        _run_continuous_delayed(x, bp[b], coeffs[b], nseg[b], plant[b], ctrl[b], max_step, empty_t, empty_x,
                                empty_u, delays[b])
        out[b, :] = x


# ------------------------------------------------------------------- results


@dataclass(frozen=True)
class Trajectory:
    """A simulated or measured trajectory.

    Attributes
    ----------
    times_s : (N,) sample times [s].
    states : (N, N_STATE) states (layout in :mod:`aerobat.dynamics`).
    commands : (N, 4) commands at the samples: collective [m/s²], p̂, q̂, r̂ [rad/s].
    mode : playback mode that produced it.
    """

    times_s: np.ndarray
    states: np.ndarray
    commands: np.ndarray
    mode: str

    @property
    def final_state(self) -> np.ndarray:
        return self.states[-1]

    @property
    def duration_s(self) -> float:
        return float(self.times_s[-1] - self.times_s[0])

    @property
    def position_m(self) -> np.ndarray:
        """(N, 3) position, world frame, z up [m]."""
        return self.states[:, POS]

    @property
    def velocity_m_s(self) -> np.ndarray:
        """(N, 3) velocity, world frame [m/s]."""
        return self.states[:, VEL]

    @property
    def quaternion(self) -> np.ndarray:
        """(N, 4) attitude quaternion (w, x, y, z), body → world."""
        return self.states[:, 6:10]

    @property
    def body_rates_rad_s(self) -> np.ndarray:
        """(N, 3) body rates p, q, r [rad/s]."""
        return self.states[:, 10:13]

    @property
    def rotor_thrusts_n(self) -> np.ndarray:
        """(N, 4) rotor thrusts [N]."""
        return self.states[:, 13:17]

    def __repr__(self) -> str:
        return f"Trajectory({len(self.times_s)} samples over {self.duration_s:.3f} s, {self.mode})"

    def euler_zyx(self) -> np.ndarray:
        """(N, 3) Euler angles φ, θ, ψ [rad] along the trajectory (eq 13)."""
        return euler_zyx(self.states)

    def rotation_angles(self) -> np.ndarray:
        """(N, 3) unwrapped rotation angles about body x, y, z [rad]."""
        return rotation_angles(self.states)


def final_state_summary(state: np.ndarray, duration_s: float) -> dict:
    """JSON-ready summary of one state: the keys ``aerobat simulate --json`` documents."""
    state = np.asarray(state)
    return {
        "duration_s": float(duration_s),
        "final_state": {
            "position_m": [float(v) for v in state[POS]],
            "velocity_m_s": [float(v) for v in state[VEL]],
            "euler_zyx_rad": [float(v) for v in euler_zyx(state)],
            "rotation_angle_rad": [float(v) for v in rotation_angles(state)],
        },
    }


# --------------------------------------------------------------------- entry points


def _steps(bp: np.ndarray, max_step: float) -> int:
    return int(_step_count(bp, max_step))


def _step_count(bp: np.ndarray, max_step: float) -> float:
    """How many RK4 steps (as a float: inf for a step too small to count them)."""
    with np.errstate(over="ignore"):
        return float(np.maximum(1, np.ceil(np.diff(bp) / max_step - 1e-9)).sum())


MAX_STEPS = 10_000_000  # RK4 steps of one simulation: 600 s at the default step is 1.2 million


def check_max_step(max_step_s: Any, name: str = "max_step_s") -> float:
    """A step size: a finite number > 0 [s] (how many steps it makes is checked against each program)."""
    check_real(name, max_step_s)
    value = float(max_step_s)
    if not (value > 0 and math.isfinite(value)):
        raise ConfigError(f"{name} = {max_step_s} must be finite and > 0 (s)")
    return value


def _check_steps(steps: float, what: str) -> None:
    if not steps <= MAX_STEPS:
        raise ConfigError(f"{what}: {steps:.3g} integration steps for this program; allowed up to {MAX_STEPS:.0e}")


def _compiled(program: object, name: str = "program") -> CompiledProgram:
    check_type(name, program, (Program, CompiledProgram), "a Program")
    return program.compile() if isinstance(program, Program) else program  # type: ignore[return-value]


def simulate(
    program: Program | CompiledProgram,
    config: VehicleConfig,
    *,
    initial_state: np.ndarray | None = None,
    mode: Mode = "continuous",
    max_step_s: float = DEFAULT_MAX_STEP_S,
    tick_s: float = DEFAULT_TICK_S,
    substeps: int = 1,
    plant: np.ndarray | None = None,
    record: bool = True,
) -> Trajectory:
    """Play ``program`` on ``config`` from ``initial_state`` (default: hover at the origin).

    Parameters
    ----------
    program : the command program (or its compiled form).
    config : vehicle constants and onboard controller.
    initial_state : (N_STATE,) start state; default :func:`~aerobat.dynamics.hover_state`.
    mode : ``"continuous"`` (design model) or ``"sampled"`` (800 Hz onboard ZOH).
    max_step_s : largest RK4 step in continuous mode [s].
    tick_s : command-generator period in sampled mode [s].
    substeps : RK4 steps per tick in sampled mode.
    plant : optional flat plant vector (:func:`~aerobat.dynamics.plant_vector`) overriding
        ``config.vehicle`` and its effects — how testbeds with extra effects use this function
        (the rate-loop latency of ``config.effects`` still applies).
    record : keep every step (True) or only the start and final states (False).
    """
    compiled = _compiled(program)
    check_type("config", config, VehicleConfig, "a VehicleConfig")
    max_step_s = check_max_step(max_step_s)
    tick_s = check_max_step(tick_s, "tick_s")
    substeps = check_int("substeps", substeps)
    if not 1 <= substeps <= MAX_STEPS:
        raise ConfigError(f"substeps = {substeps} must be >= 1 (and at most {MAX_STEPS:.0e})")
    check_type("record", record, (bool, np.bool_), "True or False")
    if not isinstance(mode, str) or mode not in ("continuous", "sampled"):
        raise ConfigError(f"mode = {mode!r}: allowed 'continuous' or 'sampled'")
    x = hover_state(config.vehicle) if initial_state is None else as_float_array("initial_state", initial_state,
                                                                                   (N_STATE,))
    start = x.copy()
    plant_v = model_plant_vector(config) if plant is None else as_float_array("plant", plant, (N_PLANT,))
    ctrl_v = controller_vector(config.controller)
    delay = np.array(config.effects.rate_latency_s, dtype=float)
    bp = compiled.breakpoints_s
    coeffs = compiled.coefficients
    nseg = len(bp) - 1
    if mode == "continuous":
        _check_steps(_step_count(bp, max_step_s), f"max_step_s = {max_step_s:g}")
        size = _steps(bp, max_step_s) + 1 if record else 0
    else:
        ticks = compiled.duration_s / tick_s
        _check_steps(ticks * substeps, f"tick_s = {tick_s:g} with substeps = {substeps}")
        size = math.ceil(ticks - 1e-9) + 2 if record else 0
    rec_t = np.empty(size)
    rec_x = np.empty((size, N_STATE))
    rec_u = np.empty((size, 4))
    if mode == "continuous":
        count = _run_continuous_delayed(x, bp, coeffs, nseg, plant_v, ctrl_v, max_step_s, rec_t, rec_x, rec_u, delay)
    else:
        count = _run_sampled(x, bp, coeffs, nseg, plant_v, ctrl_v, tick_s, substeps, rec_t, rec_x, rec_u, delay)
    if not record:
        cmds = compiled.evaluate(np.array([0.0, compiled.duration_s - 1e-12]))
        return Trajectory(np.array([0.0, compiled.duration_s]), np.stack([start, x]), cmds, mode)
    return Trajectory(rec_t[:count].copy(), rec_x[:count].copy(), rec_u[:count].copy(), mode)


def simulate_batch(
    programs: Sequence[Program | CompiledProgram],
    configs: VehicleConfig | Sequence[VehicleConfig],
    *,
    initial_states: np.ndarray | None = None,
    plants: np.ndarray | None = None,
    max_step_s: float = DEFAULT_MAX_STEP_S,
) -> np.ndarray:
    """Final states of many (program, vehicle) pairs, continuous mode, on all cores.

    Parameters
    ----------
    programs : B programs.
    configs : one vehicle for all, or B vehicles.
    initial_states : (B, N_STATE) or None for hover at the origin.
    plants : optional (B, N_PLANT) plant vectors overriding the vehicles' own (and their effects;
        each vehicle's rate-loop latency still applies).

    Returns
    -------
    (B, N_STATE) final states.
    """
    max_step_s = check_max_step(max_step_s)
    check_type("programs", programs, Sequence, "a sequence of Programs")
    compiled = [_compiled(p, f"programs[{k}]") for k, p in enumerate(programs)]
    B = len(compiled)
    if B == 0:
        return np.empty((0, N_STATE))
    check_type("configs", configs, (VehicleConfig, Sequence), "a VehicleConfig or a sequence of them")
    cfgs = [configs] * B if isinstance(configs, VehicleConfig) else list(configs)  # type: ignore[list-item]
    if len(cfgs) != B:
        raise ConfigError(f"got {B} programs but {len(cfgs)} vehicles")
    for k, cfg in enumerate(cfgs):
        check_type(f"configs[{k}]", cfg, VehicleConfig, "a VehicleConfig")
    for one in compiled:
        _check_steps(_step_count(one.breakpoints_s, max_step_s), f"max_step_s = {max_step_s:g}")
    kmax = max(len(c.breakpoints_s) - 1 for c in compiled)
    bp = np.zeros((B, kmax + 1))
    coeffs = np.zeros((B, kmax, 4, 3))
    nseg = np.zeros(B, dtype=np.int64)
    for b, c in enumerate(compiled):
        k = len(c.breakpoints_s) - 1
        bp[b, : k + 1] = c.breakpoints_s
        coeffs[b, :k] = c.coefficients
        nseg[b] = k
    if plants is None:
        plants = np.stack([model_plant_vector(c) for c in cfgs])
    ctrl = np.stack([controller_vector(c.controller) for c in cfgs])
    if initial_states is None:
        initial_states = np.stack([hover_state(c.vehicle) for c in cfgs])
    x0 = np.ascontiguousarray(as_float_array("initial_states", initial_states, (B, N_STATE)))
    plants = np.ascontiguousarray(as_float_array("plants", plants, (B, N_PLANT)))
    out = np.empty_like(x0)
    delays = np.array([c.effects.rate_latency_s for c in cfgs], dtype=float)
    if np.any(delays > 0.0):
        _batch_continuous_delayed(x0, bp, coeffs, nseg, plants, ctrl, max_step_s, delays, out)
    else:
        _batch_continuous(x0, bp, coeffs, nseg, plants, ctrl, max_step_s, out)
    return out


class NominalModel:
    """The design model Φ(p, ŝ) as a batch of final states (continuous mode, all cores).

    Implements the ``FinalStateModel`` protocol of :mod:`aerobat.design`.
    """

    def __init__(self, config: VehicleConfig, *, max_step_s: float = DEFAULT_MAX_STEP_S) -> None:
        self.config = check_type("config", config, VehicleConfig, "a VehicleConfig (e.g. aerobat.hummingbird())")
        self.max_step_s = check_max_step(max_step_s)
        self._plant = model_plant_vector(config)

    def final_states(self, programs: Sequence[Program], initial_states: np.ndarray | None = None) -> np.ndarray:
        check_type("programs", programs, Sequence, "a sequence of Programs")
        plants = np.tile(self._plant, (len(programs), 1))
        return simulate_batch(programs, self.config, initial_states=initial_states, plants=plants,
                              max_step_s=self.max_step_s)

    def trajectory(self, program: Program, initial_state: np.ndarray | None = None) -> Trajectory:
        return simulate(program, self.config, initial_state=initial_state, max_step_s=self.max_step_s)
