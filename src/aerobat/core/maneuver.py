"""The maneuver abstraction (Sect. 4), independent of any vehicle.

A maneuver is an initial state, a desired final state (expressed as the error
components it measures), a parameter vector with bounds, and a builder that
turns parameters into whatever its plant flies (for quadrocopters, a
:class:`~aerobat.quadrotor.program.Program`). Nothing here knows about quadrocopters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, Protocol, runtime_checkable

import numpy as np

from aerobat.core.bounds import Interval, OneOf, bounded, validate
from aerobat.errors import ConfigError

__all__ = [
    "ErrorKind",
    "ErrorSpec",
    "Maneuver",
    "ParameterSpec",
    "batch_errors",
    "bounds_arrays",
    "check_maneuver",
    "check_parameters",
    "error_scales",
    "parameter_scales",
    "position_indices",
]


_SCALE = Interval(0.0, None, closed="neither")
"""A parameter's or an error's scale: a finite size above zero."""


class ErrorKind(StrEnum):
    """What an error component measures; reports group errors by it (e.g. the position error norm)."""

    POSITION = "position"
    VELOCITY = "velocity"
    ANGLE = "angle"
    RATE = "rate"
    OTHER = "other"


@dataclass(frozen=True, kw_only=True)
class ParameterSpec:
    """One learnable parameter.

    Attributes
    ----------
    name : short identifier (``p0``…), shown in tables.
    description : what it controls.
    unit : its unit (``s``, ``m/s²``, ``rad``…).
    lower, upper : allowed range (Sect. 4.2); ``±inf`` for none.
    scale : typical magnitude of a meaningful change, used for finite-difference
        steps and for scaling before regularized inverses.
    bound_names : what the lower and upper limits are (named in failure messages).
    """

    name: str
    description: str
    unit: str
    lower: float = -math.inf
    upper: float = math.inf
    scale: float = bounded(1.0, _SCALE)
    bound_names: tuple[str, str] = ("", "")

    def __post_init__(self) -> None:
        # lower and upper may be ±inf (no bound), which no Interval allows: compared here
        if not self.lower < self.upper:
            raise ConfigError(f"parameter {self.name}: lower = {self.lower} must be < upper = {self.upper}")
        validate(self)

    def pinned(self, value: float) -> str:
        """``"lower"`` or ``"upper"`` if ``value`` sits on that bound (within 1e-4 of the scale: a bounded
        solve leaves a pinned parameter a hair inside it), else ``""``."""
        tol = 1e-4 * self.scale
        if math.isfinite(self.lower) and value <= self.lower + tol:
            return "lower"
        if math.isfinite(self.upper) and value >= self.upper - tol:
            return "upper"
        return ""


@dataclass(frozen=True, kw_only=True)
class ErrorSpec:
    """One measured final-state error component e = x − x*.

    Attributes
    ----------
    name : identifier (``y``, ``vy``, ``flip_angle``…).
    unit : its unit.
    scale : the size of an error that matters (weights and scaling).
    kind : what it measures; position components make up the reported position error.
    """

    name: str
    unit: str
    scale: float = bounded(1.0, _SCALE)
    kind: ErrorKind = bounded(ErrorKind.OTHER, OneOf(ErrorKind))

    def __post_init__(self) -> None:
        validate(self)


@runtime_checkable
class Maneuver(Protocol):
    """What the design and learning stages need from a maneuver.

    Optionally, ``error_batch(final_states) -> (B, n_err)`` computes the errors of a (B, N)
    batch of final states in one call, bit for bit what ``error`` gives one state at a time
    (the design evaluates hundreds; see :func:`batch_errors`). Optionally,
    ``failure_hint(params, error) -> str | None`` reads the error at the guess when a design fails
    (e.g. "a rate of the wrong sign?"); :func:`~aerobat.core.design.design` appends it to its message.
    """

    @property
    def name(self) -> str:
        """What it is called in tables and records."""
        ...

    @property
    def parameters(self) -> tuple[ParameterSpec, ...]:
        """The learned parameters, in order."""
        ...

    @property
    def errors(self) -> tuple[ErrorSpec, ...]:
        """The final-state error components, in order."""
        ...

    def guess(self) -> np.ndarray:
        """The initial parameter guess p^g (Sect. 4)."""
        ...

    def program(self, params: np.ndarray) -> Any:
        """The input program U(t, p) for parameters ``params`` (what a plant flies)."""
        ...

    def initial_state(self) -> np.ndarray:
        """The desired initial state x(0) (what the plant starts from)."""
        ...

    def error(self, final_state: np.ndarray) -> np.ndarray:
        """Error vector e = x − x* of a (measured or simulated) final state."""
        ...

    def is_valid(self, params: np.ndarray) -> bool:
        """True if ``params`` satisfies every constraint (bounds and any derived ones)."""
        ...

    def duration_s(self, params: np.ndarray) -> float:
        """How long the program for ``params`` lasts [s] (NaN if it cannot be built)."""
        ...

    def spec(self) -> dict[str, Any]:
        """A JSON-ready description that rebuilds the maneuver (for the store)."""
        ...


_MEMBERS = ("parameters", "errors", "guess", "program", "error")  # what design and learning use


def check_maneuver(value: Any, name: str = "maneuver") -> Maneuver:
    """``value`` if it has the :class:`Maneuver` members; :class:`ConfigError` naming ``name`` otherwise."""
    missing = [m for m in _MEMBERS if not hasattr(type(value), m) and not hasattr(value, m)]
    if missing:
        text = repr(value) if isinstance(value, int | float | str | bool) or value is None else ""
        raise ConfigError(f"{name}: expected a maneuver (MultiFlip, a translation, a maneuver file…), got "
                          f"{type(value).__name__} {text[:60]}".rstrip() + f" (no {', '.join(missing[:3])})")
    return value  # type: ignore[no-any-return]


def batch_errors(maneuver: Maneuver, final_states: np.ndarray) -> np.ndarray:
    """(B, n_err) errors of a (B, N) batch of final states: the maneuver's ``error_batch`` if it has one."""
    vectorized = getattr(maneuver, "error_batch", None)
    if vectorized is not None:
        return np.asarray(vectorized(final_states), dtype=float)
    return np.array([maneuver.error(f) for f in final_states], dtype=float).reshape(len(final_states), -1)


def bounds_arrays(parameters: tuple[ParameterSpec, ...]) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) arrays of the parameter bounds."""
    return np.array([p.lower for p in parameters]), np.array([p.upper for p in parameters])


def check_parameters(parameters: tuple[ParameterSpec, ...], params: np.ndarray) -> str | None:
    """None if ``params`` is finite and inside the box bounds, else a message naming the offender."""
    try:
        params = np.asarray(params, dtype=float)
    except (TypeError, ValueError, OverflowError):
        return f"expected {len(parameters)} numbers, got {type(params).__name__}"
    if params.shape != (len(parameters),):
        return f"expected {len(parameters)} parameters, got shape {params.shape}"
    for spec, value in zip(parameters, params, strict=True):
        if not math.isfinite(value):
            return f"{spec.name} = {value} is not finite"
        if not spec.lower <= value <= spec.upper:
            return f"{spec.name} = {value:.6g} {spec.unit} is outside [{spec.lower:g}, {spec.upper:g}]"
    return None


def parameter_scales(parameters: tuple[ParameterSpec, ...]) -> np.ndarray:
    """(n_par,) typical magnitudes of the parameters."""
    return np.array([p.scale for p in parameters], dtype=float)


def error_scales(errors: tuple[ErrorSpec, ...]) -> np.ndarray:
    """(n_err,) sizes of errors that matter."""
    return np.array([e.scale for e in errors], dtype=float)


def position_indices(errors: tuple[ErrorSpec, ...]) -> list[int]:
    """Indices of the position components (:attr:`ErrorKind.POSITION`) of an error vector."""
    return [k for k, e in enumerate(errors) if e.kind is ErrorKind.POSITION]
