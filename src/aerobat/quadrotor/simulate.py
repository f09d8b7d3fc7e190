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

The kernels (:mod:`aerobat.quadrotor.playback`) are compiled with numba and allocate nothing inside their loops;
:func:`simulate_batch` runs many (program, vehicle) pairs in parallel threads
(:func:`set_batch_threads`).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Literal

import numba as nb
import numpy as np

from aerobat.config import as_float_array, check_int, check_real, check_type
from aerobat.core.bounds import OneOf
from aerobat.errors import ConfigError
from aerobat.quadrotor.dynamics import (
    N_PLANT,
    N_STATE,
    POS,
    VEL,
    controller_vector,
    euler_zyx,
    hover_state,
    model_plant_vector,
    rotation_angles,
)
from aerobat.quadrotor.playback import run_continuous, run_continuous_lagged, run_sampled
from aerobat.quadrotor.program import CompiledProgram, Program
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["Mode", "NominalModel", "Trajectory", "batch_threads", "final_state_summary", "set_batch_threads",
           "simulate", "simulate_batch"]

Mode = Literal["continuous", "sampled"]
"""How a program is played: the continuous-time model, or the onboard command generator's zero-order hold."""
DEFAULT_MAX_STEP_S = 5e-4
DEFAULT_TICK_S = 1.0 / 800.0


# ------------------------------------------------------------------- batches


_NO_T = np.empty(0)
_NO_X = np.empty((0, N_STATE))
_NO_U = np.empty((0, 4))


class _Workers:
    """Threads for batches: each runs chunks of a batch through :func:`~.playback.run_continuous`.

    The kernel releases the GIL, so plain threads run it in parallel, and each runs the very
    code a single simulation runs (same results bit for bit, same speed: a numba ``prange``
    around the kernel ran ~10 % slower per simulation, and its OpenMP workers spun between the
    design's short batches, taking the cores the Python work in between needed).
    """

    lock = threading.Lock()
    pool: ThreadPoolExecutor | None = None
    size = 0
    threads: int | None = None  # set_batch_threads

    @classmethod
    def get(cls, threads: int) -> ThreadPoolExecutor:
        with cls.lock:
            if cls.pool is None or cls.size != threads:
                if cls.pool is not None:
                    cls.pool.shutdown(wait=False)
                cls.pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="aerobat-batch")
                cls.size = threads
            return cls.pool


def set_batch_threads(threads: int | None) -> None:
    """How many threads :func:`simulate_batch` and :class:`NominalModel` use; None: :func:`batch_threads`' default."""
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
        raise ConfigError(f"threads = {threads!r}: allowed an integer >= 1, or None")
    _Workers.threads = threads


def batch_threads() -> int:
    """Threads a batch runs on: :func:`set_batch_threads`, else numba's ``NUMBA_NUM_THREADS`` (all cores)."""
    return _Workers.threads if _Workers.threads is not None else int(nb.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]


def _play(rows: np.ndarray, x0: np.ndarray, bp: np.ndarray, coeffs: np.ndarray, nseg: np.ndarray, plants: np.ndarray,
          ctrl: np.ndarray, delays: np.ndarray, max_step_s: float, out: np.ndarray) -> None:
    """Rows ``rows`` of a packed batch into ``out``: the rows without rate-loop latency, then those with."""
    lagged = np.any(delays[rows] > 0.0, axis=1)
    if not lagged.all():
        run_continuous(x0, bp, coeffs, nseg, plants, ctrl, delays, max_step_s, out, rows[~lagged], _NO_T, _NO_X, _NO_U)
    if lagged.any():
        run_continuous_lagged(x0, bp, coeffs, nseg, plants, ctrl, delays, max_step_s, out, rows[lagged], _NO_T, _NO_X,
                              _NO_U)


def _run_batch(x0: np.ndarray, bp: np.ndarray, coeffs: np.ndarray, nseg: np.ndarray, plants: np.ndarray,
               ctrl: np.ndarray, delays: np.ndarray, max_step_s: float, out: np.ndarray) -> None:
    """Final states of a packed batch into ``out``: one program on this thread, several on all threads."""
    count = x0.shape[0]
    threads = min(count, batch_threads()) if count > 1 else 1
    if threads == 1:  # nothing to hand over
        _play(np.arange(count), x0, bp, coeffs, nseg, plants, ctrl, delays, max_step_s, out)
        return
    pool = _Workers.get(threads)
    if count >= 16 * threads:  # a large batch: a few chunks per thread even out a thread slowed by others
        jobs = [pool.submit(_play, rows, x0, bp, coeffs, nseg, plants, ctrl, delays, max_step_s, out)
                for rows in np.array_split(np.arange(count), 4 * threads)]
        for job in jobs:
            job.result()
        return
    # a short batch (the design's: a Jacobian, a line search): one share per thread, cut by steps so that
    # programs of different lengths even out, the calling thread running the last share itself; each
    # hand-over and each call into the kernel costs tens of µs
    steps = np.maximum(1.0, np.ceil(np.diff(bp, axis=1) / max_step_s - 1e-9))
    steps[np.arange(bp.shape[1] - 1)[None, :] >= nseg[:, None]] = 0.0
    work = np.cumsum(steps.sum(axis=1))
    cuts = np.searchsorted(work, work[-1] * np.arange(1, threads) / threads, side="right")
    shares = [rows for rows in np.split(np.arange(count), cuts) if rows.size]
    jobs = [pool.submit(_play, rows, x0, bp, coeffs, nseg, plants, ctrl, delays, max_step_s, out)
            for rows in shares[:-1]]
    try:
        _play(shares[-1], x0, bp, coeffs, nseg, plants, ctrl, delays, max_step_s, out)
    finally:
        for job in jobs:
            job.result()


# ------------------------------------------------------------------- results


@dataclass(frozen=True)
class Trajectory:
    """A simulated or measured trajectory.

    Attributes
    ----------
    times_s : (N,) sample times [s].
    states : (N, N_STATE) states (layout in :mod:`aerobat.quadrotor.dynamics`).
    commands : (N, 4) commands at the samples: collective [m/s²], p̂, q̂, r̂ [rad/s].
    mode : playback mode that produced it.
    """

    times_s: np.ndarray
    states: np.ndarray
    commands: np.ndarray
    mode: str

    @property
    def final_state(self) -> np.ndarray:
        """The state at the trajectory's last sample (13 entries)."""
        return self.states[-1]

    @property
    def duration_s(self) -> float:
        """The trajectory's length [s]."""
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
    initial_state : (N_STATE,) start state; default :func:`~aerobat.quadrotor.dynamics.hover_state`.
    mode : ``"continuous"`` (design model) or ``"sampled"`` (800 Hz onboard ZOH).
    max_step_s : largest RK4 step in continuous mode [s].
    tick_s : command-generator period in sampled mode [s].
    substeps : RK4 steps per tick in sampled mode.
    plant : optional flat plant vector (:func:`~aerobat.quadrotor.dynamics.plant_vector`) overriding
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
    OneOf(Mode).check("mode", mode)
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
        final = np.empty((1, N_STATE))
        packed = (x[None, :], bp[None, :], coeffs[None], np.array([nseg]), plant_v[None, :], ctrl_v[None, :])
        row = np.zeros(1, dtype=np.int64)
        play = run_continuous_lagged if np.any(delay > 0.0) else run_continuous
        count = play(*packed, delay[None, :], max_step_s, final, row, rec_t, rec_x, rec_u)
        x = final[0]
    else:
        count = run_sampled(x, bp, coeffs, nseg, plant_v, ctrl_v, tick_s, substeps, rec_t, rec_x, rec_u, delay)
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
    (B, N_STATE) final states, bit for bit those :func:`simulate` computes one at a time.
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
    one = all(c is cfgs[0] for c in cfgs)  # one vehicle for all: its vectors once

    def rows(make: Callable[[VehicleConfig], np.ndarray]) -> np.ndarray:
        return np.tile(make(cfgs[0]), (B, 1)) if one else np.stack([make(c) for c in cfgs])

    if plants is None:
        plants = rows(model_plant_vector)
    ctrl = rows(lambda c: controller_vector(c.controller))
    if initial_states is None:
        initial_states = rows(lambda c: hover_state(c.vehicle))
    x0 = np.ascontiguousarray(as_float_array("initial_states", initial_states, (B, N_STATE)))
    plants = np.ascontiguousarray(as_float_array("plants", plants, (B, N_PLANT)))
    delays = rows(lambda c: np.array(c.effects.rate_latency_s, dtype=float))
    return _final_states(compiled, x0, plants, ctrl, delays, max_step_s)


def _final_states(compiled: Sequence[CompiledProgram], x0: np.ndarray, plants: np.ndarray, ctrl: np.ndarray,
                  delays: np.ndarray, max_step_s: float) -> np.ndarray:
    """Run checked, contiguous inputs: pack the programs, one row each, check their step counts, run the batch."""
    B = len(compiled)
    out = np.empty_like(x0)
    nseg = np.array([len(c.breakpoints_s) - 1 for c in compiled], dtype=np.int64)
    kmax = int(nseg.max())
    bp = np.zeros((B, kmax + 1))
    coeffs = np.zeros((B, kmax, 4, 3))
    for b, c in enumerate(compiled):
        k = nseg[b]
        bp[b, : k + 1] = c.breakpoints_s
        coeffs[b, :k] = c.coefficients
    # the steps of every program at once (_step_count's arithmetic; the padding counts nothing)
    with np.errstate(over="ignore", invalid="ignore"):
        per_segment = np.maximum(1, np.ceil(np.diff(bp, axis=1) / max_step_s - 1e-9))
    per_segment[np.arange(kmax)[None, :] >= nseg[:, None]] = 0.0
    steps = per_segment.sum(axis=1)
    if not np.all(steps <= MAX_STEPS):
        _check_steps(float(steps[~(steps <= MAX_STEPS)][0]), f"max_step_s = {max_step_s:g}")
    _run_batch(x0, bp, coeffs, nseg, plants, ctrl, delays, max_step_s, out)
    return out


class NominalModel:
    """The design model Φ(p, ŝ) as a batch of final states (continuous mode, all cores).

    Implements the ``FinalStateModel`` protocol of :mod:`aerobat.design`.
    """

    def __init__(self, config: VehicleConfig, *, max_step_s: float = DEFAULT_MAX_STEP_S) -> None:
        self.config = check_type("config", config, VehicleConfig, "a VehicleConfig (e.g. aerobat.hummingbird())")
        self.max_step_s = check_max_step(max_step_s)
        self._plant = model_plant_vector(config)
        self._ctrl = controller_vector(config.controller)
        self._hover = hover_state(config.vehicle)
        self._delay = np.array(config.effects.rate_latency_s, dtype=float)

    def final_states(self, programs: Sequence[Program | CompiledProgram],
                     initial_states: np.ndarray | None = None) -> np.ndarray:
        """(B, N_STATE) final states of ``programs`` from ``initial_states`` (default: hover at the origin)."""
        check_type("programs", programs, Sequence, "a sequence of Programs")
        if initial_states is not None:
            return simulate_batch(programs, self.config, initial_states=initial_states,
                                  plants=np.tile(self._plant, (len(programs), 1)), max_step_s=self.max_step_s)
        compiled = [_compiled(p, f"programs[{k}]") for k, p in enumerate(programs)]
        B = len(compiled)
        if B == 0:
            return np.empty((0, N_STATE))
        return _final_states(compiled, np.tile(self._hover, (B, 1)), np.tile(self._plant, (B, 1)),
                             np.tile(self._ctrl, (B, 1)), np.tile(self._delay, (B, 1)), self.max_step_s)

    def trajectory(self, program: Program, initial_state: np.ndarray | None = None) -> Trajectory:
        """The whole simulated trajectory of ``program`` from ``initial_state`` (default: hover at the origin)."""
        return simulate(program, self.config, initial_state=initial_state, max_step_s=self.max_step_s)
