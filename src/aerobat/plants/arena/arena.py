"""The simulated flying-machine arena and its supervisor (Sect. 10.2, Fig. 8).

One :meth:`Arena.fly` is one iteration of Fig. 8: settle at the start under the
cascaded PD controller (commands over the lossy 70 Hz link), upload the program
with acknowledgement and retries, send exactly one trigger, keep sending
placeholder hover commands, detect a lost trigger by timeout, estimate the
final state at the estimated maneuver end from motion-capture samples alone,
then recover and return to the start. All randomness comes from one seeded
generator, so a seed reproduces every trial bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aerobat.config import check_type
from aerobat.core.bounds import SEEDS
from aerobat.core.plant import Trial, TrialStatus
from aerobat.plants.arena.kernel import supervise
from aerobat.plants.arena.params import ArenaParams
from aerobat.plants.lab_kernels import MOCAP_COLUMNS
from aerobat.plants.plant_state import StateLayout
from aerobat.plants.supervisor import TrialStop, fly_phases
from aerobat.quadrotor.dynamics import (
    controller_vector,
    hover_state,
    plant_vector,
    quaternion_from_rotation_vector,
    quaternion_multiply,
    rotation_vector_from_quaternion,
)
from aerobat.quadrotor.feedback import (
    Feedback,
    FeedbackScheme,
    Reference,
    as_feedback,
    feedback_vector,
    onboard_state,
    reference_from_trajectory,
)
from aerobat.quadrotor.program import CompiledProgram, Program
from aerobat.quadrotor.simulate import Trajectory, simulate
from aerobat.quadrotor.vehicle import VehicleConfig, VehicleParams

__all__ = ["Arena"]


# the true state may hold NaN after a diverged trial: the next trial starts from hover again
_LAYOUT = StateLayout("arena", counters=("trials_flown", "tick"), fractions=("capacity",), finite=False)

@dataclass
class _Log:
    """Motion-capture samples of the current trial (grown in place)."""

    rows: np.ndarray
    count: int = 0

    def view(self) -> np.ndarray:
        return self.rows[: self.count]


class Arena:
    """A simulated testbed: a true vehicle unlike the nominal model, sensors, links and a supervisor.

    Parameters
    ----------
    config : the *nominal* vehicle (the design model); the onboard controller inverts with it.
    params : the arena's effects (defaults: a realistic Hummingbird in a mocap arena).
    seed : seeds the arena's single random generator.
    feedback : what the onboard loop mixes into the program (:mod:`aerobat.quadrotor.feedback`):
        a :class:`Feedback`, or a scheme name with default gains; default the best scheme measured
        (``tracking``); ``"none"`` is the paper's pure open loop.
    design_model : the model the programs were designed on, if not ``config`` (a vehicle identified
        on this arena, which stays built around ``config``). Its flight of each program is the
        feedback's reference and the supervisor's prediction for the trigger check: tracking
        ``config``'s flight of a program designed on another model would pull the vehicle onto a
        flight that misses the target.
    """

    name = "arena"

    def __init__(self, config: VehicleConfig, params: ArenaParams | None = None, *, seed: int = 0,
                 feedback: Feedback | FeedbackScheme | str | None = None,
                 design_model: VehicleConfig | None = None) -> None:
        self.config = check_type("config", config, VehicleConfig, "a VehicleConfig (e.g. aerobat.hummingbird())")
        self.design_model = config if design_model is None else check_type(
            "design_model", design_model, VehicleConfig, "a VehicleConfig or None")
        self.params = ArenaParams() if params is None else check_type("params", params, ArenaParams,
                                                                      "ArenaParams or None")
        self.seed = SEEDS.check("seed", seed)
        self.feedback = as_feedback(feedback)
        self._fb_vector = feedback_vector(self.feedback)
        self.onboard, self.history = onboard_state()
        self._reference = Reference.empty()
        self.rng = np.random.default_rng(seed)
        self.trials_flown = 0
        self.capacity = 1.0
        p = self.params
        self.tick_s = 1.0 / p.onboard.rate_hz
        self.mocap_every = max(1, round(p.onboard.rate_hz / p.motion_capture.rate_hz))
        self.mocap_delay_ticks = round(p.motion_capture.latency_s / self.tick_s)
        self.link_delay_ticks = math.ceil(p.links.command_latency_s / self.tick_s - 1e-9)
        self.true_vehicle = self._true_vehicle_params()
        self.ctrl = controller_vector(config.controller)
        self.sensor = np.zeros(6)
        self.sensor[:3] = p.onboard.gyro_scale_error
        self.sensor[3:] = p.onboard.gyro_bias_rad_s
        self.start_m = np.zeros(3)
        self.tick = 0
        self.x = hover_state(self.true_vehicle)
        self.gyro_prev = np.zeros(3)
        self.radio_cmd = np.array([config.vehicle.gravity_m_s2, 0.0, 0.0, 0.0])
        self.integral = np.zeros(3)
        self.plant = self._plant_vector()
        self._empty_program = Program(switches=(), duration_s=1.0).compile()

    # ---------------------------------------------------------------- set-up
    def _true_vehicle_params(self) -> VehicleParams:
        nominal = self.config.vehicle
        tv = self.params.true_vehicle
        if not tv.enabled:
            return nominal
        return VehicleParams(
            mass_kg=nominal.mass_kg * tv.mass_scale,
            arm_length_m=nominal.arm_length_m,
            inertia_xx_kg_m2=nominal.inertia_xx_kg_m2 * tv.inertia_scale[0],
            inertia_yy_kg_m2=nominal.inertia_yy_kg_m2 * tv.inertia_scale[1],
            inertia_zz_kg_m2=nominal.inertia_zz_kg_m2 * tv.inertia_scale[2],
            motor_rate_up_per_s=tv.motor_rate_up_per_s,
            motor_rate_down_per_s=tv.motor_rate_down_per_s,
            rotor_thrust_min_n=nominal.rotor_thrust_min_n,
            rotor_thrust_max_n=nominal.rotor_thrust_max_n,
            collective_reduced_min_m_s2=nominal.collective_reduced_min_m_s2 / tv.mass_scale,
            collective_reduced_max_m_s2=nominal.collective_reduced_max_m_s2 / tv.mass_scale,
            drag_constant_m=nominal.drag_constant_m * tv.drag_constant_scale,
            gravity_m_s2=nominal.gravity_m_s2,
        )

    def _plant_vector(self) -> np.ndarray:
        """The true plant for the next trial: constants, drift, per-trial gusts and jitter."""
        p = self.params
        tv = p.true_vehicle
        gains = np.array(tv.thrust_gains if tv.enabled else (1.0, 1.0, 1.0, 1.0), dtype=float) * self.capacity
        kwargs: dict = {}
        if p.disturbances.enabled:
            d = p.disturbances
            common = d.thrust_gain_jitter * self.rng.standard_normal()
            gains = gains * (1.0 + common + d.motor_gain_jitter * self.rng.standard_normal(4))
            kwargs.update(
                wind_m_s=tuple(d.wind_std_m_s * self.rng.standard_normal(3)),
                gust_amplitude_m_s=tuple(d.gust_amplitude_std_m_s * self.rng.standard_normal(3)),
                gust_frequency_hz=d.gust_frequency_hz,
                gust_phase_rad=float(self.rng.uniform(0.0, 2.0 * math.pi)),
            )
        if p.aerodynamics.enabled:
            a = p.aerodynamics
            kwargs.update(
                body_drag_n_s2_m2=a.body_drag_n_s2_m2,
                rotor_drag_s_m=a.rotor_drag_s_m,
                rotational_damping_n_m_s=a.rotational_damping_n_m_s,
            )
        com = tv.com_offset_m if tv.enabled else (0.0, 0.0, 0.0)
        vec = plant_vector(self.true_vehicle, com_offset_m=com, thrust_gains=tuple(gains), **kwargs)
        if p.aerodynamics.enabled and not p.disturbances.enabled:
            vec[30:38] = 0.0
        return vec

    def _hover_residual(self) -> None:
        """Perturb the true state by the configured hover residual (see ``Disturbances``)."""
        d = self.params.disturbances
        self.x[3:6] += d.start_velocity_std_m_s * self.rng.standard_normal(3)
        tilt = d.start_tilt_std_rad * self.rng.standard_normal(2)
        q = quaternion_multiply(self.x[6:10], quaternion_from_rotation_vector(np.array([tilt[0], tilt[1], 0.0])))
        self.x[6:10] = q / np.linalg.norm(q)

    def reset_drift(self) -> None:
        """A fresh battery and propellers: thrust capacity back to 100 %."""
        self.capacity = 1.0

    _ARRAYS = ("x", "gyro_prev", "radio_cmd", "integral", "plant", "start_m")

    def get_state(self) -> dict[str, object]:
        """Everything that changes from trial to trial, as JSON-ready plain values.

        With the constructor arguments (``config``, ``params``, ``seed``) this fixes
        every later trial: a fresh arena given this state with :meth:`set_state`
        flies the next trials bit for bit like this one would.

        Returns
        -------
        dict
            ``rng`` (the generator's ``bit_generator.state``, integers only),
            ``trials_flown``, ``capacity``, ``tick``, and the arrays ``x`` (true
            vehicle state), ``gyro_prev``, ``radio_cmd``, ``integral``, ``plant``,
            ``start_m`` (and with onboard feedback its estimator's ``onboard`` and
            ``history``) as lists of floats; :mod:`aerobat.plants.plant_state` has the format.
        """
        arrays = {name: getattr(self, name) for name in self._ARRAYS}
        if self.feedback.enabled:
            arrays.update(onboard=self.onboard, history=self.history)
        return _LAYOUT.encode(self.rng, {"trials_flown": self.trials_flown, "tick": self.tick},
                              {"capacity": self.capacity}, arrays)

    def set_state(self, state: dict[str, object]) -> None:
        """Restore a state from :meth:`get_state` (of an arena built with the same arguments).

        Raises
        ------
        ValueError
            A field is missing, of the wrong type or length, or the generator kind differs.
        """
        onboard, history = onboard_state()
        sizes = {name: getattr(self, name).size for name in self._ARRAYS}
        if self.feedback.enabled:
            sizes.update(onboard=onboard.size, history=history.size)
        # a state stored before the axial rotor-drag entry existed lacks it (0 = none)
        read = _LAYOUT.decode(state, self.rng, sizes, padding={"plant": 0.0})
        self.rng.bit_generator.state = read.rng
        self.trials_flown = read.counters["trials_flown"]
        self.tick = read.counters["tick"]
        self.capacity = read.fractions["capacity"]
        for name in self._ARRAYS:
            setattr(self, name, read.arrays[name])
        if self.feedback.enabled:
            onboard[...] = read.arrays["onboard"].reshape(onboard.shape)
            history[...] = read.arrays["history"].reshape(history.shape)
        self.onboard, self.history = onboard, history

    # ------------------------------------------------------------ simulation
    def _mocap_noise(self, rows: int) -> np.ndarray:
        mc = self.params.motion_capture
        noise = np.empty((rows, 6))
        noise[:, :3] = mc.position_noise_m * self.rng.standard_normal((rows, 3)) if mc.position_noise_m else 0.0
        noise[:, 3:] = mc.attitude_noise_rad * self.rng.standard_normal((rows, 3)) if mc.attitude_noise_rad else 0.0
        return noise

    def _supervise(self, n_ticks: int, log: _Log, target: np.ndarray, *, closed_loop: bool = True,
                   program=None, man_start_tick: int = -1, settle: np.ndarray | None = None) -> bool:
        """Fly ``n_ticks`` with radio commands every link period; a crash or a diverged state raises
        :class:`~aerobat.plants.supervisor.TrialStop`.

        With ``settle`` = (hold ticks, position, velocity, tilt tolerances) it returns True as soon as
        the vehicle has stayed within tolerance, else False after ``n_ticks``.
        """
        if n_ticks <= 0:
            return False
        p = self.params
        period = 1.0 / p.links.command_rate_hz
        gains = np.array([p.supervisor.position_gain_per_s2, p.supervisor.velocity_gain_per_s,
                          p.supervisor.attitude_gain_per_s, p.supervisor.yaw_gain_per_s, 3.0])
        v = self.config.vehicle
        limits = np.array([v.collective_reduced_min_m_s2, v.collective_reduced_max_m_s2, 0.6 * v.gravity_m_s2,
                           8.0, v.gravity_m_s2])
        # open-loop placeholder: hover with the supervisor's learned thrust trim
        hover_cmd = np.array([v.gravity_m_s2 + gains[4] * self.integral[2], 0.0, 0.0, 0.0])
        rows = n_ticks // self.mocap_every + 2
        periods = int(math.ceil(n_ticks * self.tick_s / period)) + 2
        if log.count + rows > log.rows.shape[0]:
            grown = np.empty((max(2 * log.rows.shape[0], log.count + rows), MOCAP_COLUMNS))
            grown[: log.count] = log.rows[: log.count]
            log.rows = grown
        noise = self._mocap_noise(rows)
        drops = self.rng.random(periods)
        compiled = program if program is not None else self._empty_program
        duration = compiled.duration_s if program is not None else 0.0
        vol = p.volume
        volume = np.array([*vol.x_m, *vol.y_m, *vol.z_m], dtype=float)
        out = np.zeros(6, dtype=np.int64)
        supervise(self.x, self.gyro_prev, self.tick, self.tick + n_ticks, self.tick_s, self.plant, self.ctrl,
                  self.sensor, p.onboard.gyro_latency_samples, self.radio_cmd, compiled.breakpoints_s,
                  compiled.coefficients, len(compiled.breakpoints_s) - 1, man_start_tick, duration,
                  self.mocap_every, self.mocap_delay_ticks, noise, log.rows, log.count, period,
                  self.link_delay_ticks, drops, p.links.command_drop_probability, closed_loop,
                  np.asarray(target, dtype=float), self.integral, gains, limits, hover_cmd, volume,
                  np.zeros(4) if settle is None else settle, self._fb_vector, self._reference.samples,
                  self.onboard, self.history, out)
        self.tick = int(out[0])
        log.count = int(out[1])
        status = int(out[4])
        if status == 1:
            raise TrialStop(TrialStatus.ABORTED, "non-finite vehicle state")
        if status == 2:
            raise TrialStop(TrialStatus.CRASHED, self._volume_message(log.rows[int(out[5])]))
        return status == 3

    def _volume_message(self, row: np.ndarray) -> str:
        vol = self.params.volume
        for axis, (lo, hi), name in ((0, vol.x_m, "x"), (1, vol.y_m, "y"), (2, vol.z_m, "z")):
            rel = row[1 + axis] - self.start_m[axis]
            if rel < lo or rel > hi:
                where = "the floor" if (axis == 2 and rel < lo) else f"the {name} limits [{lo:g}, {hi:g}] m"
                return f"left the arena volume at t = {row[0]:.3f} s: {name} = {rel:+.3f} m beyond {where}"
        return "left the arena volume"  # pragma: no cover - the kernel only reports real violations

    def _settle(self, log: _Log) -> None:
        """Fly to the start until within tolerance for the hold time; a trial stop on timeout."""
        s = self.params.supervisor
        hold_ticks = max(1, round(s.settle_hold_s / self.tick_s))
        settle = np.array([hold_ticks, s.settle_position_m, s.settle_velocity_m_s, s.settle_tilt_rad], dtype=float)
        if not self._supervise(round(s.settle_timeout_s / self.tick_s), log, self.start_m, settle=settle):
            raise TrialStop(TrialStatus.ABORTED, f"did not settle at the start within {s.settle_timeout_s:g} s")

    def _upload(self, program: Program, log: _Log) -> int:
        """Send the switch list in packets, each acknowledged; retries cost a timeout each. Returns the attempts."""
        links = self.params.links
        packets = max(1, math.ceil(len(program.switches) / links.upload_switches_per_packet))
        if self.feedback.enabled:  # the reference goes up with the program
            packets += math.ceil(self._reference.samples.shape[0] / links.upload_reference_samples_per_packet)
        attempts_total = 0
        for packet in range(packets):
            for _attempt in range(links.upload_max_attempts):
                attempts_total += 1
                sent = self.rng.random() >= links.upload_drop_probability
                acked = sent and self.rng.random() >= links.upload_drop_probability
                wait = 0.004 if acked else links.upload_timeout_s
                self._supervise(max(1, round(wait / self.tick_s)), log, self.start_m)
                if acked:
                    break
            else:
                raise TrialStop(TrialStatus.ABORTED, f"upload of packet {packet + 1}/{packets} not acknowledged "
                                                     f"after {links.upload_max_attempts} attempts")
        return attempts_total

    # ----------------------------------------------------------------- trial
    def fly(self, program: Program) -> Trial:
        """One supervised trial of ``program`` (Fig. 8, :func:`~aerobat.plants.supervisor.fly_phases`)."""
        check_type("program", program, Program, "a Program")
        self.plant = self._plant_vector()
        nominal = simulate(program, self.design_model, record=True)  # what the program was designed to fly
        if self.feedback.enabled:
            self._reference = reference_from_trajectory(nominal.times_s, nominal.states,
                                                        self.feedback.gains.reference_rate_hz)
        sortie = _Sortie(self, program, nominal)
        flown = fly_phases(sortie, program.compile())
        if flown.ok:
            return flown.trial(f"maneuver flown ({sortie.attempts} upload packet attempts)",
                               {"upload_attempts": sortie.attempts, "start_time_s": flown.start_time_s})
        return flown.trial("", {"upload_attempts": sortie.attempts} if flown.status is TrialStatus.NO_TRIGGER else {})

    def _pick_up(self) -> None:
        """After a failed trial: the vehicle back at the start, restarted."""
        self.x = hover_state(self.true_vehicle, (float(self.start_m[0]), float(self.start_m[1]),
                                                 float(self.start_m[2])))
        self.gyro_prev[:] = 0.0
        self.integral[:] = 0.0
        self.onboard, self.history = onboard_state()  # restarted: the estimator starts level
        self.radio_cmd = np.array([self.config.vehicle.gravity_m_s2, 0.0, 0.0, 0.0])

    def _maneuver_started(self, log: _Log, nominal: Trajectory, start_time: float, check_tick: int) -> bool:
        """Did the vehicle start the maneuver? Nearest of two hypotheses at the check time.

        The measured pose change since the trigger is compared with the nominal model's
        prediction (triggered) and with no change at all (trigger lost).
        """
        rows = log.view()
        check_time = check_tick * self.tick_s - self.mocap_delay_ticks * self.tick_s
        available = rows[rows[:, 0] <= check_time + 1e-12]
        before = rows[rows[:, 0] <= start_time + 1e-12]
        if available.shape[0] == 0 or before.shape[0] == 0:
            return True
        ref, now = before[-1], available[-1]
        k = min(int(np.searchsorted(nominal.times_s, now[0] - start_time)), len(nominal.times_s) - 1)
        predicted_disp = nominal.states[k, 0:3]
        predicted_rot = rotation_vector_from_quaternion(nominal.states[k, 6:10])
        measured_disp = now[1:4] - ref[1:4]
        measured_rot = rotation_vector_from_quaternion(
            quaternion_multiply(ref[4:8] * np.array([1.0, -1.0, -1.0, -1.0]), now[4:8]))
        lever = 0.2  # metres of "pose distance" per radian
        d_triggered = (np.linalg.norm(measured_disp - predicted_disp)
                       + lever * np.linalg.norm(measured_rot - predicted_rot))
        d_lost = np.linalg.norm(measured_disp) + lever * np.linalg.norm(measured_rot)
        return bool(d_triggered < d_lost)


class _Sortie:
    """One arena trial as the supervisor flies it (:class:`~aerobat.plants.supervisor.Sortie`)."""

    def __init__(self, arena: Arena, program: Program, nominal: Trajectory) -> None:
        self.arena = arena
        self.program = program
        self.nominal = nominal  # the design model's flight: the trigger check's prediction
        self.log = _Log(np.empty((4096, MOCAP_COLUMNS)))
        self.start_m = arena.start_m
        self.attempts = 0
        self.start_tick = -1  # the tick the program starts at, as the supervisor knows it
        self.man_start = -1  # the tick the vehicle starts the program at (-1: the trigger was lost)
        self.compiled: CompiledProgram | None = None

    def take_off(self) -> None:
        self.arena._settle(self.log)

    def hover(self) -> None:
        """The settle ends in hover; the trigger follows at once."""

    def trigger(self, compiled: CompiledProgram) -> float:
        """Upload, then exactly one trigger packet on the command link, sent at the next link period."""
        a, p = self.arena, self.arena.params
        self.attempts = a._upload(self.program, self.log)
        period = 1.0 / p.links.command_rate_hz
        send_tick = math.ceil((math.floor(a.tick * a.tick_s / period + 1e-9) + 1) * period / a.tick_s - 1e-9)
        a._supervise(send_tick - a.tick, self.log, a.start_m)
        triggered = a.rng.random() >= p.links.command_drop_probability
        if p.disturbances.enabled:
            a._hover_residual()
        start_tick = a.tick + a.link_delay_ticks  # measured link delay: the supervisor knows it
        self.start_tick = start_tick
        self.man_start = start_tick if triggered else -1
        self.compiled = compiled
        a.radio_cmd = np.array([a.config.vehicle.gravity_m_s2, 0.0, 0.0, 0.0])
        a.trials_flown += 1
        return start_tick * a.tick_s

    def maneuver(self, compiled: CompiledProgram, start_time_s: float) -> None:
        """Placeholder hover commands (the vehicle ignores them while the program runs); a lost
        trigger is found by the trigger check and flown back."""
        a, p = self.arena, self.arena.params
        start_tick = self.start_tick
        end_tick = start_tick + math.ceil(compiled.duration_s / a.tick_s - 1e-9)
        check_tick = start_tick + round(min(p.supervisor.trigger_timeout_s, 0.5 * compiled.duration_s) / a.tick_s)
        a._supervise(check_tick - a.tick, self.log, a.start_m, closed_loop=False, program=compiled,
                     man_start_tick=self.man_start)
        if not a._maneuver_started(self.log, self.nominal, start_time_s, check_tick):
            lost = "trigger lost: no maneuver motion within the timeout; no correction"
            try:
                a._supervise(round(p.supervisor.return_time_s / a.tick_s), self.log, a.start_m)
            except TrialStop as failure:  # the return failed too: picked up
                raise TrialStop(TrialStatus.NO_TRIGGER, f"{lost}; then {failure}") from None
            raise TrialStop(TrialStatus.NO_TRIGGER, lost, picked_up=False)
        margin = math.ceil(0.015 / a.tick_s)
        a._supervise(end_tick + margin - a.tick, self.log, a.start_m, closed_loop=False, program=compiled,
                     man_start_tick=self.man_start)

    def return_to_start(self) -> None:
        """Recover and return under closed-loop control; the battery loses its share of capacity."""
        a = self.arena
        try:
            a._supervise(round(a.params.supervisor.return_time_s / a.tick_s), self.log, a.start_m,
                         program=self.compiled, man_start_tick=self.man_start)
        finally:
            if a.params.drift.enabled:
                a.capacity *= 1.0 - a.params.drift.thrust_loss_per_trial

    def land(self) -> None:
        """The arena's vehicle hovers at the start between trials."""

    def mocap(self) -> np.ndarray:
        return self.log.view()

    def now_s(self) -> float:
        return self.arena.tick * self.arena.tick_s

    def pick_up(self) -> None:
        self.arena._pick_up()
