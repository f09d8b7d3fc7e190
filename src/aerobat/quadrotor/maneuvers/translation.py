"""Adaptive near-time-optimal translation (Sect. 9, Figs. 7 and 12).

The time-optimal benchmark (:mod:`aerobat.quadrotor.timeoptimal`) gives bang-bang thrust and
bang-singular rate inputs in the vertical Y–Z plane. As a maneuver, its switch
times — and the end time — become the learnable parameters (Sect. 9), ramp-downs
are added (Sect. 7.2), the benchmark's timing is p^g, and p⁰ comes from the full
model. There are more switch times than errors, so C is the right pseudo-inverse
(eq 48).

The switch times are carried as the *durations between consecutive switches*
(p_k = t_k − t_{k−1}, the last one ending at T): the same information, but, as
Sect. 4.1 recommends, durations keep the switch order fixed, so the constraints
are simple bounds (p_k ≥ 0) instead of an ordering.

The benchmark's angle θ tilts thrust toward +y (ÿ = f·sin θ). With the body→world
convention a positive roll φ tilts thrust toward −y, so θ = −φ and the roll-rate
command is p̂ = −ω.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aerobat.config import check_real, check_type, dataclass_from_table, dataclass_to_table, short_repr
from aerobat.core.bounds import Interval, bounded, constraints, required, validate
from aerobat.core.maneuver import ErrorKind, ErrorSpec, ParameterSpec, check_parameters
from aerobat.errors import ConfigError, SolveFailed
from aerobat.quadrotor.dynamics import POS, VEL, hover_state, rotation_angles
from aerobat.quadrotor.program import MANEUVER_RAMP_S, Program, RampDown, Switch
from aerobat.quadrotor.vehicle import VehicleConfig, VehicleParams

__all__ = ["Translation", "translation_from_solution", "translation_from_spec", "translation_maneuver"]


def _pair(name: str, value: object) -> None:
    """Two real numbers (a tuple, a list or an array of two); :class:`ConfigError` naming ``name`` otherwise."""
    if isinstance(value, str | bytes) or not hasattr(value, "__len__") or len(value) != 2:  # type: ignore[arg-type]
        raise ConfigError(f"{name}: expected two numbers, got {type(value).__name__} {short_repr(value)}")
    for k in range(2):
        check_real(f"{name}[{k}]", value[k])  # type: ignore[index]


@dataclass(frozen=True, kw_only=True)
class Translation:
    """Hover at the origin to hover at ``target_yz`` with a given final roll angle.

    Parameters
    ----------
    vehicle : the design model's constants (hover collective, gravity).
    target_yz : (Y, Z) target [m].
    final_angle_rad : final roll angle (multiples of 2π allowed) [rad].
    interval_inputs : per interval between switch times, (collective [m/s²], roll-rate command [rad/s]).
    guess_times_s : the benchmark's interior switch times followed by its end time T* [s];
        the parameters are the durations between them.
    ramp_s : ramp-down duration for collective and rates [s].
    """

    vehicle: VehicleParams
    target_yz: tuple[float, float]
    final_angle_rad: float = required(Interval(unit="rad", as_float=True))
    interval_inputs: tuple[tuple[float, float], ...]
    guess_times_s: tuple[float, ...]
    ramp_s: float = bounded(0.1, MANEUVER_RAMP_S)
    name: str = ""
    parameters: tuple[ParameterSpec, ...] = field(init=False, repr=False, compare=False)
    errors: tuple[ErrorSpec, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        check_type("vehicle", self.vehicle, VehicleParams, "a VehicleParams (a VehicleConfig's .vehicle)")
        _pair("target_yz", self.target_yz)
        validate(self)
        check_type("name", self.name, str, "a string")
        for field_name in ("guess_times_s", "interval_inputs"):
            value = getattr(self, field_name)
            if isinstance(value, str) or not isinstance(value, tuple | list):
                raise ConfigError(f"{field_name}: expected a tuple, got {type(value).__name__} {short_repr(value)}")
        for k, t in enumerate(self.guess_times_s):
            check_real(f"guess_times_s[{k}]", t)
        for k, pair in enumerate(self.interval_inputs):
            _pair(f"interval_inputs[{k}]", pair)
        n = len(self.guess_times_s)
        if n < 1 or len(self.interval_inputs) != n:
            raise ConfigError(f"need one input pair per interval: {len(self.interval_inputs)} inputs, {n} times")
        if not all(math.isfinite(t) for t in self.guess_times_s) or np.any(np.diff(self.guess_times_s) < 0):
            raise ConfigError("guess_times_s must be finite and non-decreasing")
        if not self.name:
            object.__setattr__(self, "name", f"translation to ({self.target_yz[0]:g}, {self.target_yz[1]:g}) m")
        params = [
            ParameterSpec(name=f"p{k}", description=f"duration of input interval {k + 1}", unit="s", lower=0.0,
                          upper=5.0, scale=0.02, bound_names=("zero duration", "the 5 s limit on an interval"))
            for k in range(n)
        ]
        errors = (
            ErrorSpec(name="y", unit="m", scale=0.1, kind=ErrorKind.POSITION),
            ErrorSpec(name="vy", unit="m/s", scale=0.1, kind=ErrorKind.VELOCITY),
            ErrorSpec(name="z", unit="m", scale=0.1, kind=ErrorKind.POSITION),
            ErrorSpec(name="vz", unit="m/s", scale=0.1, kind=ErrorKind.VELOCITY),
            ErrorSpec(name="roll", unit="rad", scale=math.radians(5.0), kind=ErrorKind.ANGLE),
        )
        object.__setattr__(self, "parameters", tuple(params))
        object.__setattr__(self, "errors", errors)

    def guess(self) -> np.ndarray:
        """The initial parameter guess the design's solver starts from (the time-optimal solution where known)."""
        return np.diff(np.concatenate([[0.0], self.guess_times_s]))

    def switch_times(self, params: np.ndarray) -> np.ndarray:
        """Switch times and end time [s] of parameters (durations)."""
        return np.cumsum(np.asarray(params, dtype=float))

    def is_valid(self, params: np.ndarray) -> bool:
        """True when ``params`` give a program inside the vehicle's envelope (positive durations)."""
        return check_parameters(self.parameters, params) is None and float(np.sum(params)) > 0.05

    def duration_s(self, params: np.ndarray) -> float:
        """Hover to hover [s]: the sum of the interval durations."""
        if not self.is_valid(params):
            problem = check_parameters(self.parameters, params) or "total duration must exceed 0.05 s"
            raise ConfigError(f"{self.name}: invalid parameters: {problem}")
        return float(self.switch_times(params)[-1])

    def program(self, params: np.ndarray) -> Program:
        """The translation's switch program for the parameter vector ``params``."""
        if not self.is_valid(params):
            problem = check_parameters(self.parameters, params) or "total duration must exceed 0.05 s"
            raise ConfigError(f"{self.name}: invalid parameters: {problem}")
        times = self.switch_times(params)
        starts = np.concatenate([[0.0], times[:-1]])
        end = float(times[-1])
        events: dict[tuple[str, float], float] = {}
        for start, (collective, rate) in zip(starts, self.interval_inputs, strict=True):
            if start < end:  # a zero-length interval is overwritten by the next one
                events[("collective", float(start))] = collective
                events[("rate_p", float(start))] = rate
        switches = tuple(Switch(time_s=t, channel=ch, value=v) for (ch, t), v in sorted(events.items(),
                                                                                        key=lambda e: e[0][1]))
        return Program(
            switches=switches,
            duration_s=end,
            ramp_down=RampDown(collective_s=min(self.ramp_s, end), rates_s=min(self.ramp_s, end)),
            hover_collective_m_s2=self.vehicle.gravity_m_s2,
            name=self.name,
        )

    def initial_state(self) -> np.ndarray:
        """The hover state the translation starts from (13 entries: position, velocity, quaternion, rates)."""
        return hover_state(self.vehicle)

    def error(self, final_state: np.ndarray) -> np.ndarray:
        """The translation's error vector e(final_state): deviations from hover at the target."""
        s = np.asarray(final_state, dtype=float)
        roll = rotation_angles(s)[0]
        return np.array([
            s[POS][1] - self.target_yz[0],
            s[VEL][1],
            s[POS][2] - self.target_yz[1],
            s[VEL][2],
            roll - self.final_angle_rad,
        ])

    def error_batch(self, final_states: np.ndarray) -> np.ndarray:
        """(B, 5) errors of (B, N_STATE) final states, bit for bit :meth:`error` of each."""
        s = np.asarray(final_states, dtype=float)
        roll = rotation_angles(s)[:, 0]
        pos, vel = s[:, POS], s[:, VEL]
        return np.stack([pos[:, 1] - self.target_yz[0], vel[:, 1], pos[:, 2] - self.target_yz[1], vel[:, 2],
                         roll - self.final_angle_rad], axis=1)

    def spec(self) -> dict[str, Any]:
        """The translation as a plain mapping the store and ``from_spec`` rebuild it from."""
        return {
            "kind": "translation",
            "target_yz": list(self.target_yz),
            "final_angle_rad": self.final_angle_rad,
            "interval_inputs": [list(p) for p in self.interval_inputs],
            "guess_times_s": list(self.guess_times_s),
            "ramp_s": self.ramp_s,
            "vehicle": dataclass_to_table(self.vehicle),
        }


def translation_maneuver(
    config: VehicleConfig,
    target_yz: tuple[float, float],
    *,
    final_angle_rad: float = 0.0,
    ramp_s: float = 0.1,
    limits: Any | None = None,
) -> Translation:
    """Solve the time-optimal benchmark to ``target_yz`` and turn it into a learnable maneuver.

    Raises
    ------
    SolveFailed
        If the benchmark solve fails (its message says why).
    """
    from aerobat.quadrotor.timeoptimal import BenchmarkLimits, solve_translation

    check_type("config", config, VehicleConfig, "a VehicleConfig (e.g. aerobat.hummingbird())")
    _pair("target_yz", target_yz)
    bounds = constraints(Translation)  # checked before the solve, as the maneuver will check them
    bounds["final_angle_rad"].check("final_angle_rad", final_angle_rad)
    bounds["ramp_s"].check("ramp_s", ramp_s)
    v = config.vehicle
    if math.hypot(float(target_yz[0]), float(target_yz[1])) < 1e-3 and abs(final_angle_rad) < 1e-6:
        raise ConfigError(f"translation to {tuple(target_yz)}: the target is the start; a translation needs a "
                          f"target at least 1 mm away (or a final angle)")
    if limits is None:
        margin = 0.05 * (v.collective_reduced_max_m_s2 - v.collective_reduced_min_m_s2)
        limits = BenchmarkLimits(
            f_min_m_s2=v.collective_reduced_min_m_s2 + margin,
            f_max_m_s2=v.collective_reduced_max_m_s2 - margin,
            max_rate_rad_s=10.0,
            gravity_m_s2=v.gravity_m_s2,
        )
    solution = solve_translation(float(target_yz[0]), float(target_yz[1]), final_angle_rad=final_angle_rad,
                                 limits=limits)
    if not solution.ok:
        raise SolveFailed(f"time-optimal benchmark to {target_yz} failed: {solution.message}", solution)
    return translation_from_solution(v, solution, ramp_s=ramp_s)


def translation_from_solution(vehicle: VehicleParams, solution: Any, *, ramp_s: float = 0.1) -> Translation:
    """The maneuver of a solved benchmark: its switch times (and T*) are p^g."""
    cuts = sorted({a.start_s for a in solution.thrust_arcs + solution.rate_arcs if a.start_s > 0.0})
    times = [*cuts, float(solution.duration_s)]
    starts = [0.0, *cuts]
    inputs = []
    for start, stop in zip(starts, times, strict=True):
        mid = 0.5 * (start + stop)
        thrust = next(a.value for a in solution.thrust_arcs if a.start_s <= mid <= a.end_s)
        rate = next(a.value for a in solution.rate_arcs if a.start_s <= mid <= a.end_s)
        inputs.append((float(thrust), -float(rate)))  # θ = −φ: p̂ = −ω
    return Translation(
        vehicle=vehicle,
        target_yz=(float(solution.target_m[0]), float(solution.target_m[1])),
        final_angle_rad=-float(solution.final_angle_rad),
        interval_inputs=tuple(inputs),
        guess_times_s=tuple(times),
        ramp_s=ramp_s,
    )


def translation_from_spec(spec: Any, source: str) -> Translation:
    """Rebuild a :class:`Translation` from its ``spec()`` (registered as maneuver kind ``translation``)."""
    allowed = {"kind", "target_yz", "final_angle_rad", "interval_inputs", "guess_times_s", "ramp_s", "vehicle"}
    unknown = sorted(set(spec) - allowed)
    if unknown:
        raise ConfigError(f"{source}: unknown field(s) {', '.join(unknown)}; allowed: {', '.join(sorted(allowed))}")
    missing = sorted(allowed - set(spec))
    if missing:
        raise ConfigError(f"{source}: missing required field(s) {', '.join(missing)}")
    try:
        return Translation(
            vehicle=dataclass_from_table(VehicleParams, spec["vehicle"], source=f"{source}.vehicle"),
            target_yz=(float(spec["target_yz"][0]), float(spec["target_yz"][1])),
            final_angle_rad=float(spec["final_angle_rad"]),
            interval_inputs=tuple((float(a), float(b)) for a, b in spec["interval_inputs"]),
            guess_times_s=tuple(float(t) for t in spec["guess_times_s"]),
            ramp_s=float(spec["ramp_s"]),
        )
    except ConfigError:
        raise
    except (TypeError, ValueError, IndexError) as exc:
        raise ConfigError(f"{source}: {exc}") from None

