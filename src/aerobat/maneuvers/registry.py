"""Rebuild maneuvers from their specifications, keyed by ``spec["kind"]``.

Every maneuver describes itself with ``spec()``: a JSON-ready table whose
``kind`` names its family. The experiment store keeps that table, and
:func:`from_spec` turns it back into an equal maneuver, so a stored session can
be resumed, replotted or re-simulated without the command line that made it.

Families register a builder with :func:`register_maneuver`. ``flip``
(:class:`~aerobat.maneuvers.flip.MultiFlip`) is built in. For any other kind,
:func:`from_spec` first imports ``aerobat.maneuvers.<kind>`` (if such a module
exists), so a module that registers its builder at import time needs no other
wiring.
"""

from __future__ import annotations

import importlib
import math
import re
from collections.abc import Callable, Mapping
from typing import Any

from ..config import ConfigError, dataclass_from_table
from ..vehicle import VehicleParams
from .base import Maneuver
from .flip import MultiFlip

__all__ = ["ManeuverBuilder", "from_spec", "register_maneuver", "registered_kinds"]

ManeuverBuilder = Callable[[Mapping[str, Any], str], Maneuver]
"""``builder(spec, source) -> maneuver``; raises :class:`ConfigError` naming ``source`` and the field."""

_BUILDERS: dict[str, ManeuverBuilder] = {}
_KIND_PATTERN = re.compile(r"^[a-z][a-z0-9_]{0,40}$")


def register_maneuver(kind: str, builder: ManeuverBuilder, *, replace: bool = False) -> None:
    """Make :func:`from_spec` build specifications of ``kind`` with ``builder``.

    Parameters
    ----------
    kind : the value of ``spec["kind"]`` (lower-case identifier).
    builder : ``builder(spec, source)`` returning the maneuver; it raises
        :class:`~aerobat.config.ConfigError` naming ``source`` and the field on bad input.
    replace : allow replacing an existing registration.
    """
    if not isinstance(kind, str) or not _KIND_PATTERN.match(kind):
        raise ValueError(f"maneuver kind {kind!r}: expected a lower-case identifier")
    if kind in _BUILDERS and not replace and _BUILDERS[kind] is not builder:
        raise ValueError(f"maneuver kind {kind!r} is already registered")
    _BUILDERS[kind] = builder


def registered_kinds() -> tuple[str, ...]:
    """The kinds :func:`from_spec` can build right now, sorted."""
    return tuple(sorted(_BUILDERS))


def from_spec(spec: Mapping[str, Any], *, source: str = "maneuver spec") -> Maneuver:
    """The maneuver described by ``spec`` (the output of its ``spec()``).

    Parameters
    ----------
    spec : the specification table; ``spec["kind"]`` selects the builder.
    source : where the table came from, used in error messages
        (e.g. ``"aerobat.sqlite: session 3 maneuver"``).

    Raises
    ------
    ConfigError
        Not a table, unknown kind, or a field missing, of the wrong type or out of range.
    """
    if not isinstance(spec, Mapping):
        raise ConfigError(f"{source}: expected a table, got {type(spec).__name__}")
    kind = spec.get("kind")
    if not isinstance(kind, str):
        raise ConfigError(f"{source}.kind: expected a string naming the maneuver family, got {kind!r}")
    if kind not in _BUILDERS and _KIND_PATTERN.match(kind):
        try:  # a family module registers itself when imported
            importlib.import_module(f"{__package__}.{kind}")
        except ModuleNotFoundError:
            pass
    builder = _BUILDERS.get(kind)
    if builder is None:
        raise ConfigError(f"{source}.kind: unknown maneuver kind {kind!r}; known: {', '.join(registered_kinds())}")
    return builder(spec, source)


# ------------------------------------------------------------------- flip


def _field(spec: Mapping[str, Any], name: str, source: str, expected: type | tuple[type, ...], what: str) -> Any:
    if name not in spec:
        raise ConfigError(f"{source}: missing required field {name}")
    value = spec[name]
    if isinstance(value, bool) or not isinstance(value, expected):
        raise ConfigError(f"{source}.{name}: expected {what}, got {type(value).__name__} {value!r}")
    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(f"{source}.{name} = {value}: must be finite")
    return value


_FLIP_FIELDS = ("kind", "flips", "max_rate_rad_s", "axis", "dims", "coast_collective", "ramp_collective_s", "vehicle")


def _flip_from_spec(spec: Mapping[str, Any], source: str) -> MultiFlip:
    unknown = sorted(set(spec) - set(_FLIP_FIELDS))
    if unknown:
        raise ConfigError(f"{source}: unknown field(s) {', '.join(unknown)}; allowed: {', '.join(_FLIP_FIELDS)}")
    vehicle_table = _field(spec, "vehicle", source, Mapping, "a table of vehicle constants")
    vehicle = dataclass_from_table(VehicleParams, vehicle_table, source=f"{source}.vehicle")
    try:
        return MultiFlip(
            vehicle=vehicle,
            flips=_field(spec, "flips", source, int, "an integer"),
            max_rate_rad_s=float(_field(spec, "max_rate_rad_s", source, (int, float), "a number [rad/s]")),
            axis=_field(spec, "axis", source, str, "'roll' or 'pitch'"),
            dims=_field(spec, "dims", source, int, "2 or 3"),
            coast_collective=_field(spec, "coast_collective", source, str, "'min' or 'max'"),
            ramp_collective_s=float(_field(spec, "ramp_collective_s", source, (int, float), "a number [s]")),
        )
    except ValueError as exc:
        if isinstance(exc, ConfigError):
            raise
        raise ConfigError(f"{source}: {exc}") from None


# MultiFlip's attributes are read-only (frozen dataclass) where the Maneuver protocol declares
# plain variables, so mypy does not see it as a Maneuver; it is one at run time
register_maneuver("flip", _flip_from_spec)  # type: ignore[arg-type]
