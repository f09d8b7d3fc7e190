"""One flight: a firmware process, the physical world around it, the radio and motion capture.

:class:`Flight` owns a fresh :class:`~.sitl.SitlProcess` and steps it in lockstep with
:func:`.physics.step`: one state packet out, one motor packet back, one gyro period of physics.
Time advances in radio frames: :meth:`Flight.frame` takes the channels the ground sends for one
frame period; the radio drops the frame with the configured probability (seeded) or delivers it
after the link latency, right before the state packet of the step it arrives in. Motion capture
samples the true state at its rate with seeded noise into a log the supervisor reads with its
latency. Nothing here decides what to fly: that is the plant's supervisor.

The steps of a frame run in one compiled loop (:mod:`.lockstep`: motion capture, the exchange
through the C library's ``send``/``recv`` on the process's sockets, the physics; or
:mod:`.lockstep_shm`, the same over shared memory with ``firmware.exchange = "shm"``), split only
where an RC frame is due; the process's watchdog takes over whenever an answer is late.

Everything random comes from the generator passed in, so a seed repeats a flight bit for bit;
the firmware is deterministic in lockstep.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from aerobat.errors import ConfigError
from aerobat.plants.betaflight.lockstep import (
    IO_EXCHANGES,
    IO_LOG,
    IO_MOCAP_USED,
    N_IO,
    NO_ANSWER,
    NON_FINITE,
    SEND_FAILED,
    run_steps,
)
from aerobat.plants.betaflight.packets import MOTOR_STRUCT, Exchange
from aerobat.plants.betaflight.params import BetaflightParams
from aerobat.plants.betaflight.physics import (
    A_GROUND,
    C_CONTACT,
    C_DELAY,
    C_TICK,
    N_COUNTERS,
    PACKET_DOUBLES,
    aux_vector,
    ground_state,
    prime,
)
from aerobat.plants.betaflight.sitl import SitlProcess
from aerobat.plants.lab_kernels import MOCAP_COLUMNS, estimate_pose
from aerobat.quadrotor.dynamics import N_STATE

__all__ = ["Flight", "NonFinite"]

_SLICE_S = 0.05  # the compiled shared-memory wait's timeout: then the watchdog takes the step


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
        self.latency_steps = round(params.radio.latency_s / self.step_s)
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
        self.scratch = np.zeros((6, N_STATE))
        self.packet = np.zeros(PACKET_DOUBLES)
        # the firmware's packet, whole (packets.MOTOR_STRUCT): 4 motor commands, then the rate loop's
        # set point (3) and P, I, D, F per axis (12)
        self.block = np.zeros(MOTOR_STRUCT.size, dtype=np.uint8)
        self.motors = self.block.view(np.float32)
        self._io = np.zeros(N_IO, dtype=np.int64)
        self.tick = 0
        self.log = np.empty((4096, MOCAP_COLUMNS))
        self.log_count = 0
        self._queue: list[tuple[int, tuple[int, ...]]] = []
        self.frames_sent = 0
        self.frames_dropped = 0
        prime(self.x, self.plant, self.aux, self.counters, self._noise(1)[0], self.packet, self.scratch)
        self.firmware_cpu_s: float | None = None
        self.spun = (0.0, 0.0)
        self._run_steps = run_steps
        if fw.exchange is Exchange.SHM:  # loaded (and its C helper built) before a firmware starts
            from aerobat.plants.betaflight import shm
            from aerobat.plants.betaflight.lockstep_shm import run_steps_shm

            wait_ns, spin_ns = int(_SLICE_S * 1e9), int(shm.SPIN_S * 1e9)

            def run_shm(_state_fd: int, _motor_fd: int, first: int, *args: object) -> tuple[int, int]:
                address = self.sitl.shm_address
                if address is None:  # closed: the Python exchange raises
                    return SEND_FAILED, first
                return run_steps_shm(address, spin_ns, wait_ns, first, *args)  # type: ignore[no-any-return]

            self._run_steps = run_shm  # type: ignore[assignment]
        self.sitl = SitlProcess(binary, eeprom, gyro_rate_hz=fw.gyro_rate_hz, step_timeout_s=fw.step_timeout_s,
                                exchange=fw.exchange)

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        """Kill the firmware and release its ports and files (idempotent)."""
        self.firmware_cpu_s = self.firmware_cpu_time_s()
        self.spun = self.spun_s()
        self.sitl.close()

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

    def __enter__(self) -> Flight:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # ------------------------------------------------------------------ time
    @property
    def time_s(self) -> float:
        """Simulated time since power-on [s]."""
        return self.tick * self.step_s

    @property
    def on_floor(self) -> bool:
        return bool(self.counters[C_CONTACT])

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
        dropped = not lossless and self.rng.random() < self.params.radio.drop_probability
        self.frames_sent += 1
        if dropped:
            self.frames_dropped += 1
        else:
            self._queue.append((self.tick + self.latency_steps, tuple(int(c) for c in channels_us)))
        self._advance(self.frame_steps)

    def advance(self, steps: int) -> None:
        """Fly ``steps`` gyro periods with no radio frame: the receiver gets its frames another way.

        A real-time rehearsal sends its sticks as MSP over the firmware's UART
        (:mod:`aerobat.plants.fc`); this keeps the UDP receiver silent, so the firmware's
        receiver stays MSP, its default.
        """
        self._advance(steps)

    def release(self) -> None:
        """Take the floor away: from now on the vehicle flies free, as in the air (a replayed flight).

        Arm on the floor first (the firmware calibrates its gyro standing still), then release.
        """
        self.aux[A_GROUND] = -math.inf
        self.counters[C_CONTACT] = 0

    def sampled_frame(self, channels_us: Sequence[int], rows: np.ndarray) -> None:
        """One lossless radio frame, sampled: ``rows`` (k, 23) gets k evenly spaced samples of the frame.

        Row j is (time [s], true body rates p, q, r [rad/s] FLU, the firmware's four motor commands in
        packet order, its set point roll, pitch, yaw [deg/s] and P, I, D, F of roll, pitch, yaw) after
        the frame's (j + 1)-th k-th part; k must divide the frame's gyro periods.
        """
        parts = rows.shape[0]
        if self.frame_steps % parts:
            raise ValueError(f"{parts} samples do not divide a frame of {self.frame_steps} gyro periods")
        self.frames_sent += 1
        self._queue.append((self.tick + self.latency_steps, tuple(int(c) for c in channels_us)))
        for j in range(parts):
            self._advance(self.frame_steps // parts)
            rows[j, 0] = self.time_s
            rows[j, 1:4] = self.x[10:13]
            rows[j, 4:23] = self.motors

    def _advance(self, n: int) -> None:
        noise = self._noise(n)
        mc = self.params.motion_capture
        rows = n // self.mocap_every + 2
        if self.log_count + rows > self.log.shape[0]:
            grown = np.empty((2 * self.log.shape[0] + rows, MOCAP_COLUMNS))
            grown[: self.log_count] = self.log[: self.log_count]
            self.log = grown
        mocap_noise = np.zeros((rows, 6))
        if mc.position_noise_m:
            mocap_noise[:, :3] = mc.position_noise_m * self.rng.standard_normal((rows, 3))
        if mc.attitude_noise_rad:
            mocap_noise[:, 3:] = mc.attitude_noise_rad * self.rng.standard_normal((rows, 3))
        io = self._io
        io[IO_LOG] = self.log_count
        io[IO_MOCAP_USED] = 0
        io[IO_EXCHANGES] = 0
        sitl = self.sitl
        state_fd, motor_fd = sitl.socket_fds
        queue = self._queue
        tick0 = self.tick
        i, resume = 0, False
        try:
            while i < n:
                if not resume:
                    while queue and queue[0][0] <= tick0 + i:  # RC frames reach the receiver first
                        sitl.send_rc(queue.pop(0)[1])
                stop = min(n, queue[0][0] - tick0) if queue else n
                status, i = self._run_steps(state_fd, motor_fd, i, stop, resume, tick0, self.mocap_every,
                                            self.step_s, self.x, self.block, self.motors, self.plant, self.aux,
                                            self.pending, self.counters, noise, mocap_noise, self.log, io,
                                            self.packet, self.scratch)
                resume = False
                if status == NO_ANSWER:  # the watchdog finishes the exchange (or raises)
                    sitl.receive_into(self.block)
                    resume = True
                elif status == SEND_FAILED:
                    sitl.exchange(self.packet, self.block)
                    resume = True
                elif status == NON_FINITE:
                    self.tick = tick0 + i + 1
                    raise NonFinite(f"non-finite vehicle state at t = {self.tick * self.step_s:.4f} s")
        finally:
            self.log_count = int(io[IO_LOG])
            sitl.steps += int(io[IO_EXCHANGES])
        self.tick = tick0 + n
        assert int(self.counters[C_TICK]) == self.tick

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
