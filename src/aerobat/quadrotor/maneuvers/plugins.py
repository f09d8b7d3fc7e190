"""Maneuvers written in Python, named ``package.module:Name`` or ``path/to/file.py:Name`` on the command line.

``package.module`` is imported (it must be on ``PYTHONPATH`` or installed);
``path/to/file.py`` (relative to the working directory) is loaded from the file as the module
``file`` (its directory goes on ``sys.path``, so its own imports and study workers find it).
``Name`` is a maneuver class or factory called with the design vehicle
(``Name(vehicle=VehicleParams)``; a callable that takes no vehicle is called bare). For the
store, resumed sessions and study workers to rebuild the maneuver from its ``spec()``, its
kind must be registered: either ``Name.from_spec(spec, source)`` exists (it is registered
here, and ``spec()`` should carry ``"module": "package.module"`` so other processes import it),
or the package declares an ``aerobat.maneuvers`` entry point (``docs/maneuvers.md``).
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import re
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

from aerobat.core.maneuver import Maneuver
from aerobat.core.registry import MANEUVERS
from aerobat.errors import ConfigError
from aerobat.quadrotor.vehicle import VehicleConfig, VehicleParams

__all__ = ["load_maneuver", "load_plugin_maneuver"]

_REFERENCE = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_]\w*$")
_FILE_REFERENCE = re.compile(r"^(?P<path>.+\.py):(?P<name>[A-Za-z_]\w*)$")
SPELLINGS = "a maneuver file (.toml), path/to/file.py:Name or package.module:Name"
"""The ways to name a maneuver with ``--maneuver`` (for messages)."""


def load_maneuver(source: str | Path, vehicle: VehicleParams | VehicleConfig | None = None, *,
                  option: str = "maneuver") -> Maneuver:
    """The maneuver ``source`` names, for ``vehicle``: what ``--maneuver`` takes, in one call.

    Parameters
    ----------
    source : a maneuver file (``examples/maneuvers/sideways_step.toml``), ``path/to/file.py:Name``
        or ``package.module:Name``.
    vehicle : the design vehicle (a :class:`VehicleConfig` or its :class:`VehicleParams`); default
        Table 1 (``hummingbird()``).
    option : what messages call the source (``--maneuver`` on the command line).

    Raises
    ------
    ConfigError
        The file or reference is wrong (one line naming the file and field).
    """
    from aerobat.quadrotor.maneuvers.staged import load_maneuver_file
    from aerobat.quadrotor.vehicle import hummingbird

    if vehicle is None:
        vehicle = hummingbird()
    if isinstance(vehicle, VehicleConfig):
        vehicle = vehicle.vehicle
    if not isinstance(vehicle, VehicleParams):
        raise ConfigError(f"vehicle: expected a VehicleConfig or VehicleParams, got {type(vehicle).__name__}")
    if isinstance(source, Path):
        source = str(source)
    if not isinstance(source, str):
        raise ConfigError(f"{option}: expected {SPELLINGS}, got {type(source).__name__}")
    if source.endswith(".toml") or (not source.endswith(".py") and _exists(source)):
        return load_maneuver_file(source, vehicle)
    return load_plugin_maneuver(source, vehicle, option=option)


def _exists(path: str) -> bool:
    """Whether ``path`` names something; False for names the file system refuses (too long…)."""
    try:
        return Path(path).exists()
    except (OSError, ValueError):
        return False


def load_plugin_maneuver(reference: str, vehicle: VehicleParams, *, option: str = "--maneuver") -> Maneuver:
    """Import ``package.module:Name`` (or load ``file.py:Name``), build the maneuver for ``vehicle``, register it."""
    file_match = _FILE_REFERENCE.match(reference)
    if file_match:
        module = _module_from_file(Path(file_match["path"]), reference, option)
        module_name, attribute = module.__name__, file_match["name"]
    elif reference.endswith(".py"):
        raise ConfigError(f"{option} {reference!r}: a Python file; name the maneuver in it as "
                          f"{reference}:Name{_candidates(reference)}")
    elif not _REFERENCE.match(reference):
        raise ConfigError(f"{option} {reference!r}: expected {SPELLINGS}")
    else:
        module_name, _, attribute = reference.partition(":")
        try:
            module = importlib.import_module(module_name)
        except ImportError as exc:
            raise ConfigError(f"{option} {reference!r}: cannot import {module_name}: {exc}"
                              f"{_spelling_hint(module_name, attribute)}") from None
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


def _module_from_file(path: Path, reference: str, option: str) -> ModuleType:
    """The module in ``path``, loaded once under its file name (its directory on ``sys.path``)."""
    if not path.is_file():
        raise ConfigError(f"{option} {reference!r}: {path} is not a file")
    name = path.stem
    if not name.isidentifier():
        raise ConfigError(f"{option} {reference!r}: {path.name} is not a Python module name (letters, digits, _)")
    resolved = path.resolve()
    loaded = sys.modules.get(name)
    if loaded is not None:
        where = getattr(loaded, "__file__", None)
        if where and Path(where).resolve() == resolved:
            return loaded
        raise ConfigError(f"{option} {reference!r}: a module named {name} is already loaded from "
                          f"{where or 'elsewhere'}; rename {path.name}")
    folder = str(resolved.parent)
    if folder not in sys.path:
        sys.path.insert(0, folder)
    spec = importlib.util.spec_from_file_location(name, resolved)
    if spec is None or spec.loader is None:  # pragma: no cover - a .py file always has a loader
        raise ConfigError(f"{option} {reference!r}: cannot load {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except Exception as exc:
        sys.modules.pop(name, None)
        raise ConfigError(f"{option} {reference!r}: loading {path} failed: {type(exc).__name__}: {exc}") from None
    return module


def _candidates(path_text: str) -> str:
    """``" (in it: A, B)"``: the classes a Python file defines that look like maneuvers, without importing it."""
    import ast

    try:
        tree = ast.parse(Path(path_text).read_text(encoding="utf-8"))
    except (OSError, SyntaxError, ValueError, UnicodeDecodeError):
        return ""
    names = [node.name for node in tree.body if isinstance(node, ast.ClassDef)
             and {"program", "error"} <= {f.name for f in node.body if isinstance(f, ast.FunctionDef)}]
    return f" (maneuvers in it: {', '.join(names)})" if names else ""


def _spelling_hint(module_name: str, attribute: str) -> str:
    """What to write instead of a dotted name that is a file under the working directory."""
    as_file = Path(*module_name.split(".")).with_suffix(".py")
    if as_file.is_file():
        hint = f"; {as_file} is a file here: name it as {as_file.as_posix()}:{attribute}"
        try:
            installed = importlib.util.find_spec("aerobat." + module_name) is not None
        except ImportError:
            installed = False
        if installed:
            hint += f" (or aerobat.{module_name}:{attribute}, the copy installed with aerobat)"
        return hint
    return ""
