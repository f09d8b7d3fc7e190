"""Maneuvers written in Python, named ``package.module:Name`` on the command line.

``Name`` is a maneuver class or factory called with the design vehicle
(``Name(vehicle=VehicleParams)``; a callable that takes no vehicle is called bare). For the
store, resumed sessions and study workers to rebuild the maneuver from its ``spec()``, its
kind must be registered: either ``Name.from_spec(spec, source)`` exists (it is registered
here, and ``spec()`` should carry ``"module": "package.module"`` so other processes import it),
or the package declares an ``aerobat.maneuvers`` entry point (``docs/maneuvers.md``).
"""

from __future__ import annotations

import importlib
import inspect
import re
from typing import Any

from aerobat.core.maneuver import Maneuver
from aerobat.core.registry import MANEUVERS
from aerobat.errors import ConfigError
from aerobat.quadrotor.vehicle import VehicleParams

__all__ = ["load_plugin_maneuver"]

_REFERENCE = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_]\w*$")


def load_plugin_maneuver(reference: str, vehicle: VehicleParams, *, option: str = "--maneuver") -> Maneuver:
    """Import ``package.module:Name``, build the maneuver for ``vehicle`` and register its kind."""
    if not _REFERENCE.match(reference):
        raise ConfigError(f"{option} {reference!r}: expected a maneuver file (.toml) or package.module:Name")
    module_name, _, attribute = reference.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise ConfigError(f"{option} {reference!r}: cannot import {module_name}: {exc}") from None
    factory = getattr(module, attribute, None)
    if factory is None or not callable(factory):
        raise ConfigError(f"{option} {reference!r}: {module_name} has no callable {attribute}")
    try:
        takes_vehicle = "vehicle" in inspect.signature(factory).parameters
    except (TypeError, ValueError):
        takes_vehicle = True
    try:
        maneuver = factory(vehicle=vehicle) if takes_vehicle else factory()
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{option} {reference!r}: building it failed: {exc}") from None
    if not isinstance(maneuver, Maneuver):
        raise ConfigError(f"{option} {reference!r}: {attribute} did not return a maneuver (it lacks some of "
                          f"name, parameters, errors, guess, program, initial_state, error, is_valid, duration_s, "
                          f"spec; see docs/maneuvers.md)")
    kind = maneuver.spec().get("kind") if isinstance(maneuver.spec(), dict) else None
    builder: Any = getattr(factory, "from_spec", None)
    if isinstance(kind, str) and kind not in MANEUVERS and builder is not None:
        MANEUVERS.register(kind, builder)
    return maneuver
