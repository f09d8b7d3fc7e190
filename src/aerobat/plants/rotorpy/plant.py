"""RotorPy as an independent physical vehicle (issue 7).

The vehicle is RotorPy's ``Multirotor`` with its shipped AscTec Hummingbird
parameters (``rotorpy.vehicles.hummingbird_params``), flown through RotorPy's
public ``cmd_ctbr`` interface (collective thrust and body rates): a model that
aerobat did not write, with its own mass, inertia, X-configuration rotor layout,
motor model, rate loop and aerodynamics (rotor H-force, parasitic drag,
translational lift).

One :meth:`RotorPyPlant.fly` mirrors one arena trial (Fig. 8) without the lossy
radio: the supervisor's cascaded PD controller (``pd_command`` from the arena)
settles the vehicle at the start on motion-capture feedback, the maneuver
program is sampled by an 800 Hz command generator (zero-order hold) and fed to
``Multirotor.step`` as ``cmd_thrust`` [N] = RotorPy mass × mass-normalized
collective and ``cmd_w`` [rad/s]; the final state is estimated from
motion-capture samples alone with the arena's estimation helpers; then the PD
controller brings the vehicle back to the start for the next trial.

Everything random comes from one ``numpy.random.Generator`` seeded by ``seed``.
RotorPy's own motor noise and Dryden gusts draw from numpy's *global* legacy
RNG; when either is enabled the plant reseeds ``np.random`` from its generator
at the start of every trial (documented side effect), so a seed still
reproduces every trial bit for bit.

The extra is optional: ``pip install 'aerobat[rotorpy]'``. ``rotorpy`` is
imported only when a plant is built.

See ``docs/plants.md`` for what this plant models, what it leaves out, the
adapted vehicle settings and their reasons, and measured speed.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from aerobat.core.plant import Trial, TrialStatus
from aerobat.errors import MissingDependency
from aerobat.plants.lab_kernels import MOCAP_COLUMNS, estimate_pose, mocap_sample, pd_command, settled
from aerobat.plants.plant_state import StateLayout
from aerobat.plants.rotorpy.settings import (
    RotorPySettings,
    WindSettings,
    build_quad_params,
    import_rotorpy,
    load_rotorpy_settings,
)
from aerobat.plants.supervisor import Phase, TrialStop, fly_phases
from aerobat.quadrotor.dynamics import N_STATE
from aerobat.quadrotor.feedback import (
    Feedback,
    FeedbackScheme,
    apply_feedback,
    as_feedback,
    feedback_vector,
    onboard_propagate,
    onboard_receive,
    onboard_state,
    reference_from_trajectory,
    relay_deviation,
)
from aerobat.quadrotor.program import CompiledProgram, Program
from aerobat.quadrotor.simulate import simulate
from aerobat.quadrotor.vehicle import VehicleConfig

__all__ = ["RotorPyPlant"]

_LAYOUT = StateLayout("rotorpy", counters=("trials_flown", "tick"))


# ------------------------------------------------------------ integrators


def _fixed_step_solver(order: int) -> type:
    """A ``scipy.integrate.OdeSolver`` taking exactly one explicit Runge–Kutta step to ``t_bound``.

    RotorPy holds the rotor-speed command constant over each ``step`` (one 800 Hz tick), so a
    single 3rd-order (Kutta) or classical 4th-order step per tick is enough; scipy accepts an
    ``OdeSolver`` subclass as ``method``, and RotorPy passes ``integrator_kwargs`` to
    ``solve_ivp`` unchanged. Accuracy against a tight DOP853 reference: docs/plants.md.
    """
    from scipy.integrate import OdeSolver

    class FixedStepRK(OdeSolver):
        def __init__(self, fun, t0, y0, t_bound, vectorized=False, **extraneous):
            super().__init__(fun, t0, y0, t_bound, vectorized)

        def _step_impl(self):
            t, y, f = self.t, self.y, self.fun
            h = self.t_bound - t
            k1 = f(t, y)
            k2 = f(t + 0.5 * h, y + 0.5 * h * k1)
            if order == 3:
                k3 = f(t + h, y + h * (2.0 * k2 - k1))
                self.y = y + (h / 6.0) * (k1 + 4.0 * k2 + k3)
            else:
                k3 = f(t + 0.5 * h, y + 0.5 * h * k2)
                k4 = f(t + h, y + h * k3)
                self.y = y + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)
            self.t = self.t_bound
            return True, None

        def _dense_output_impl(self):  # pragma: no cover - solve_ivp asks only with dense_output=True
            raise NotImplementedError("fixed-step solver: no dense output")

    FixedStepRK.__name__ = FixedStepRK.__qualname__ = f"FixedStepRK{order}"
    return FixedStepRK


def _integrator_kwargs(name: str, tick_s: float) -> dict[str, Any]:
    if name == "rk3":
        return {"method": _fixed_step_solver(3)}
    if name == "rk4":
        return {"method": _fixed_step_solver(4)}
    if name in ("RK45", "RK23", "DOP853"):
        return {"method": name, "first_step": tick_s}  # the tick is short: skip the step-size search
    return {"method": name}


# ------------------------------------------------------------------ plant


def _wind_profile(wind: WindSettings, tick_s: float) -> Any | None:
    if wind.model == "none":
        return None
    if wind.model == "constant":
        from rotorpy.wind.default_winds import ConstantWind

        return ConstantWind(*wind.velocity_m_s)
    if wind.model == "sinusoid":
        from rotorpy.wind.default_winds import SinusoidWind

        return _Offset(SinusoidWind(amplitudes=np.array(wind.amplitude_m_s), frequencies=np.array(wind.frequency_hz),
                                    phase=np.array(wind.phase_s)), np.array(wind.velocity_m_s))
    try:
        from rotorpy.wind.dryden_winds import DrydenGust
    except ImportError as exc:
        raise MissingDependency("torch", extra="rotorpy", purpose="RotorPy's Dryden wind model (rotorpy 3.0.0)",
                                detail=f"{exc}; or choose another wind model") from None
    return DrydenGust(dt=tick_s, avg_wind=np.array(wind.velocity_m_s), sig_wind=np.array(wind.sigma_m_s),
                      altitude=wind.altitude_m)


class _Offset:
    """A RotorPy wind profile plus a constant mean wind."""

    def __init__(self, profile: Any, mean: np.ndarray) -> None:
        self.profile = profile
        self.mean = mean

    def update(self, t: float, position: np.ndarray) -> np.ndarray:
        return self.mean + np.asarray(self.profile.update(t, position), dtype=float)


class RotorPyPlant:
    """RotorPy's Hummingbird as the physical vehicle, supervised like the arena.

    Parameters
    ----------
    config : the *nominal* vehicle (the design model); the supervisor's PD controller uses its
        envelope and gravity. The RotorPy vehicle has its own constants.
    settings_path : a RotorPy plant TOML file (:func:`load_rotorpy_settings`), or None.
    seed : seeds the plant's random generator (motion-capture noise, RotorPy's global RNG).
    settings : settings given directly (mutually exclusive with ``settings_path``).
    wind_profile : any object with RotorPy's wind interface ``update(t, position) -> (3,)`` [m/s];
        replaces ``settings.wind``.
    feedback : what the onboard loop mixes into the program (:mod:`aerobat.quadrotor.feedback`);
        default ``none``, the best measured with the default update rule (``tracking`` wins only
        with ``rule="broyden"``: docs/results.md, Feedback). The onboard estimator integrates RotorPy's
        body rates (its model has no gyro errors) and takes the supervisor's motion-capture estimate
        every supervisor period (``supervisor_rate_hz``; no radio here, so no drops).
    design_model : the model the programs were designed on, if not ``config``: the feedback's reference is
        its flight of each program.
    """

    name = "rotorpy"

    def __init__(self, config: VehicleConfig, settings_path: str | Path | None = None, seed: int = 0, *,
                 settings: RotorPySettings | None = None, wind_profile: Any | None = None,
                 feedback: Feedback | FeedbackScheme | str | None = None,
                 design_model: VehicleConfig | None = None) -> None:
        multirotor_cls, _ = import_rotorpy()
        if settings_path is not None and settings is not None:
            raise ValueError("give either settings_path or settings, not both")
        source = str(settings_path) if settings_path is not None else "RotorPy settings"
        self.settings = load_rotorpy_settings(settings_path) if settings_path is not None else (
            settings or RotorPySettings())
        s = self.settings
        self.config = config
        self.design_model = config if design_model is None else design_model
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.quad_params = build_quad_params(s, source=source)
        self.tick_s = 1.0 / s.command_rate_hz
        self.vehicle = multirotor_cls(self.quad_params, control_abstraction="cmd_ctbr", aero=s.aero,
                                      integrator_kwargs=_integrator_kwargs(s.integrator, self.tick_s))
        self.mass_kg = float(self.vehicle.mass)
        self.wind_profile = wind_profile if wind_profile is not None else _wind_profile(s.wind, self.tick_s)
        self.uses_global_rng = (float(self.quad_params.get("motor_noise_std", 0.0)) != 0.0
                                or (wind_profile is None and s.wind.model == "dryden"))
        self.mocap_every = max(1, round(s.command_rate_hz / s.motion_capture.rate_hz))
        self.mocap_delay_s = s.motion_capture.latency_s
        self.control_every = max(1, math.floor(s.command_rate_hz / s.supervisor_rate_hz + 1e-9))
        sup = s.supervisor
        v = config.vehicle
        self._gains = np.array([sup.position_gain_per_s2, sup.velocity_gain_per_s, sup.attitude_gain_per_s,
                                sup.yaw_gain_per_s, 3.0])
        self._limits = np.array([v.collective_reduced_min_m_s2, v.collective_reduced_max_m_s2,
                                 0.6 * v.gravity_m_s2, 8.0, v.gravity_m_s2])
        self.hover_cmd = np.array([v.gravity_m_s2, 0.0, 0.0, 0.0])
        self._supervisor_cmd = self.hover_cmd.copy()
        self.start_m = np.zeros(3)
        self.trials_flown = 0
        self.steps_taken = 0
        self.tick = 0
        self.integral = np.zeros(3)
        self._rate_integral = np.zeros(3)
        self.state = self.hover_state()
        self._rows = np.empty((4096, MOCAP_COLUMNS))
        self._count = 0
        self._truth: list[np.ndarray] = []
        self.last_truth: tuple[np.ndarray, np.ndarray] = (np.empty(0), np.empty((0, N_STATE)))
        self._empty_noise = np.zeros(6)
        self._est_pos = np.zeros(3)
        self._est_vel = np.zeros(3)
        self._est_quat = np.array([1.0, 0.0, 0.0, 0.0])
        # None: RotorPy's default, the open loop (the best measured with the default rule)
        self.feedback = Feedback(FeedbackScheme.NONE) if feedback is None else as_feedback(feedback)
        self._fb_vector = feedback_vector(self.feedback)

    # ---------------------------------------------------------------- state
    def hover_state(self, position_m: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """A RotorPy state dict in true hover at ``position_m``: level, at rest, rotors at hover speed.

        The rotor speeds are what RotorPy's own cmd_ctbr allocation commands for a thrust of m·g
        (RotorPy's g = 9.81) and zero moment, so the state is an exact equilibrium without wind.
        """
        state = {
            "x": np.array(self.start_m if position_m is None else position_m, dtype=float),
            "v": np.zeros(3),
            "q": np.array([0.0, 0.0, 0.0, 1.0]),  # RotorPy: scalar last (x, y, z, w)
            "w": np.zeros(3),
            "wind": np.zeros(3),
            "rotor_speeds": np.zeros(4),
        }
        hover = self.vehicle.get_cmd_motor_speeds(
            state, {"cmd_thrust": self.vehicle.mass * self.vehicle.g, "cmd_w": np.zeros(3)})
        state["rotor_speeds"] = np.clip(hover, self.vehicle.rotor_speed_min, self.vehicle.rotor_speed_max)
        return state

    def aerobat_state(self, state: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """A RotorPy state dict in aerobat's layout (quaternion w, x, y, z; motor thrusts NaN).

        ``RATE_INT`` is the plant's running trapezoidal ∫ω dt (truth only: it counts whole turns).
        """
        s = self.state if state is None else state
        x = np.zeros(N_STATE)
        x[0:3] = s["x"]
        x[3:6] = s["v"]
        q = s["q"]
        x[6:10] = (q[3], q[0], q[1], q[2])
        x[10:13] = s["w"]
        x[13:17] = np.nan  # RotorPy's rotor order and layout differ from the paper's motors
        x[17:20] = self._rate_integral
        return x

    # --------------------------------------------------------- persistence
    _ARRAYS = ("integral", "start_m")
    _VEHICLE_KEYS = ("x", "v", "q", "w", "wind", "rotor_speeds")

    def get_state(self) -> dict[str, Any]:
        """Everything that changes from trial to trial, as JSON-ready plain values.

        With the constructor arguments this fixes every later trial: a fresh plant given this
        state with :meth:`set_state` flies the next trials bit for bit like this one would
        (except with a stateful wind model such as Dryden, whose filter state is not captured).

        Returns
        -------
        dict
            ``format``, ``rng`` (the generator's ``bit_generator.state``), ``trials_flown``,
            ``tick``, ``vehicle`` (RotorPy's state dict as lists), ``integral``, ``start_m``,
            ``supervisor_cmd`` (lists of floats).
        """
        arrays = {f"vehicle.{key}": self.state[key] for key in self._VEHICLE_KEYS}
        arrays.update({name: getattr(self, name) for name in self._ARRAYS})
        arrays["supervisor_cmd"] = self._supervisor_cmd
        return _LAYOUT.encode(self.rng, {"trials_flown": self.trials_flown, "tick": self.tick}, {}, arrays)

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restore a state from :meth:`get_state` (of a plant built with the same arguments).

        Raises
        ------
        ValueError
            A field is missing, of the wrong type or length, or the generator kind differs.
        """
        sizes = {f"vehicle.{key}": self.state[key].size for key in self._VEHICLE_KEYS}
        sizes.update({name: 3 for name in self._ARRAYS}, supervisor_cmd=4)
        read = _LAYOUT.decode(state, self.rng, sizes)
        self.rng.bit_generator.state = read.rng
        self.trials_flown = read.counters["trials_flown"]
        self.tick = read.counters["tick"]
        self.state = {key: read.arrays[f"vehicle.{key}"] for key in self._VEHICLE_KEYS}
        self.integral = read.arrays["integral"]
        self.start_m = read.arrays["start_m"]
        self._supervisor_cmd = read.arrays["supervisor_cmd"]

    # ------------------------------------------------------------ stepping
    def _record(self) -> None:
        """A motion-capture sample of the current state (before the step) plus the true state."""
        if self._count == self._rows.shape[0]:
            grown = np.empty((2 * self._rows.shape[0], MOCAP_COLUMNS))
            grown[: self._count] = self._rows[: self._count]
            self._rows = grown
        mc = self.settings.motion_capture
        noise = self._empty_noise
        if mc.position_noise_m or mc.attitude_noise_rad:
            noise = np.empty(6)
            noise[:3] = mc.position_noise_m * self.rng.standard_normal(3)
            noise[3:] = mc.attitude_noise_rad * self.rng.standard_normal(3)
        truth = self.aerobat_state()
        t = self.tick * self.tick_s
        if not np.all(np.isfinite(truth[:13])):
            raise TrialStop(TrialStatus.ABORTED, f"non-finite vehicle state at t = {t:.3f} s")
        row = self._rows[self._count]
        mocap_sample(truth, t, noise, row)
        self._count += 1
        self._truth.append(np.concatenate([[t], truth]))
        vol = self.settings.volume
        for axis, (lo, hi), name in ((0, vol.x_m, "x"), (1, vol.y_m, "y"), (2, vol.z_m, "z")):
            rel = row[1 + axis] - self.start_m[axis]
            if rel < lo or rel > hi:
                where = "the floor" if (axis == 2 and rel < lo) else f"the {name} limits [{lo:g}, {hi:g}] m"
                raise TrialStop(TrialStatus.CRASHED, f"left the flyable volume at t = {t:.3f} s: "
                                             f"{name} = {rel:+.3f} m beyond {where}")

    def _step(self, cmd: np.ndarray) -> None:
        """One command-generator tick: sample mocap, hold ``cmd`` over the tick, integrate."""
        if self.tick % self.mocap_every == 0:
            self._record()
        t = self.tick * self.tick_s
        state = self.state
        if self.wind_profile is not None:
            state["wind"] = np.asarray(self.wind_profile.update(t, state["x"]), dtype=float)
        control = {"cmd_thrust": self.mass_kg * float(cmd[0]), "cmd_w": np.array(cmd[1:4], dtype=float)}
        try:
            with np.errstate(all="ignore"):
                self.state = self.vehicle.step(state, control, self.tick_s)
        except ValueError as exc:  # solve_ivp refuses a non-finite state, wind or command
            raise TrialStop(TrialStatus.ABORTED, f"non-finite vehicle state, wind or command at t = {t:.4f} s "
                                         f"(RotorPy step: {exc})") from None
        self._rate_integral += 0.5 * self.tick_s * (state["w"] + self.state["w"])
        self.tick += 1
        self.steps_taken += 1

    def _feedback(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """What the supervisor knows now: the arena's estimate from the mocap samples older than the latency."""
        if self._count == 0:
            return None
        available = self.tick * self.tick_s - self.mocap_delay_s + 1e-12
        rows = int(np.searchsorted(self._rows[: self._count, 0], available, side="right"))
        if not estimate_pose(self._rows, rows, self._est_pos, self._est_vel, self._est_quat):
            return None
        return self._est_pos, self._est_vel, self._est_quat

    def _closed_loop(self, n_ticks: int) -> None:
        """Fly ``n_ticks`` under the supervisor's PD hover controller at ``supervisor_rate_hz``."""
        cmd = self._supervisor_cmd  # held between the controller's updates, like a radio command
        period = self.control_every * self.tick_s
        for _ in range(n_ticks):
            if self.tick % self.control_every == 0:
                est = self._feedback()
                if est is None:
                    cmd[:] = self.hover_cmd
                else:
                    pd_command(est[0], est[1], est[2], self.start_m, self.integral, self._gains, self._limits,
                               period, cmd)
            self._step(cmd)

    def _settle(self) -> None:
        """Hold the start until within the supervisor's tolerances for its hold time."""
        sup = self.settings.supervisor
        hold = max(1, round(sup.settle_hold_s / self.tick_s))
        deadline = self.tick + round(sup.settle_timeout_s / self.tick_s)
        chunk = self.control_every
        calm = 0
        while self.tick < deadline:
            self._closed_loop(chunk)
            est = self._feedback()
            if est is not None and settled(est[0], est[1], est[2], self.start_m, sup.settle_position_m,
                                           sup.settle_velocity_m_s, sup.settle_tilt_rad):
                calm += chunk
                if calm >= hold:
                    return
            else:
                calm = 0
        raise TrialStop(TrialStatus.ABORTED, f"did not settle at the start within {sup.settle_timeout_s:g} s")

    # ---------------------------------------------------------------- trial
    def fly(self, program: Program | CompiledProgram) -> Trial:
        """One supervised trial (:func:`~aerobat.plants.supervisor.fly_phases`): settle, run the program open
        loop at 800 Hz, measure, return."""
        wall = time.perf_counter()
        steps0 = self.steps_taken
        compiled = program.compile() if isinstance(program, Program) else program
        self._count = 0
        self._truth = []
        self._rate_integral[:] = 0.0  # the truth counts turns from this trial's start
        if self.uses_global_rng:
            # RotorPy's motor noise (and Dryden gusts) use numpy's global RNG: reseed it per trial
            np.random.seed(int(self.rng.integers(2**32)))  # noqa: NPY002 - RotorPy draws from it
        try:
            flown = fly_phases(_Sortie(self), compiled)
        finally:
            truth = np.array(self._truth) if self._truth else np.empty((0, N_STATE + 1))
            self.last_truth = (truth[:, 0], truth[:, 1:])
        info: dict[str, Any] = {"steps": self.steps_taken - steps0, "wall_s": time.perf_counter() - wall}
        if flown.phase is not Phase.LAND:  # ended early
            return flown.trial("", info)
        info = {"start_time_s": flown.start_time_s, **info}
        return flown.trial(f"maneuver flown on RotorPy ({info['steps']} steps of {self.tick_s * 1e3:.3g} ms)", info)

    def _fly_program(self, compiled: CompiledProgram) -> None:
        """The program's ticks, open loop (with the onboard feedback if there is one), then hover commands
        until the supervisor's estimation window is filled."""
        n_man = math.ceil(compiled.duration_s / self.tick_s - 1e-9)
        commands = compiled.evaluate(np.arange(n_man) * self.tick_s)
        self.trials_flown += 1
        if self.feedback.enabled:
            self._fly_with_feedback(compiled, commands, self.tick * self.tick_s)
        else:
            for k in range(n_man):
                self._step(commands[k])
        for _ in range(math.ceil(0.015 / self.tick_s)):
            self._step(compiled.hover)

    def _fly_with_feedback(self, compiled: CompiledProgram, commands: np.ndarray, start_time: float) -> None:
        """The program's ticks with the onboard feedback: the estimator starts from the supervisor's
        attitude estimate at the trigger, integrates the body rates every tick and takes in the
        supervisor's estimate (attitude, deviation from the reference) every supervisor period."""
        nominal = simulate(compiled, self.design_model, record=True)
        reference = reference_from_trajectory(nominal.times_s, nominal.states, self.feedback.gains.reference_rate_hz)
        onboard, history = onboard_state()
        est = self._feedback()
        if est is not None:
            onboard[0:4] = est[2]
        scratch = np.empty(10)
        relay = np.empty(6)
        cmd = np.empty(4)
        for k in range(commands.shape[0]):
            t = self.tick * self.tick_s
            if k % self.control_every == 0 and self._count:
                available = int(np.searchsorted(self._rows[: self._count, 0], t - self.mocap_delay_s + 1e-12,
                                                side="right"))
                if available:
                    row = self._rows[available - 1]
                    moved = relay_deviation(self._rows, available, start_time, self.start_m, reference.samples,
                                            reference.dt_s, scratch, relay)
                    onboard_receive(onboard, history, self._fb_vector, float(row[0]), row[4:8].copy(),
                                    relay[0:3], relay[3:6], moved)
            cmd[:] = commands[k]
            apply_feedback(cmd, onboard, self._fb_vector, reference.samples, k * self.tick_s, t, scratch)
            w = self.state["w"]
            onboard_propagate(onboard, history, t, float(w[0]), float(w[1]), float(w[2]), self.tick_s)
            self._step(cmd)

    def _pick_up(self) -> None:
        """After a failed trial: the vehicle back in hover at the start (picked up, restarted)."""
        self.state = self.hover_state()
        self.integral[:] = 0.0
        self._rate_integral[:] = 0.0
        self._supervisor_cmd[:] = self.hover_cmd


class _Sortie:
    """One RotorPy trial as the supervisor flies it (:class:`~aerobat.plants.supervisor.Sortie`)."""

    def __init__(self, plant: RotorPyPlant) -> None:
        self.plant = plant
        self.start_m = plant.start_m
        self.compiled: CompiledProgram | None = None

    def take_off(self) -> None:
        self.plant._settle()

    def hover(self) -> None:
        """The settle ends in hover; the program starts at once."""

    def trigger(self, compiled: CompiledProgram) -> float:
        """The program runs on the supervisor's computer: it starts at the next tick."""
        self.compiled = compiled
        return self.plant.tick * self.plant.tick_s

    def maneuver(self, compiled: CompiledProgram, start_time_s: float) -> None:
        self.plant._fly_program(compiled)

    def return_to_start(self) -> None:
        assert self.compiled is not None
        self.plant._supervisor_cmd[:] = self.compiled.hover  # the program's last command, then the PD loop
        self.plant._settle()

    def land(self) -> None:
        """The vehicle hovers at the start between trials."""

    def mocap(self) -> np.ndarray:
        return self.plant._rows[: self.plant._count]

    def now_s(self) -> float:
        return self.plant.tick * self.plant.tick_s

    def pick_up(self) -> None:
        self.plant._pick_up()
