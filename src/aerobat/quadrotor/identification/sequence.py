"""The identification trials: short, safe programs that excite what the fit needs.

Every trial starts its excitation at t = 0 (a plant that checks its trigger by watching
for motion sees it at once) and ends in hover. Built from a *prior* vehicle, so the
amplitudes fit the vehicle one believes one has:

=====================  ======================================================================
collective steps       g + d, then g − d (d = 0.4 (β̄ − g)), then hover: collective gain, motors
collective limits      zero collective (motors at f_min, the vehicle drops), then 1.1 × what
                       saturates every motor until it has stopped, then hover: 4 f_min/m,
                       4 f_max/m, motor rates, vertical drag. It drops about half a metre.
rate doublets          per axis, +A for D then −A for D then 0: the attitude comes back level.
                       Roll and pitch at two amplitudes, 0.7 and 1.4 × the rate step the loop
                       answers without a motor reaching f_min (for 0.15 s and 0.1 s; 1.1 and
                       2.2 rad/s on Table 1, peaks of 10° and 13°, never above ``max_angle_rad``),
                       so the response is the loop's, not the motors' limits; yaw at 3 rad/s for
                       0.25 s and 1.5 rad/s for 0.35 s (a yaw step moves the two motor pairs
                       against each other, which tells uneven motors from a centre-of-mass
                       offset): rate-loop gains, latencies, moment arms, drag
slow flips             optional: one roll and one pitch flip at 720°/s designed on the prior:
                       the steady rate shortfall (damping) that short doublets hardly show
=====================  ======================================================================

:class:`IdentificationSequence` is the sequence as the store keeps a session's maneuver:
its one "parameter" is the trial number, its "errors" are how far from the start each
trial ended (x, y, z). It is not a learnable maneuver and is not registered as one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np

from aerobat.config import table_field
from aerobat.core.design import design
from aerobat.core.maneuver import ErrorKind, ErrorSpec, ParameterSpec, check_parameters
from aerobat.errors import ConfigError
from aerobat.quadrotor.dynamics import POS, hover_state
from aerobat.quadrotor.maneuvers.flip import Axis, MultiFlip
from aerobat.quadrotor.program import Program, Switch, program_from_table, program_to_table
from aerobat.quadrotor.simulate import NominalModel
from aerobat.quadrotor.vehicle import VehicleConfig, vehicle_from_table, vehicle_table

__all__ = [
    "IdentificationSequence",
    "IdentificationTrial",
    "TrialKind",
    "identification_sequence",
    "sequence_from_spec",
]


class TrialKind(StrEnum):
    """What an identification trial excites."""

    COLLECTIVE_STEPS = "collective_steps"
    COLLECTIVE_LIMITS = "collective_limits"
    ROLL_DOUBLET = "roll_doublet"
    PITCH_DOUBLET = "pitch_doublet"
    YAW_DOUBLET = "yaw_doublet"
    ROLL_FLIP = "roll_flip"
    PITCH_FLIP = "pitch_flip"

    @property
    def required(self) -> bool:
        """A fit needs at least one usable trial of this kind (flips are optional)."""
        return self not in (TrialKind.ROLL_FLIP, TrialKind.PITCH_FLIP)

    @property
    def identifies(self) -> str:
        """What only this kind of trial measures well (for refusal messages)."""
        return _IDENTIFIES[self]


_IDENTIFIES = {
    TrialKind.COLLECTIVE_STEPS: "the collective gain (hover command) and the motor rates",
    TrialKind.COLLECTIVE_LIMITS: "the collective limits 4 f_min/m and 4 f_max/m",
    TrialKind.ROLL_DOUBLET: "the roll rate-loop gain, latency and moment arm",
    TrialKind.PITCH_DOUBLET: "the pitch rate-loop gain, latency and moment arm",
    TrialKind.YAW_DOUBLET: "the yaw rate-loop gain, latency and moment arm",
    TrialKind.ROLL_FLIP: "the steady roll-rate shortfall (damping) at flip rates",
    TrialKind.PITCH_FLIP: "the steady pitch-rate shortfall (damping) at flip rates",
}


@dataclass(frozen=True, kw_only=True)
class IdentificationTrial:
    """One identification trial: what it excites and the program that does it."""

    kind: TrialKind
    name: str
    program: Program

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", TrialKind(self.kind))


def _program(name: str, switches: list[tuple[float, str, float]], duration_s: float, hover: float) -> Program:
    return Program(switches=tuple(Switch(time_s=t, channel=ch, value=float(v)) for t, ch, v in switches),
                   duration_s=duration_s, hover_collective_m_s2=hover, name=name)


def identification_sequence(prior: VehicleConfig, *, flips: bool = True, max_angle_rad: float = 0.5,
                            flip_model: Any = None) -> tuple[tuple[IdentificationTrial, ...], list[str]]:
    """The default trials for a vehicle believed to be ``prior``, and notes on any left out.

    Parameters
    ----------
    prior : the vehicle one believes one has (amplitudes and the slow flips are built on it).
    flips : include the two slow flips (roll and pitch, one turn at 720°/s).
    max_angle_rad : largest attitude a rate doublet may reach [rad] (safe angles).
    flip_model : the model the slow flips are designed on (a final-state model, e.g. the plant's
        firmware model, started from the paper model's p⁰); None: the paper's model of ``prior``.
    """
    if not 0.05 <= max_angle_rad <= 1.2:
        raise ConfigError(f"max_angle_rad = {max_angle_rad:g} is out of range: allowed [0.05, 1.2] rad")
    v, c = prior.vehicle, prior.controller
    g = v.gravity_m_s2
    tau_up = 1.0 / v.motor_rate_up_per_s
    saturate = 4.0 * v.rotor_thrust_max_n / c.mass_kg  # the command that puts every motor at f_max
    accel_max, accel_min = v.collective_max_m_s2, v.collective_min_m_s2
    trials = []
    step = 0.4 * (v.collective_reduced_max_m_s2 - g)
    hold = max(0.15, 4.0 * tau_up)
    trials.append(IdentificationTrial(kind=TrialKind.COLLECTIVE_STEPS, name="collective steps", program=_program(
        "collective steps", [(0.0, "collective", g + step), (hold, "collective", g - step),
                             (2 * hold, "collective", g)], 2 * hold + 0.5, g)))
    fall = 0.25
    arrest = fall * (g - accel_min) / (accel_max - g) + 2.0 * tau_up
    trials.append(IdentificationTrial(kind=TrialKind.COLLECTIVE_LIMITS, name="collective limits", program=_program(
        "collective limits", [(0.0, "collective", 0.0), (fall, "collective", min(1.1 * saturate, 200.0)),
                              (fall + arrest, "collective", g)], fall + arrest + 0.45, g)))
    hover_rotor = v.hover_rotor_thrust_n
    for kind, channel, label, inertia, gain in (
            (TrialKind.ROLL_DOUBLET, "rate_p", "roll", v.inertia_xx_kg_m2, c.rate_gain_p_per_s),
            (TrialKind.PITCH_DOUBLET, "rate_q", "pitch", v.inertia_yy_kg_m2, c.rate_gain_q_per_s)):
        # the rate step the loop answers without driving a motor to f_min (from hover): a linear response
        linear = 2.0 * v.arm_length_m * (hover_rotor - v.rotor_thrust_min_n) / inertia / gain
        for amplitude, half in ((0.7 * linear, 0.15), (1.4 * linear, 0.1)):
            amplitude = min(amplitude, max_angle_rad / half, 20.0)
            name = f"{label} doublet {amplitude:.3g} rad/s"
            trials.append(IdentificationTrial(kind=kind, name=name, program=_program(
                name, [(0.0, channel, amplitude), (half, channel, -amplitude), (2 * half, channel, 0.0)],
                2 * half + 0.4, g)))
    for amplitude, half in ((3.0, 0.25), (1.5, 0.35)):
        name = f"yaw doublet {amplitude:g} rad/s"
        trials.append(IdentificationTrial(kind=TrialKind.YAW_DOUBLET, name=name, program=_program(
            name, [(0.0, "rate_r", amplitude), (half, "rate_r", -amplitude), (2 * half, "rate_r", 0.0)],
            2 * half + 0.4, g)))
    notes = []
    if flips:
        model = NominalModel(prior)
        flip_axes: tuple[tuple[TrialKind, Axis], ...] = (
            (TrialKind.ROLL_FLIP, "roll"), (TrialKind.PITCH_FLIP, "pitch"))
        for kind, axis in flip_axes:
            flip = MultiFlip(vehicle=v, flips=1, max_rate_rad_s=math.radians(720.0), dims=2, axis=axis)
            result = design(flip, model)  # type: ignore[arg-type]
            if flip_model is not None and result.converged:
                result = design(flip, flip_model, p_guess=result.p_nominal)
            if not result.converged:
                notes.append(f"slow {axis} flip left out: it cannot be designed on {prior.name}: {result.message}")
                continue
            program = flip.program(result.p_nominal)
            name = f"slow {axis} flip (720 deg/s)"
            trials.append(IdentificationTrial(kind=kind, name=name, program=Program(
                switches=program.switches, duration_s=program.duration_s, ramp_down=program.ramp_down,
                hover_collective_m_s2=program.hover_collective_m_s2, name=name)))
    return tuple(trials), notes


@dataclass(frozen=True)
class IdentificationSequence:
    """An identification sequence as a stored session's maneuver (see the module doc).

    Attributes
    ----------
    prior : the vehicle the trials were built for (and the plant was built around).
    trials : the trials, flown in this order.
    """

    prior: VehicleConfig
    trials: tuple[IdentificationTrial, ...]
    name: str = ""
    parameters: tuple[ParameterSpec, ...] = field(init=False, repr=False, compare=False)
    errors: tuple[ErrorSpec, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not self.trials:
            raise ConfigError("an identification sequence needs at least one trial")
        if not self.name:
            object.__setattr__(self, "name", f"identification ({len(self.trials)} trials)")
        object.__setattr__(self, "parameters", (ParameterSpec(
            name="trial", description="which trial of the sequence (0-based)", unit="-", lower=0.0,
            upper=float(len(self.trials) - 1) if len(self.trials) > 1 else 1.0, scale=1.0),))
        object.__setattr__(self, "errors", tuple(
            ErrorSpec(name=axis, unit="m", scale=0.1, kind=ErrorKind.POSITION) for axis in "xyz"))

    def trial_index(self, params: np.ndarray) -> int:
        problem = check_parameters(self.parameters, params)
        index = int(round(float(np.asarray(params, dtype=float)[0]))) if problem is None else -1
        if problem is not None or not 0 <= index < len(self.trials):
            raise ConfigError(f"{self.name}: no trial {params!r}; allowed 0 … {len(self.trials) - 1}")
        return index

    def guess(self) -> np.ndarray:
        return np.zeros(1)

    def program(self, params: np.ndarray) -> Program:
        return self.trials[self.trial_index(params)].program

    def initial_state(self) -> np.ndarray:
        return hover_state(self.prior.vehicle)

    def error(self, final_state: np.ndarray) -> np.ndarray:
        """How far from the start the trial ended (x, y, z) [m]."""
        return np.asarray(final_state, dtype=float)[POS].copy()

    def is_valid(self, params: np.ndarray) -> bool:
        try:
            self.trial_index(params)
        except ConfigError:
            return False
        return True

    def duration_s(self, params: np.ndarray) -> float:
        return float(self.program(params).duration_s)

    def spec(self) -> dict[str, Any]:
        return {
            "kind": "identification",
            "prior": vehicle_table(self.prior),
            "trials": [{"kind": t.kind.value, "name": t.name, **program_to_table(t.program)} for t in self.trials],
        }


def sequence_from_spec(spec: Mapping[str, Any], source: str) -> IdentificationSequence:
    """The sequence a stored identification session flew (inverse of :meth:`IdentificationSequence.spec`)."""
    if not isinstance(spec, Mapping) or spec.get("kind") != "identification":
        raise ConfigError(f"{source}: not an identification session (maneuver kind {spec.get('kind')!r})")
    prior = vehicle_from_table(table_field(spec, "prior", source, Mapping, "a vehicle table"),
                               source=f"{source}.prior")
    rows = table_field(spec, "trials", source, list, "a list of trials")
    trials = []
    for k, row in enumerate(rows):
        where = f"{source}.trials[{k}]"
        if not isinstance(row, Mapping):
            raise ConfigError(f"{where}: expected a table")
        try:
            kind = TrialKind(str(row.get("kind")))
        except ValueError:
            raise ConfigError(f"{where}.kind = {row.get('kind')!r}: allowed "
                              f"{', '.join(k.value for k in TrialKind)}") from None
        name = table_field(row, "name", where, str, "a string")
        program = program_from_table({"program": row.get("program"), "switch": row.get("switch", [])}, source=where)
        trials.append(IdentificationTrial(kind=kind, name=name, program=program))
    return IdentificationSequence(prior, tuple(trials))
