"""Limits, input arcs and the solution record of the time-optimal benchmark."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from aerobat.core.bounds import Interval, OneOf, bounded, required, validate

_F_LOW_RAW = 3.92
_F_HIGH_RAW = 21.58
_MARGIN = 0.05


@dataclass(frozen=True, kw_only=True)
class BenchmarkLimits:
    """Input limits and gravity of the benchmark vehicle (mass-normalised).

    Parameters
    ----------
    f_min_m_s2 : float
        Minimum collective thrust per unit mass, m/s^2.  Default
        ``3.92 + 0.05 * (21.58 - 3.92)`` (5 % margin above the motor minimum).
    f_max_m_s2 : float
        Maximum collective thrust per unit mass, m/s^2.  Default
        ``21.58 - 0.05 * (21.58 - 3.92)``.  Must exceed gravity.
    max_rate_rad_s : float
        Maximum magnitude of the body rate, rad/s.
    gravity_m_s2 : float
        Gravitational acceleration, m/s^2.

    Raises
    ------
    ConfigError
        If a field is not a finite positive number, ``f_max_m_s2 <= gravity_m_s2`` (no hover)
        or ``f_min_m_s2 >= f_max_m_s2``.  The message names the field, its value and the
        allowed range.
    """

    f_min_m_s2: float = bounded(_F_LOW_RAW + _MARGIN * (_F_HIGH_RAW - _F_LOW_RAW),
                                Interval(0.0, "f_max_m_s2", closed="neither", unit="m/s²"))
    f_max_m_s2: float = bounded(_F_HIGH_RAW - _MARGIN * (_F_HIGH_RAW - _F_LOW_RAW),
                                Interval("gravity_m_s2", None, closed="neither", unit="m/s², above g to hover"))
    max_rate_rad_s: float = bounded(10.0, Interval(0.0, None, closed="neither", unit="rad/s"))
    gravity_m_s2: float = bounded(9.81, Interval(0.0, None, closed="neither", unit="m/s²"))

    def __post_init__(self) -> None:
        # each limit after the one it is relative to: gravity, then f_max above it, then f_min below f_max
        validate(self, skip=("f_min_m_s2", "f_max_m_s2"))
        validate(self, only=("f_max_m_s2",))
        validate(self, only=("f_min_m_s2",))

    def _key(self) -> tuple[float, float, float, float]:
        return (
            float(self.f_min_m_s2),
            float(self.f_max_m_s2),
            float(self.max_rate_rad_s),
            float(self.gravity_m_s2),
        )


class ArcKind(StrEnum):
    """Where an input sits on an arc: at its upper bound, its lower bound, or inside (singular)."""

    MAX = "max"
    MIN = "min"
    SINGULAR = "singular"


@dataclass(frozen=True, kw_only=True)
class InputArc:
    """One arc of an input program.

    Parameters
    ----------
    kind : ArcKind
        ``MAX`` (input at its upper bound), ``MIN`` (lower bound) or
        ``SINGULAR`` (interior value); its text (``'max'``, ``'min'``, ``'singular'``) is accepted.
    start_s, end_s : float
        Arc start and end time, s.
    value : float
        The input on the arc (m/s^2 for thrust, rad/s for rate).  For a
        singular rate arc whose rate varies, this is the mean rate
        ``(theta(end) - theta(start)) / (end - start)``; the exact rate is
        given by ``tangent_law`` (see :meth:`evaluate`).
    tangent_law : tuple of float or None
        For singular rate arcs only: ``(alpha, beta)`` of the bilinear
        tangent law ``theta(start + s) = theta(start) + atan2(beta*s, 1 + alpha*s)``,
        i.e. ``omega(start + s) = beta / ((1 + alpha*s)**2 + (beta*s)**2)``.
        ``None`` for arcs on which the input is constant.
    """

    kind: ArcKind = required(OneOf(ArcKind))
    start_s: float = required(Interval(unit="s"))
    end_s: float = required(Interval("start_s", None, unit="s"))
    value: float
    tangent_law: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        validate(self)

    @property
    def duration_s(self) -> float:
        """Length of the arc, s."""
        return self.end_s - self.start_s

    def evaluate(self, t_s: np.ndarray | float) -> np.ndarray:
        """Input value at absolute time(s) ``t_s`` (assumed inside the arc).

        Parameters
        ----------
        t_s : array_like
            Absolute times, s.

        Returns
        -------
        numpy.ndarray
            Input values with the shape of ``t_s``.
        """
        t = np.asarray(t_s, dtype=float)
        if self.tangent_law is None:
            return np.full_like(t, self.value)
        alpha, beta = self.tangent_law
        s = t - self.start_s
        return beta / ((1.0 + alpha * s) ** 2 + (beta * s) ** 2)

    def to_json_dict(self) -> dict[str, Any]:
        """JSON-serialisable dictionary of the arc."""
        return {
            "kind": self.kind.value,
            "start_s": float(self.start_s),
            "end_s": float(self.end_s),
            "value": float(self.value),
            "tangent_law": None if self.tangent_law is None else [float(v) for v in self.tangent_law],
        }


def _json_float(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


class SolveStatus(StrEnum):
    """How a time-optimal solve ended."""

    OPTIMAL = "optimal"
    FAILED = "failed"

    @property
    def meaning(self) -> str:
        return {SolveStatus.OPTIMAL: "a verified local optimum: converged, boundary conditions met to 1e-6, "
                                     "minimum principle holds",
                SolveStatus.FAILED: "no verified optimum; the message says which stage failed"}[self]


@dataclass(frozen=True, kw_only=True, eq=False)
class TimeOptimalSolution:
    """Result of :func:`solve_translation`.

    Attributes
    ----------
    status : SolveStatus
        ``optimal`` (converged local optimum satisfying all checks) or
        ``failed``.
    message : str
        Human-readable summary or the reason for failure.
    target_m : tuple of float
        Target position ``(Y, Z)``, m.
    final_angle_rad : float
        Required final attitude, rad.
    limits : BenchmarkLimits
        Limits used.
    duration_s : float
        Refined minimum time ``T*`` (nan if failed).
    transcription_duration_s : float
        Final time of the direct transcription (nan if it failed).
    thrust_arcs, rate_arcs : tuple of InputArc
        Arc programs of the refined solution (empty if failed).  Together
        they fully define the input programs (see :meth:`inputs`).
    times_s : numpy.ndarray
        ``(N,)`` dense sample times of the refined trajectory (includes the
        switch times).
    states : numpy.ndarray
        ``(N, 5)`` states at ``times_s``; columns y, z, vy, vz, theta.
    boundary_error : float
        Max abs final-state residual of the refined input program,
        re-integrated independently with an adaptive ODE solver.
    """

    status: SolveStatus
    message: str
    target_m: tuple[float, float]
    final_angle_rad: float
    limits: BenchmarkLimits
    duration_s: float
    transcription_duration_s: float
    thrust_arcs: tuple[InputArc, ...]
    rate_arcs: tuple[InputArc, ...]
    times_s: np.ndarray
    states: np.ndarray
    boundary_error: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", SolveStatus(self.status))

    def __repr__(self) -> str:
        return (f"TimeOptimalSolution(status={self.status.value!r}, target_m={self.target_m}, "
                f"duration_s={self.duration_s:.6g})")

    @property
    def ok(self) -> bool:
        """True if the solution is a verified optimum (``status`` is ``optimal``)."""
        return self.status is SolveStatus.OPTIMAL

    def inputs(self, t_s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Thrust and rate of the refined program at times ``t_s``.

        Parameters
        ----------
        t_s : array_like
            Times in ``[0, duration_s]``, s.  At a switch the arc starting
            there is used.

        Returns
        -------
        thrust, rate : numpy.ndarray
            Input values with the shape of ``t_s``.
        """
        t = np.asarray(t_s, dtype=float)
        return eval_arcs(self.thrust_arcs, t), eval_arcs(self.rate_arcs, t)

    def to_json_dict(self) -> dict[str, Any]:
        """JSON-serialisable summary (non-finite numbers become ``None``)."""
        return {
            "status": self.status.value,
            "message": self.message,
            "target_m": [float(self.target_m[0]), float(self.target_m[1])],
            "final_angle_rad": float(self.final_angle_rad),
            "duration_s": _json_float(self.duration_s),
            "transcription_duration_s": _json_float(self.transcription_duration_s),
            "boundary_error": _json_float(self.boundary_error),
            "thrust_arcs": [a.to_json_dict() for a in self.thrust_arcs],
            "rate_arcs": [a.to_json_dict() for a in self.rate_arcs],
        }


def eval_arcs(arcs: Sequence[InputArc], t: np.ndarray) -> np.ndarray:
    out = np.full(t.shape, np.nan)
    if not arcs:
        return out
    starts = np.array([a.start_s for a in arcs])
    idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(arcs) - 1)
    for k, arc in enumerate(arcs):
        m = idx == k
        if np.any(m):
            out[m] = arc.evaluate(t[m])
    return out


class StageFailure(Exception):
    """Internal: an ordinary solver failure, turned into status 'failed'."""
