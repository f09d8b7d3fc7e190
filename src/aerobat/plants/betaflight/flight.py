"""One flight: a firmware process, the physical world around it, the radio and motion capture.

:class:`Flight` owns a fresh :class:`~aerobat.firmware.betaflight.sitl.SitlProcess` and steps it in lockstep with
:func:`.physics.step`: one state packet out, one motor packet back, one gyro period of physics.
Time advances in radio frames: :meth:`Flight.frame` takes the channels the ground sends for one
frame period; the radio drops the frame with the configured probability (seeded) or delivers it
after the link latency, right before the state packet of the step it arrives in. Motion capture
samples the true state at its rate with seeded noise into a log the supervisor reads with its
latency. Nothing here decides what to fly: that is the plant's supervisor.

Frames run in one compiled loop (:mod:`.frame_loop`): the radio's draw and latency queue, the
noise, the RC packets, and each step's motion capture, exchange (:mod:`.lockstep`: shared memory
with ``firmware.exchange = "shm"``, the C library's ``send``/``recv`` on the process's sockets
with ``"udp"``) and physics — and, for :meth:`Flight.run_frames`, the
supervisor's pilot and checks between frames. Python is back at least every
:data:`CHUNK_FRAMES` frames and whenever an answer is late: then the process's watchdog takes
over.

Everything random comes from the generator passed in, so a seed repeats a flight bit for bit;
the firmware is deterministic in lockstep.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from aerobat.errors import ConfigError
from aerobat.firmware.betaflight.packets import MOTOR_STRUCT, RC_STRUCT, Exchange, SpinPolicy
from aerobat.firmware.betaflight.shm import SpinChoices
from aerobat.firmware.betaflight.sitl import SitlProcess
from aerobat.plants.betaflight.cores import CorePair, claim_core_pair
from aerobat.plants.betaflight.lockstep import (
    DONE,
    IO_EXCHANGES,
    IO_LOG,
    IO_RESUME,
    NO_ANSWER,
    NON_FINITE,
    RESUME_STEP,
    SEND_FAILED,
)
from aerobat.plants.betaflight.physics import (
    A_GROUND,
    C_CONTACT,
    C_DELAY,
    N_COUNTERS,
    PACKET_DOUBLES,
    SCRATCH_ROWS,
    aux_vector,
    ground_state,
    prime,
)
from aerobat.plants.fpv import frames as fr
from aerobat.plants.fpv.frames import AnglePilot, FramesEnd, FramesRun, Mode, ProgramPilot, Radio, Until
from aerobat.plants.fpv.params import BetaflightParams
from aerobat.plants.lab_kernels import MOCAP_COLUMNS, estimate_pose
from aerobat.quadrotor.dynamics import N_STATE

__all__ = ["CHUNK_FRAMES", "N_PACKET", "N_SAMPLE", "SAMPLE_GYRO", "SAMPLE_MOTORS", "SAMPLE_PID", "SAMPLE_RATES",
           "SAMPLE_SETPOINT", "SAMPLE_TIME", "Flight", "NonFinite"]

# the columns of a row of :meth:`Flight.sampled_frame`
SAMPLE_TIME = 0
"""The flight's time [s]."""
SAMPLE_RATES = slice(1, 4)
"""The true body rates p, q, r [rad/s], body FLU."""
SAMPLE_MOTORS = slice(4, 8)
"""The firmware's four motor commands, packet order (0..1)."""
SAMPLE_SETPOINT = slice(8, 11)
"""The firmware's rate set point roll, pitch, yaw [deg/s]."""
SAMPLE_PID = slice(11, 23)
"""The PID terms, axis-major: roll's P, I, D, F, then pitch's, then yaw's (firmware units)."""
N_PACKET = SAMPLE_PID.stop - SAMPLE_MOTORS.start
"""The motor packet's floats (motors, set point, PID terms) in a sample row, and at the end of a record row."""
SAMPLE_GYRO = slice(23, 26)
"""The gyro the firmware reads p, q, r [rad/s], body FLU: the true rates with the sensor's scale error, bias and
noise and the frame's vibration (the state packet's, as the firmware gets it next)."""
N_SAMPLE = 26

_SLICE_S = 0.05  # the compiled shared-memory wait's timeout: then the watchdog takes the step


CHUNK_FRAMES = 250
"""Most frames per compiled call: Python (Ctrl-C, a fault injected by a test) gets a turn every 0.26 s simulated."""


class NonFinite(Exception):
    """The vehicle's state went non-finite (the trial is aborted)."""


class Flight:
    """A firmware instance and the world it flies in, from power-on on the floor.

    Parameters
    ----------
    binary, eeprom : the lockstep SITL and its configured eeprom.
    params : the plant's settings.
    plant : the true vehicle's plant vector for this flight (:func:`.physics.airframe_plant`).
    start_m : the maneuver start [m]; the vehicle stands on the floor below it.
    rng : the plant's generator (noise, radio drops).
    gravity_m_s2 : g.
    """

    packet_columns = N_PACKET  # a record row ends with the firmware's motor packet
    """:meth:`run_frames` can record the firmware's motor packet after each frame (the lockstep SITL answers
    every step with it; a flight controller on a serial link sends its motors only when asked)."""

    def __init__(self, binary: Path, eeprom: Path, params: BetaflightParams, plant: np.ndarray,
                 start_m: np.ndarray, rng: np.random.Generator, gravity_m_s2: float) -> None:
        fw = params.firmware
        self.params = params
        self.rng = rng
        self.step_s = 1.0 / fw.gyro_rate_hz
        frame_steps = fw.gyro_rate_hz / params.radio.rate_hz
        if abs(frame_steps - round(frame_steps)) > 1e-9:
            raise ConfigError(f"radio.rate_hz = {params.radio.rate_hz:g}: the frame period must be a whole number "
                              f"of gyro periods ({fw.gyro_rate_hz} Hz)")
        self.frame_steps = round(frame_steps)
        self.mocap_every = max(1, round(fw.gyro_rate_hz / params.motion_capture.rate_hz))
        latency_steps = round(params.radio.latency_s / self.step_s)
        self.start_m = np.asarray(start_m, dtype=float)
        ground = float(self.start_m[2] + params.volume.z_m[0])
        self.x = ground_state((float(self.start_m[0]), float(self.start_m[1]), ground))
        self.plant = plant
        self.aux = aux_vector(params, step_s=self.step_s, ground_z_m=ground, gravity_m_s2=gravity_m_s2)
        delay = round(params.airframe.output_delay_s / self.step_s)
        self.counters = np.zeros(N_COUNTERS, dtype=np.int64)
        self.counters[C_DELAY] = delay
        self.counters[C_CONTACT] = 1
        self.pending = np.zeros((delay + 1, 4))
        self.scratch = np.zeros((SCRATCH_ROWS, N_STATE))  # the physics' rows, a held sample's state, the rotors' angles
        self.packet = np.zeros(PACKET_DOUBLES)
        # the firmware's packet, whole (packets.MOTOR_STRUCT): 4 motor commands, then the rate loop's
        # set point (3) and P, I, D, F per axis (12)
        self.block = np.zeros(MOTOR_STRUCT.size, dtype=np.uint8)
        self.motors = self.block.view(np.float32)
        self.log = np.empty((4096, MOCAP_COLUMNS))
        # the compiled loop's state (frames.S_*), constants and scratch; the radio's latency queue is a ring
        self._st = np.zeros(fr.N_ST, dtype=np.int64)
        self._fst = np.zeros(fr.N_FST)
        self._max_latency_steps = latency_steps  # the radio's latency queue is sized for this
        queue = latency_steps // self.frame_steps + 4
        self._queue_due = np.zeros(queue, dtype=np.int64)
        self._queue_rc = np.zeros((queue, 16), dtype=np.int64)
        self._rc_block = np.zeros(RC_STRUCT.size, dtype=np.uint8)  # (0.0, 16 channels): the RC packet
        self._rc_words = self._rc_block.view(np.uint16)
        self._noise_buffer = np.zeros((self.frame_steps, 6))
        self._mocap_noise = np.zeros((self.frame_steps // self.mocap_every + 2, 6))
        self._scratch = np.zeros(22)  # the loop's estimate, sticks, command and quaternion
        self._no_record = np.empty((0, 1 + N_STATE))
        self._no_pilot = (np.zeros(fr.N_PILOT), np.zeros(3), np.zeros(3), np.zeros(4), np.zeros(8))
        self._no_program = (np.zeros((1, 4)), np.zeros(1), np.zeros((1, 3)), np.zeros(12), np.zeros(10), np.zeros(6))
        volume = params.volume
        self._volume = np.array([volume.x_m, volume.y_m, volume.z_m], dtype=float)
        mc = params.motion_capture
        self._fcfg = np.zeros(fr.N_FCFG)
        self._fcfg[fr.Q_STEP_S] = self.step_s
        self._fcfg[fr.Q_DROP_PROBABILITY] = params.radio.drop_probability
        self._fcfg[fr.Q_POSITION_NOISE_M] = mc.position_noise_m
        self._fcfg[fr.Q_ATTITUDE_NOISE_RAD] = mc.attitude_noise_rad
        self._fcfg[fr.Q_MOCAP_LATENCY_S] = mc.latency_s
        self._cfg = np.zeros(fr.N_CFG, dtype=np.int64)
        self._cfg[fr.K_EVERY] = self.mocap_every
        self._cfg[fr.K_LATENCY_STEPS] = latency_steps
        self._cfg[fr.K_SENSOR_NOISE] = int(params.sensors.gyro_noise_rad_s != 0.0
                                           or params.sensors.accel_noise_m_s2 != 0.0)
        self._cfg[fr.K_WAIT_NS] = int(_SLICE_S * 1e9)
        prime(self.x, self.plant, self.aux, self.counters, self._noise(1)[0], self.packet, self.scratch)
        self.firmware_cpu_s: float | None = None
        self.spun = (0.0, 0.0)
        self.choices: SpinChoices | None = None
        self.cores: CorePair | None = None
        """The cores held for the driver's thread and the firmware (spinning shared memory, ``pin_cores``)."""
        if fw.exchange is Exchange.SHM:
            self._cfg[fr.K_EXCHANGE] = fr.X_SHM
            # a negative budget: the exchange measures whether spinning pays (shm_exchange.c, choose_spin)
            self._cfg[fr.K_SPIN_NS] = round(fw.spin_us * 1e3) * (-1 if fw.spin is SpinPolicy.MEASURED else 1)
        from aerobat.plants.betaflight.frame_loop import fly_frames

        self._fly_frames = fly_frames
        self.compiled_calls = 0
        """Calls into the compiled frame loop so far (Python's turns in the flight)."""
        # compiled (or loaded from numba's cache) before the firmware starts, not in its first frame: a
        # real-time world would miss its first seconds (a run of no frames flies nothing)
        self._compiled(Mode.STEPS, 0, self.frame_steps, Radio.NONE, 0, False, Until.NONE,
                       np.full((1, 16), 1000, dtype=np.int64), self._no_pilot, self._no_program, self._no_record)
        self.sitl = SitlProcess(binary, eeprom, gyro_rate_hz=fw.gyro_rate_hz, step_timeout_s=fw.step_timeout_s,
                                exchange=fw.exchange, spin_us=fw.spin_us)
        if fw.exchange is Exchange.SHM and fw.spin_us > 0 and fw.pin_cores and self.sitl.pid is not None:
            self.cores = claim_core_pair(self.sitl.pid)
        self._cfg[fr.K_STATE_FD], self._cfg[fr.K_MOTOR_FD] = self.sitl.socket_fds
        self._cfg[fr.K_RC_FD] = self.sitl.rc_socket_fd

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        """Kill the firmware and release its ports and files (idempotent)."""
        self.firmware_cpu_s = self.firmware_cpu_time_s()
        self.spun = self.spun_s()
        self.choices = self.spin_choices()
        self.sitl.close()
        if self.cores is not None:
            self.cores.release()

    def firmware_cpu_time_s(self) -> float | None:
        """CPU time the firmware process has used so far [s] (after :meth:`close`: at its end; None if unknown)."""
        now = self.sitl.cpu_time_s()
        return now if now is not None else self.firmware_cpu_s

    def spun_s(self) -> tuple[float, float]:
        """(firmware, driver) time spent spinning in the shared-memory waits so far [s] (zeros over UDP).

        After :meth:`close`: at its end.
        """
        now = self.sitl.spun_s()
        return self.spun if math.isnan(now[0]) else now

    def spin_choices(self) -> SpinChoices | None:
        """What the driver's measured spin policy chose so far (after :meth:`close`: at its end; None: not
        measured, over UDP or with a fixed policy)."""
        if self._cfg[fr.K_SPIN_NS] >= 0:
            return None
        now = self.sitl.spin_choices()
        return now if now is not None else self.choices

    def __enter__(self) -> Flight:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # ------------------------------------------------------------------ time
    @property
    def tick(self) -> int:
        """Gyro steps since power-on."""
        return int(self._st[fr.S_TICK])

    @property
    def time_s(self) -> float:
        """Simulated time since power-on [s]."""
        return self.tick * self.step_s

    @property
    def on_floor(self) -> bool:
        return bool(self.counters[C_CONTACT])

    @property
    def latency_steps(self) -> int:
        """The radio link's latency in gyro steps (a replay sets 0: its frames act at once)."""
        return int(self._cfg[fr.K_LATENCY_STEPS])

    @latency_steps.setter
    def latency_steps(self, steps: int) -> None:
        if not 0 <= steps <= self._max_latency_steps:  # the queue is sized for the configured latency
            raise ValueError(f"latency of {steps} steps: 0 to {self._max_latency_steps} allowed")
        self._cfg[fr.K_LATENCY_STEPS] = steps

    @property
    def log_count(self) -> int:
        """Motion-capture samples taken so far (rows of :attr:`log`)."""
        return int(self._st[IO_LOG])

    @property
    def frames_sent(self) -> int:
        """Radio frames sent so far (lost ones included)."""
        return int(self._st[fr.S_SENT])

    @property
    def frames_dropped(self) -> int:
        """Radio frames the radio lost so far."""
        return int(self._st[fr.S_DROPPED])

    @property
    def frames_queued(self) -> int:
        """Radio frames on their way (sent, not yet delivered: the link latency)."""
        return int(self._st[fr.S_Q_COUNT])

    def _noise(self, n: int) -> np.ndarray:
        if self.params.sensors.gyro_noise_rad_s == 0.0 and self.params.sensors.accel_noise_m_s2 == 0.0:
            return np.zeros((n, 6))
        return self.rng.standard_normal((n, 6))

    def frame(self, channels_us: Sequence[int], *, lossless: bool = False) -> None:
        """Send one radio frame and fly one frame period.

        The frame is lost with the radio's drop probability (``lossless``: never, e.g. a radio
        that stopped altogether is modelled by its channels instead) and otherwise reaches the
        receiver after the link latency.
        """
        self.run_frames(Mode.STREAM, 1, channels_us=np.array([channels_us], dtype=np.int64),
                        radio=Radio.LOSSLESS if lossless else Radio.LOSSY)

    def advance(self, steps: int) -> None:
        """Fly ``steps`` gyro periods with no radio frame: the receiver gets its frames another way.

        A real-time rehearsal sends its sticks as MSP over the firmware's UART
        (:mod:`aerobat.plants.fc`); this keeps the UDP receiver silent, so the firmware's
        receiver stays MSP, its default.
        """
        self.run_frames(Mode.STEPS, 1, steps=steps, radio=Radio.NONE)

    def release(self) -> None:
        """Take the floor away: from now on the vehicle flies free, as in the air (a replayed flight).

        Arm on the floor first (the firmware calibrates its gyro standing still), then release.
        """
        self.aux[A_GROUND] = -math.inf
        self.counters[C_CONTACT] = 0

    def sampled_frame(self, channels_us: Sequence[int], rows: np.ndarray) -> None:
        """One lossless radio frame, sampled: ``rows`` (k, :data:`N_SAMPLE`) gets k evenly spaced samples of the frame.

        Row j (columns ``SAMPLE_*``: time [s], true body rates p, q, r [rad/s] FLU, the firmware's four motor
        commands in packet order, its set point roll, pitch, yaw [deg/s], P, I, D, F of roll, pitch, yaw, and
        the gyro the firmware reads, FLU [rad/s]) is taken after the frame's (j + 1)-th k-th part; k must
        divide the frame's gyro periods.
        """
        parts = rows.shape[0]
        if self.frame_steps % parts:
            raise ValueError(f"{parts} samples do not divide a frame of {self.frame_steps} gyro periods")
        channels = np.array([channels_us], dtype=np.int64)
        for j in range(parts):
            self.run_frames(Mode.STREAM if j == 0 else Mode.STEPS, 1, steps=self.frame_steps // parts,
                            channels_us=channels, radio=Radio.LOSSLESS if j == 0 else Radio.NONE)
            rows[j, SAMPLE_TIME] = self.time_s
            rows[j, SAMPLE_RATES] = self.x[10:13]
            rows[j, SAMPLE_MOTORS.start:SAMPLE_PID.stop] = self.motors  # the motor packet: motors, set point, PID
            gyro = self.packet[1:4]  # the state packet's gyro, FRD (p, −q, −r)
            rows[j, SAMPLE_GYRO] = gyro[0], -gyro[1], -gyro[2]

    def run_frames(self, mode: Mode, frames: int, *, steps: int | None = None, radio: Radio = Radio.LOSSY,
                   channels_us: np.ndarray | None = None, pilot: AnglePilot | ProgramPilot | None = None,
                   check: bool = False, until: Until = Until.NONE, record: np.ndarray | None = None) -> FramesRun:
        """Fly up to ``frames`` radio frames of ``steps`` gyro periods (default: one frame period) in compiled code.

        ``mode`` says where each frame's channels come from: ``channels_us`` (k, 16) [us], a row per
        frame or one for all (:attr:`Mode.STREAM`), or ``pilot``'s sticks (:attr:`Mode.ANGLE`: an
        :class:`~aerobat.plants.fpv.frames.AnglePilot`; :attr:`Mode.PROGRAM`: a
        :class:`~aerobat.plants.fpv.frames.ProgramPilot`);
        ``radio`` what the radio does with them. After each frame: a truth row into ``record``
        (frames, 1 + state: time [s], true state; with :data:`N_PACKET` more columns, the firmware's
        motor packet after it: motors, set point, PID terms as in :data:`SAMPLE_MOTORS` on), the
        flight-volume check around the start (``check``: the floor or a motion-capture sample
        outside ``params.volume`` ends the run) and the stop condition ``until``.

        Raises :class:`~aerobat.firmware.betaflight.errors.FirmwareNotResponding` (the watchdog) and :class:`NonFinite`.
        """
        steps = self.frame_steps if steps is None else int(steps)
        if steps < 1 or frames < 0:
            raise ValueError(f"{frames} frames of {steps} gyro periods: both must be positive")
        if mode is Mode.ANGLE and not isinstance(pilot, AnglePilot):
            raise ValueError("Mode.ANGLE needs an AnglePilot")
        if mode is Mode.PROGRAM and not (isinstance(pilot, ProgramPilot) and pilot.commands.shape == (frames, 4)):
            raise ValueError(f"Mode.PROGRAM needs a ProgramPilot with ({frames}, 4) commands")
        if mode is not Mode.STEPS and channels_us is None and pilot is None:
            raise ValueError(f"{mode.name} needs the channels")
        if record is not None and record.shape not in ((frames, 1 + N_STATE), (frames, 1 + N_STATE + N_PACKET)):
            raise ValueError(f"record must be ({frames}, {1 + N_STATE}) or ({frames}, {1 + N_STATE + N_PACKET}), "
                             f"not {record.shape}")
        if steps > self._noise_buffer.shape[0]:
            self._noise_buffer = np.zeros((steps, 6))
            self._mocap_noise = np.zeros((steps // self.mocap_every + 2, 6))
        program = self._no_program
        if isinstance(pilot, AnglePilot):
            floats = np.zeros(fr.N_PILOT)
            floats[:fr.P_SETTLE_HOLD + 1] = (pilot.period_s, pilot.settle_position_m, pilot.settle_velocity_m_s,
                                             pilot.settle_tilt_rad, float(pilot.settle_hold_frames))
            arrays = (floats, np.asarray(pilot.target_m, dtype=float), pilot.integral, pilot.gains, pilot.limits)
        elif isinstance(pilot, ProgramPilot):
            floats = np.zeros(fr.N_PILOT)
            floats[fr.P_PERIOD_S] = pilot.period_s
            arrays = (floats, *self._no_pilot[1:4], pilot.limits)
            commands = np.ascontiguousarray(pilot.commands, dtype=float)
            law = pilot.law
            if law is not None:
                floats[fr.P_FEEDBACK] = 1.0
                floats[[fr.P_DURATION_S, fr.P_START_TIME_S, fr.P_AHEAD_S, fr.P_REFERENCE_DT_S, fr.P_LAW_LATENCY_S]] = (
                    law.duration_s, law.start_time_s, law.ahead_s, law.reference_dt_s, law.mocap_latency_s)
                program = (commands, law.gains, np.ascontiguousarray(law.reference), law.state, np.empty(10),
                           np.empty(6))
            else:
                program = (commands, *self._no_program[1:])
        else:
            arrays = self._no_pilot
        if pilot is not None:
            channels = np.array([pilot.channels_us], dtype=np.int64) if channels_us is None else channels_us
        else:
            channels = channels_us if channels_us is not None else np.full((1, 16), 1000, dtype=np.int64)
        channels = np.ascontiguousarray(channels, dtype=np.int64)
        many = channels.shape[0] > 1
        if many and channels.shape[0] != frames:
            raise ValueError(f"{channels.shape[0]} rows of channels for {frames} frames")
        self._st[fr.S_CALM] = 0
        self._fst[:] = (math.nan, 0.0, 0.0)
        done, resume = 0, 0
        status = DONE
        while done < frames:
            chunk = min(CHUNK_FRAMES, frames - done)
            self._reserve_log(chunk * (steps // self.mocap_every + 2))
            address = self.sitl.shm_address
            self._cfg[fr.K_SHM] = address if address is not None else 0
            if mode is Mode.PROGRAM:
                arrays[0][fr.P_FIRST_FRAME] = done
            status, flown = self._compiled(mode, chunk, steps, radio, resume, check, until,
                                           channels[done:done + chunk] if many else channels, arrays,
                                           (program[0][done:done + chunk], *program[1:])
                                           if mode is Mode.PROGRAM else program,
                                           record[done:done + chunk] if record is not None else self._no_record)
            self.sitl.steps += int(self._st[IO_EXCHANGES])
            self._st[IO_EXCHANGES] = 0
            done += int(flown)
            resume = 0
            if status == DONE:
                continue
            if status == NO_ANSWER:  # the watchdog finishes the exchange (or raises)
                self.sitl.receive_into(self.block)
                resume = int(self._st[IO_RESUME])
            elif status == SEND_FAILED:
                self.sitl.exchange(self.packet, self.block)
                resume = RESUME_STEP
            elif status == fr.RC_FAILED:  # the Python send raises the right error, or gets it through
                head = int(self._st[fr.S_Q_HEAD])
                self.sitl.send_rc(tuple(int(c) for c in self._queue_rc[head]))
                self._st[fr.S_Q_HEAD] = (head + 1) % self._queue_due.shape[0]
                self._st[fr.S_Q_COUNT] -= 1
            elif status == NON_FINITE:
                self._st[fr.S_TICK] += self._st[fr.S_STEP] + 1
                self._st[fr.S_IN_FRAME] = 0
                raise NonFinite(f"non-finite vehicle state at t = {self.time_s:.4f} s")
            elif status == fr.QUEUE_FULL:
                raise RuntimeError(f"the radio's latency queue ({self._queue_due.shape[0]} frames) overflowed")
            else:
                break
        airborne = None if math.isnan(self._fst[fr.F_AIRBORNE_S]) else float(self._fst[fr.F_AIRBORNE_S])
        end = {DONE: FramesEnd.DONE, fr.UNTIL_MET: FramesEnd.MET, fr.CRASH_FLOOR: FramesEnd.FLOOR,
               fr.CRASH_VOLUME: FramesEnd.VOLUME}[status]
        return FramesRun(end, done, int(self._st[fr.S_AXIS]) if end is FramesEnd.VOLUME else None, airborne,
                         float(self._fst[fr.F_WORST_MEASURED_M]), float(self._fst[fr.F_WORST_TRUE_M]))

    def _compiled(self, mode: Mode, frames: int, steps: int, radio: Radio, resume: int, check: bool, until: Until,
                  channels: np.ndarray, pilot: tuple[np.ndarray, ...], program: tuple[np.ndarray, ...],
                  record: np.ndarray) -> tuple[int, int]:
        self.compiled_calls += 1
        return self._fly_frames(  # type: ignore[no-any-return, call-arg]
            int(mode), frames, steps, int(radio), resume, check, int(until), self.rng, self._cfg, self._fcfg,
            self._st, self._fst, self.x, self.block, self.motors, self.plant, self.aux, self.pending,
            self.counters, self.packet, self.scratch, self._noise_buffer, self._mocap_noise, self.log,
            self._queue_due, self._queue_rc, self._rc_block, self._rc_words, channels, *pilot, self.start_m,
            self._volume, record, self._scratch, *program)

    def _reserve_log(self, rows: int) -> None:
        count = self.log_count
        if count + rows > self.log.shape[0]:
            grown = np.empty((2 * self.log.shape[0] + rows, MOCAP_COLUMNS))
            grown[:count] = self.log[:count]
            self.log = grown

    # ------------------------------------------------------------------ measurement
    def estimate(self, pos: np.ndarray, vel: np.ndarray, quat: np.ndarray) -> bool:
        """The supervisor's estimate now: the arena's fit over mocap samples older than the latency."""
        available = self.time_s - self.params.motion_capture.latency_s + 1e-12
        rows = int(np.searchsorted(self.log[: self.log_count, 0], available, side="right"))
        return bool(estimate_pose(self.log, rows, pos, vel, quat))

    def mocap(self) -> np.ndarray:
        """The motion-capture log so far: rows (t, x, y, z, qw, qx, qy, qz)."""
        return self.log[: self.log_count]

    def motor_commands(self) -> tuple[float, float, float, float]:
        """The firmware's latest motor packet (0 = stopped, ``motor_idle`` = armed idle)."""
        return (float(self.motors[0]), float(self.motors[1]), float(self.motors[2]), float(self.motors[3]))

    def truth(self) -> np.ndarray:
        """A copy of the true state (aerobat layout; thrust slots in Betaflight packet order)."""
        return self.x.copy()

    def frames_for(self, seconds: float) -> int:
        """Radio frames in ``seconds`` (at least one)."""
        return max(1, math.ceil(seconds * self.params.radio.rate_hz - 1e-9))
