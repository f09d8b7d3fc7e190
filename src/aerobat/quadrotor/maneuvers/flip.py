"""Hover-to-hover multi-flips (Sect. 8), in 2D (5 parameters) and 3D (9 parameters).

Five stages — accelerate, start rotate, coast, stop rotate, recover — each with a
constant angular acceleration about the flip axis and a constant collective on
the edge of the reduced envelope (eqs 33–34 as ``../shared/design.md`` reads them):

==============  ===========================================  ======================
stage           flip-axis acceleration                      collective
==============  ===========================================  ======================
accelerate      −l m (β̄ − p₀)/(2 I)                         p₀
start rotate    +l m (β̄ − β̲)/(4 I)                          (β̄ + β̲)/2
coast           0                                            β̲ (or β̄, an option)
stop rotate     −l m (β̄ − β̲)/(4 I)                          (β̄ + β̲)/2
recover         +l m (β̄ − p₃)/(2 I)                         p₃
==============  ===========================================  ======================

Durations: p₁ (accelerate), T₂ (eq 35), p₂ (coast), T₄ (eq 36 with the rate
returning to zero), p₄ (recover). The 3D extension adds eqs 43–46: lateral
angular-acceleration "triangles" p₅, p₆, p₇ during accelerate, start and stop
rotate, and a yaw correction p₈ split over accelerate and recover.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Literal

import numpy as np

from aerobat.config import check_type, dataclass_from_table, dataclass_to_table, table_field
from aerobat.core.bounds import Integer, Interval, OneOf, bounded, validate
from aerobat.core.maneuver import ErrorKind, ErrorSpec, ParameterSpec, check_parameters
from aerobat.errors import ConfigError
from aerobat.quadrotor.dynamics import POS, VEL, euler_zyx, hover_state, rotation_angles
from aerobat.quadrotor.envelope import ReducedEnvelope
from aerobat.quadrotor.program import MANEUVER_RAMP_S, Program, RampDown, make_switch
from aerobat.quadrotor.vehicle import VehicleParams

__all__ = ["DIMS", "FLIPS", "MAX_RATE", "MAX_RATE_DEG_S", "Axis", "Coast", "FlipStages", "MultiFlip", "flip_from_spec"]

Axis = Literal["roll", "pitch"]
"""The axis a flip turns about: roll (in the Y–Z plane) or pitch (X–Z)."""
Coast = Literal["min", "max"]
"""The collective of a flip's coast stage: the reduced envelope's minimum β̲ or its maximum β̄."""

DIMS = Integer(2, 3)
"""2D flips (5 parameters, 5 errors) or 3D (9 and 9): :attr:`MultiFlip.dims`, ``--dims``."""
FLIPS = Integer(1, 10)
"""c_N, the full turns a flip may make (:attr:`MultiFlip.flips`, the envelope study's flip counts, ``--flips``)."""
_RATE_LOW_RAD_S, _RATE_HIGH_RAD_S = 0.5, 100.0
MAX_RATE = Interval(_RATE_LOW_RAD_S, _RATE_HIGH_RAD_S, as_float=True,
                    unit=f"rad/s, {math.degrees(_RATE_LOW_RAD_S):.0f}–{math.degrees(_RATE_HIGH_RAD_S):.0f} °/s")
"""c_pmax, the coast rates a flip may have [rad/s] (:attr:`MultiFlip.max_rate_rad_s`)."""
MAX_RATE_DEG_S = Interval(math.degrees(_RATE_LOW_RAD_S), math.degrees(_RATE_HIGH_RAD_S), unit="deg/s")
"""The same range in degrees per second, for what is given in them (``--max-rate-deg-s``, the envelope's rates)."""


def _event_time(event: tuple[tuple[str, float], float]) -> float:
    return event[0][1]


def _triangle(events: dict[tuple[str, float], float], channel: str, start: float, length: float, span: float,
              amplitude: float) -> None:
    """Eq 43's triangle on ``channel``: +A/span² from ``start``, −A/span² from half ``length`` on (0 if empty)."""
    if length <= 1e-9 or span <= 1e-9:
        events[(channel, round(start, 12))] = 0.0
        return
    level = amplitude / span**2
    events[(channel, round(start, 12))] = level
    events[(channel, round(start + 0.5 * length, 12))] = -level


@lru_cache(maxsize=64)
def _ramp_down(collective_s: float) -> RampDown:
    """The flip's ramp-down (built and checked once per duration: programs are built in every design step)."""
    return RampDown(collective_s=collective_s)


@dataclass(frozen=True)
class FlipStages:
    """Durations [s], flip-axis accelerations [rad/s²] and collectives [m/s²] of the five stages."""

    durations_s: np.ndarray
    accelerations_rad_s2: np.ndarray
    collectives_m_s2: np.ndarray

    @property
    def starts_s(self) -> np.ndarray:
        return np.concatenate([[0.0], np.cumsum(self.durations_s)[:-1]])

    @property
    def total_s(self) -> float:
        return float(self.durations_s.sum())


@dataclass(frozen=True, kw_only=True)
class MultiFlip:
    """A hover-to-hover multi-flip designed on ``vehicle`` (the nominal model).

    Parameters
    ----------
    vehicle : the design model's physical constants (envelope, inertia).
    flips : c_N, number of full turns.
    max_rate_rad_s : c_pmax, coast rate [rad/s].
    axis : ``"roll"`` (flip in the Y–Z plane) or ``"pitch"`` (X–Z plane).
    dims : 2 (5 parameters, 5 errors) or 3 (9 parameters, 9 errors).
    coast_collective : ``"min"`` (β̲, default; design.md's reading of eq 34) or ``"max"`` (β̄ as printed).
    ramp_collective_s : thrust ramp-down to hover over the program's last seconds (Sect. 7.2).
    """

    vehicle: VehicleParams
    flips: int = bounded(3, FLIPS)
    max_rate_rad_s: float = bounded(math.radians(1800.0), MAX_RATE)
    axis: Axis = bounded("roll", OneOf(Axis))
    dims: int = bounded(3, DIMS)
    coast_collective: Coast = bounded("min", OneOf(Coast))
    ramp_collective_s: float = bounded(0.1, MANEUVER_RAMP_S)
    name: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.vehicle, VehicleParams):
            hint = " (a VehicleConfig: pass its .vehicle)" if hasattr(self.vehicle, "vehicle") else ""
            raise ConfigError(f"MultiFlip: vehicle must be a VehicleParams, got {type(self.vehicle).__name__}{hint}")
        validate(self)
        check_type("name", self.name, str, "a string")
        if not self.name:
            object.__setattr__(
                self, "name",
                f"{self.dims}D {self.flips}x {self.axis} flip at {math.degrees(self.max_rate_rad_s):.0f} deg/s",
            )
        bl, bh = self.vehicle.collective_reduced_min_m_s2, self.vehicle.collective_reduced_max_m_s2
        envelope_names = ("β̲, the vehicle's reduced-envelope minimum collective (collective_reduced_min_m_s2)",
                          "β̄, the vehicle's reduced-envelope maximum collective (collective_reduced_max_m_s2)")
        params = [
            ParameterSpec(name="p0", description="accelerate collective", unit="m/s²", lower=bl, upper=bh, scale=1.0,
                          bound_names=envelope_names),
            ParameterSpec(name="p1", description="accelerate duration", unit="s", lower=0.0, upper=2.0, scale=0.02,
                          bound_names=("zero duration", "the 2 s limit on a stage")),
            ParameterSpec(name="p2", description="coast duration", unit="s", lower=0.0, upper=5.0, scale=0.02),
            ParameterSpec(name="p3", description="recover collective", unit="m/s²", lower=bl, upper=bh, scale=1.0,
                          bound_names=envelope_names),
            ParameterSpec(name="p4", description="recover duration", unit="s", lower=0.0, upper=2.0, scale=0.02,
                          bound_names=("zero duration", "the 2 s limit on a stage")),
        ]
        lat = "pitch" if self.axis == "roll" else "roll"
        if self.dims == 3:
            params += [
                ParameterSpec(name="p5", description=f"{lat} triangle, accelerate", unit="rad", lower=-2.0,
                              upper=2.0, scale=0.05),
                ParameterSpec(name="p6", description=f"{lat} triangle, start rotate", unit="rad", lower=-2.0,
                              upper=2.0, scale=0.05),
                ParameterSpec(name="p7", description=f"{lat} triangle, stop rotate", unit="rad", lower=-2.0,
                              upper=2.0, scale=0.05),
                ParameterSpec(name="p8", description="yaw triangles, accelerate + recover", unit="rad",
                              lower=-4.0, upper=4.0, scale=0.05),
            ]
        h, o = ("y", "x") if self.axis == "roll" else ("x", "y")
        pos, vel, ang = ErrorKind.POSITION, ErrorKind.VELOCITY, ErrorKind.ANGLE
        errors = [
            ErrorSpec(name=h, unit="m", scale=0.1, kind=pos),
            ErrorSpec(name=f"v{h}", unit="m/s", scale=0.1, kind=vel),
            ErrorSpec(name="z", unit="m", scale=0.1, kind=pos),
            ErrorSpec(name="vz", unit="m/s", scale=0.1, kind=vel),
            ErrorSpec(name="flip_angle", unit="rad", scale=math.radians(5.0), kind=ang),
        ]
        if self.dims == 3:
            errors += [
                ErrorSpec(name=o, unit="m", scale=0.1, kind=pos),
                ErrorSpec(name=f"v{o}", unit="m/s", scale=0.1, kind=vel),
                ErrorSpec(name="roll" if self.axis == "pitch" else "pitch", unit="rad", scale=math.radians(5.0),
                          kind=ang),
                ErrorSpec(name="yaw", unit="rad", scale=math.radians(5.0), kind=ang),
            ]
        object.__setattr__(self, "parameters", tuple(params))
        object.__setattr__(self, "errors", tuple(errors))

    # -- Protocol attributes (set in __post_init__) --
    parameters: tuple[ParameterSpec, ...] = field(init=False, repr=False, compare=False)
    errors: tuple[ErrorSpec, ...] = field(init=False, repr=False, compare=False)

    # ---------------------------------------------------------------- helpers
    @property
    def envelope(self) -> ReducedEnvelope:
        """The reduced-envelope bounds (collective, rates) the flip's parameters must respect."""
        cached = self.__dict__.get("_envelope")
        if cached is None:  # built once: program() runs inside every design iteration
            cached = ReducedEnvelope.for_axis(self.vehicle, self.axis)
            object.__setattr__(self, "_envelope", cached)
        return cached

    @property
    def target_flip_angle_rad(self) -> float:
        """The total rotation the flip must make [rad]: 2π times the number of flips."""
        return 2.0 * math.pi * self.flips

    def stages(self, params: np.ndarray) -> FlipStages:
        """Stage durations, accelerations and collectives for parameters ``params`` (eqs 33–36)."""
        p = np.asarray(params, dtype=float)
        env = self.envelope
        c = self.max_rate_rad_s
        a_acc = env.acceleration_at_high(p[0])
        a_rot = env.max_acceleration_rad_s2
        a_rec = env.acceleration_at_high(p[3])
        t2 = (c + p[1] * a_acc) / a_rot
        t4 = (c + p[4] * a_rec) / a_rot
        coast = env.collective_min_m_s2 if self.coast_collective == "min" else env.collective_max_m_s2
        corner = env.corner_collective_m_s2
        return FlipStages(
            durations_s=np.array([p[1], t2, p[2], t4, p[4]]),
            accelerations_rad_s2=np.array([-a_acc, a_rot, 0.0, -a_rot, a_rec]),
            collectives_m_s2=np.array([p[0], corner, coast, corner, p[3]]),
        )

    # ------------------------------------------------------------- protocol
    def guess(self) -> np.ndarray:
        """Eqs 37–39 (T₂, T₄ from the rotation stages alone, T₃ = p₂)."""
        env = self.envelope
        c = self.max_rate_rad_s
        g = self.vehicle.gravity_m_s2
        a_rot = env.max_acceleration_rad_s2
        p0 = 0.9 * env.collective_max_m_s2
        t_rot = c / a_rot
        p2 = max(2.0 * math.pi * self.flips / c - c / a_rot, 0.0)
        p1 = g * (t_rot + p2 + t_rot) / (2.0 * p0)
        guess = [p0, p1, p2, p0, p1]
        if self.dims == 3:
            guess += [0.0, 0.0, 0.0, 0.0]
        return np.array(guess)

    def is_valid(self, params: np.ndarray) -> bool:
        """True when ``params`` give a program inside the vehicle's envelope (positive durations)."""
        return check_parameters(self.parameters, params) is None

    def duration_s(self, params: np.ndarray) -> float:
        """Hover to hover [s]: the five stages (eqs 35–36), ramps inside the last."""
        problem = check_parameters(self.parameters, params)
        if problem is not None:
            raise ConfigError(f"{self.name}: invalid parameters: {problem}")
        return self.stages(np.asarray(params, dtype=float)).total_s

    def program(self, params: np.ndarray) -> Program:
        """The flip's switch program for the parameter vector ``params`` (Sect. 6)."""
        problem = check_parameters(self.parameters, params)
        if problem is not None:
            raise ConfigError(f"{self.name}: invalid parameters: {problem}")
        p = np.asarray(params, dtype=float)
        st = self.stages(p)
        # plain floats from here (the same IEEE values as NumPy's scalars, a fraction of the cost: this
        # runs for every simulation of every design)
        starts = st.starts_s.tolist()
        durations = st.durations_s.tolist()
        end = float(st.durations_s.sum())
        flip_ch, lat_ch = ("accel_p", "accel_q") if self.axis == "roll" else ("accel_q", "accel_p")
        # a later event at the same instant (zero-length stage) replaces the earlier one
        events: dict[tuple[str, float], float] = {}
        at = [round(t, 12) for t in starts]  # each stage's start as an event key
        for k, (collective, accel) in enumerate(zip(st.collectives_m_s2.tolist(), st.accelerations_rad_s2.tolist(),
                                                    strict=True)):
            events[("collective", at[k])] = collective
            events[(flip_ch, at[k])] = accel
        if self.dims == 3:
            q = p.tolist()
            # eq 43: F1(A, t_s, t_Δ) = A·sgn(t_s + t_Δ/2 − t)/t_Δ² on the stage [t_s, t_s + t_Δ]
            for k, amplitude in ((0, q[5]), (1, q[6]), (3, q[7])):
                _triangle(events, lat_ch, starts[k], durations[k], durations[k], amplitude)
            events[(lat_ch, at[2])] = 0.0
            events[(lat_ch, at[4])] = 0.0
            # eqs 44, 46: F2 with t_Δ = p1 + p4 over accelerate and over recover
            span = q[1] + q[4]
            _triangle(events, "accel_r", 0.0, q[1], span, q[8])
            events[("accel_r", at[1])] = 0.0
            _triangle(events, "accel_r", starts[4], q[4], span, q[8])
        switches = tuple(
            make_switch(t, ch, v) for (ch, t), v in sorted(events.items(), key=_event_time)
            if t < end
        )
        return Program(
            switches=switches,
            duration_s=end,
            ramp_down=_ramp_down(min(self.ramp_collective_s, end)),
            hover_collective_m_s2=self.vehicle.gravity_m_s2,
            name=self.name,
        )

    def initial_state(self) -> np.ndarray:
        """The hover state the flip starts from (13 entries: position, velocity, quaternion, rates)."""
        return hover_state(self.vehicle)

    def error(self, final_state: np.ndarray) -> np.ndarray:
        """e = x − x* with x* = hover at the origin after 2π·c_N about the flip axis."""
        s = np.asarray(final_state, dtype=float)
        pos, vel = s[POS], s[VEL]
        angles = rotation_angles(s)
        euler = euler_zyx(s)
        if self.axis == "roll":
            h, o, flip, other = 1, 0, angles[0], euler[1]
        else:
            h, o, flip, other = 0, 1, angles[1], euler[0]
        e = [pos[h], vel[h], pos[2], vel[2], flip - self.target_flip_angle_rad]
        if self.dims == 3:
            e += [pos[o], vel[o], other, euler[2]]
        return np.array(e)

    def error_batch(self, final_states: np.ndarray) -> np.ndarray:
        """(B, n_err) errors of (B, N_STATE) final states, bit for bit :meth:`error` of each."""
        s = np.asarray(final_states, dtype=float)
        angles = rotation_angles(s)
        euler = euler_zyx(s)
        if self.axis == "roll":
            h, o, flip, other = 1, 0, angles[:, 0], euler[:, 1]
        else:
            h, o, flip, other = 0, 1, angles[:, 1], euler[:, 0]
        pos, vel = s[:, POS], s[:, VEL]
        columns = [pos[:, h], vel[:, h], pos[:, 2], vel[:, 2], flip - self.target_flip_angle_rad]
        if self.dims == 3:
            columns += [pos[:, o], vel[:, o], other, euler[:, 2]]
        return np.stack(columns, axis=1)

    def spec(self) -> dict[str, Any]:
        """The flip as a plain mapping the store and ``from_spec`` rebuild it from."""
        return {
            "kind": "flip",
            "flips": self.flips,
            "max_rate_rad_s": self.max_rate_rad_s,
            "axis": self.axis,
            "dims": self.dims,
            "coast_collective": self.coast_collective,
            "ramp_collective_s": self.ramp_collective_s,
            "vehicle": dataclass_to_table(self.vehicle),
        }


_FLIP_FIELDS = ("kind", "flips", "max_rate_rad_s", "axis", "dims", "coast_collective", "ramp_collective_s", "vehicle")


def flip_from_spec(spec: Mapping[str, Any], source: str) -> MultiFlip:
    """The :class:`MultiFlip` that ``spec()`` describes (registered as maneuver kind ``flip``)."""
    unknown = sorted(set(spec) - set(_FLIP_FIELDS))
    if unknown:
        raise ConfigError(f"{source}: unknown field(s) {', '.join(unknown)}; allowed: {', '.join(_FLIP_FIELDS)}")
    vehicle_table = table_field(spec, "vehicle", source, Mapping, "a table of vehicle constants")
    vehicle = dataclass_from_table(VehicleParams, vehicle_table, source=f"{source}.vehicle")
    try:
        return MultiFlip(
            vehicle=vehicle,
            flips=table_field(spec, "flips", source, int, "an integer"),
            max_rate_rad_s=float(table_field(spec, "max_rate_rad_s", source, (int, float), "a number [rad/s]")),
            axis=table_field(spec, "axis", source, str, f"one of {OneOf(Axis).describe()}"),
            dims=table_field(spec, "dims", source, int, f"an integer {DIMS.describe()}"),
            coast_collective=table_field(spec, "coast_collective", source, str, f"one of {OneOf(Coast).describe()}"),
            ramp_collective_s=float(table_field(spec, "ramp_collective_s", source, (int, float), "a number [s]")),
        )
    except ConfigError as exc:
        text = str(exc)
        raise ConfigError(text if text.startswith(source) else f"{source}: {text}") from None
