"""The firmware design model: the paper's method designing on the flight controller that flies the maneuver.

:class:`FirmwareModel` implements the design's ``FinalStateModel`` protocol
(:class:`aerobat.core.design.FinalStateModel`): a batch of programs in, their final states out,
each program flown from hover through Betaflight 4.6's stick-to-motor path as a compiled model
(:mod:`aerobat.quadrotor.firmware.flight`) around an X-frame airframe
(:class:`aerobat.quadrotor.xframe.Airframe`).

Two fidelities (:class:`Fidelity`). ``EXACT`` is the firmware step for step: the integer steps
(1 µs pulses, the integer throttle map, the gyro's LSB, the motor packet's whole microseconds)
and feedforward's treatment of a repeated frame (4.6 extrapolates the first repeat and zeroes the
next with any receiver but CRSF). Its final state jumps by centimetres where a switch crosses a
radio frame's boundary or a pulse its half microsecond, so ``DESIGN`` (the default) leaves those
out: the integer steps by their mean effect, every frame as news (as a CRSF receiver gives them).
It is smooth in the program's parameters, which Newton's method and finite differences need; what
it leaves out is measured against ``EXACT`` and the SITL (docs/plants.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from aerobat.config import check_type
from aerobat.errors import ConfigError
from aerobat.quadrotor.dynamics import N_STATE, P_GRAV
from aerobat.quadrotor.firmware.config import FirmwareConfig
from aerobat.quadrotor.firmware.flight import (
    A_BATTERY,
    A_CURVE_K,
    A_CURVE_R,
    A_FMAX,
    A_ROTOR_J,
    A_SPIN,
    A_THRUST_COEF,
    N_AIRFRAME,
    N_RECORD,
    fly,
    work_size,
)
from aerobat.quadrotor.firmware.layout import N_MEMORY, Q_ALL, constants
from aerobat.quadrotor.firmware.loop import hover
from aerobat.quadrotor.firmware.sticks import N_LIMITS
from aerobat.quadrotor.program import CompiledProgram, Program
from aerobat.quadrotor.simulate import batch_threads
from aerobat.quadrotor.xframe import Airframe, sagging_command, xframe_plant

__all__ = ["Fidelity", "FirmwareModel", "FirmwareTrajectory"]


class Fidelity(StrEnum):
    """How closely the firmware model follows the firmware's discrete steps."""

    DESIGN = "design"
    """Smooth in the program: integer steps by their mean effect, every radio frame news."""
    EXACT = "exact"
    """Step for step: every integer step, and repeated frames as the firmware treats them."""


@dataclass(frozen=True)
class FirmwareTrajectory:
    """A program flown by the firmware model, one row per gyro period.

    Attributes
    ----------
    times_s : (n,) from the program's start [s].
    states : (n, N_STATE) true states.
    motors : (n, 4) the firmware's motor packet (slot order, 0..1).
    setpoint_deg_s : (n, 3) the set point the PID tracked (roll, pitch, yaw; firmware axes).
    pid : (n, 4, 3) P, I, D, F (rows) per axis (columns), Betaflight's units.
    """

    times_s: np.ndarray
    states: np.ndarray
    motors: np.ndarray
    setpoint_deg_s: np.ndarray
    pid: np.ndarray


class FirmwareModel:
    """Φ(p): programs flown from hover through a Betaflight configuration around an X-frame airframe.

    Parameters
    ----------
    firmware : the configuration the firmware runs.
    airframe : the vehicle (rigid body, rotor layout, thrust curve, motor lag, rotor inertia, output delay).
    sticks : the ground station's stick map (:data:`aerobat.quadrotor.firmware.sticks.N_LIMITS` floats:
        rate curves inverted, collective to throttle).
    radio_rate_hz : radio frames per second (a frame carries the program's mean over its period).
    gravity_m_s2 : gravity.
    aerodynamics : :func:`aerobat.quadrotor.dynamics.plant_vector`'s drag keywords, if the vehicle has them.
    fidelity : :class:`Fidelity` (default ``DESIGN``: smooth in the program).
    description : one line for reports (what the model is built from).
    """

    def __init__(self, firmware: FirmwareConfig, airframe: Airframe, sticks: np.ndarray, *, radio_rate_hz: float,
                 gravity_m_s2: float = 9.81, aerodynamics: dict[str, Any] | None = None,
                 fidelity: Fidelity | str = Fidelity.DESIGN, description: str = "") -> None:
        self.firmware = check_type("firmware", firmware, FirmwareConfig, "a FirmwareConfig")
        self.airframe = check_type("airframe", airframe, Airframe, "an Airframe")
        sticks = np.asarray(sticks, dtype=float)
        if sticks.shape != (N_LIMITS,):
            raise ConfigError(f"sticks: expected the stick map's {N_LIMITS} numbers, got shape {sticks.shape}")
        if not (isinstance(radio_rate_hz, int | float) and 0.0 < radio_rate_hz <= firmware.gyro_rate_hz):
            raise ConfigError(f"radio_rate_hz = {radio_rate_hz!r}: allowed (0, {firmware.gyro_rate_hz}] Hz")
        self.sticks = sticks
        try:
            self.fidelity = Fidelity(fidelity)
        except ValueError:
            raise ConfigError(f"fidelity = {fidelity!r}: one of {', '.join(f.value for f in Fidelity)}") from None
        self.description = description
        self.gravity_m_s2 = float(gravity_m_s2)
        self.steps_per_frame = max(1, int(round(firmware.gyro_rate_hz / radio_rate_hz)))
        self.radio_period_s = self.steps_per_frame * firmware.gyro_period_s
        self.delay_steps = int(round(airframe.output_delay_s * firmware.gyro_rate_hz))
        exact = self.fidelity is Fidelity.EXACT
        self.k = constants(firmware, radio_period_s=self.radio_period_s, quantize=Q_ALL if exact else 0,
                           duplicates=exact)
        self.aerodynamics = dict(aerodynamics or {})
        self.plant = xframe_plant(airframe, **self.aerodynamics)
        self.plant[P_GRAV] = self.gravity_m_s2
        self.frame = np.zeros(N_AIRFRAME)
        self.frame[A_FMAX] = airframe.thrust_max_n
        self.frame[A_CURVE_R] = airframe.curve_min_speed_ratio
        self.frame[A_CURVE_K] = airframe.curve_shape
        self.frame[A_ROTOR_J] = airframe.rotor_inertia_kg_m2
        self.frame[A_THRUST_COEF] = airframe.thrust_coefficient_n_s2
        self.frame[A_SPIN:A_SPIN + 4] = [1.0 if ccw else -1.0 for ccw in airframe.spins_ccw]
        self.frame[A_BATTERY:A_BATTERY + 3] = airframe.battery_constants()
        self.hover_thrust_n = airframe.mass_kg * self.gravity_m_s2 / 4.0
        if self.hover_thrust_n >= airframe.thrust_max_n:
            raise ConfigError(f"airframe: {airframe.mass_kg} kg cannot hover on four rotors of "
                              f"{airframe.thrust_max_n} N")
        u = _hover_command(airframe, self.hover_thrust_n)
        self.hover_packet = np.full(4, u)
        self.memory = np.zeros(N_MEMORY)
        hover(self.k, self.memory, u)

    def __repr__(self) -> str:
        return f"FirmwareModel({self.description or self.firmware.source!r})"

    def hover_state(self) -> np.ndarray:
        """Level hover at the origin, each rotor at the hover thrust."""
        x = np.zeros(N_STATE)
        x[6] = 1.0
        x[13:17] = self.hover_thrust_n
        return x

    def _fly_one(self, program: CompiledProgram, x0: np.ndarray, record: np.ndarray) -> np.ndarray:
        x = np.array(x0, dtype=float)
        memory = self.memory.copy()
        duration = program.duration_s
        work = np.empty(work_size(duration, self.radio_period_s, self.delay_steps, N_STATE))
        status = fly(program.breakpoints_s, program.coefficients, program.hover, self.steps_per_frame, duration,
                     self.k, memory, x, self.plant, self.frame, self.sticks, self.hover_packet, self.delay_steps,
                     work, record)
        if status != 0:
            x[:] = np.nan
        return x

    def final_states(self, programs: Sequence[Program | CompiledProgram],
                     initial_states: np.ndarray | None = None) -> np.ndarray:
        """(B, N_STATE) states at each program's end, from hover (or ``initial_states``, the firmware in hover)."""
        compiled = [_compiled(p, f"programs[{i}]") for i, p in enumerate(programs)]
        count = len(compiled)
        if initial_states is None:
            starts = np.tile(self.hover_state(), (count, 1))
        else:
            starts = np.asarray(initial_states, dtype=float)
            if starts.shape != (count, N_STATE):
                raise ConfigError(f"initial_states: expected ({count}, {N_STATE}), got {starts.shape}")
        out = np.empty((count, N_STATE))
        empty = np.empty((0, N_RECORD))

        def run(rows: np.ndarray) -> None:
            for i in rows:
                out[i] = self._fly_one(compiled[i], starts[i], empty)

        threads = min(count, batch_threads())
        if threads <= 1:
            run(np.arange(count))
            return out
        with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="aerobat-firmware") as pool:
            for job in [pool.submit(run, rows) for rows in np.array_split(np.arange(count), min(count, 4 * threads))]:
                job.result()
        return out

    def trajectory(self, program: Program | CompiledProgram, initial_state: np.ndarray | None = None
                   ) -> FirmwareTrajectory:
        """The whole flight of ``program``: every gyro period's state, motor packet, set point and PID terms."""
        compiled = _compiled(program, "program")
        steps = int(math.floor(compiled.duration_s / self.firmware.gyro_period_s + 1e-9)) + 1
        record = np.full((steps + 1, N_RECORD), np.nan)
        x0 = self.hover_state() if initial_state is None else np.asarray(initial_state, dtype=float)
        record[0, 0] = 0.0
        record[0, 1:21] = x0
        record[0, 21:25] = self.hover_packet
        record[0, 25:] = 0.0
        self._fly_one(compiled, x0, record)
        rows = record[np.isfinite(record[:, 0])]
        return FirmwareTrajectory(times_s=rows[:, 0], states=rows[:, 1:21], motors=rows[:, 21:25],
                                  setpoint_deg_s=rows[:, 25:28], pid=rows[:, 28:40].reshape(-1, 4, 3))


def _compiled(program: Any, name: str) -> CompiledProgram:
    if isinstance(program, CompiledProgram):
        return program
    if isinstance(program, Program):
        return program.compile()
    raise ConfigError(f"{name}: expected a Program, got {type(program).__name__}")


def _hover_command(airframe: Airframe, thrust_n: float) -> float:
    """The motor command at which each rotor gives ``thrust_n`` [N], the battery's sag at that load included."""
    if not airframe.battery_flown:
        return airframe.command_for_thrust(thrust_n)
    return float(sagging_command(thrust_n, airframe.thrust_max_n, airframe.curve_min_speed_ratio,
                                 airframe.curve_shape, *airframe.battery_constants()))
