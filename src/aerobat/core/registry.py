"""Registries: names at the edges (command line, TOML, store) to the objects inside.

One :class:`Registry` per family — maneuvers (kind → builder from a spec table),
update rules (name → :class:`~aerobat.core.rules.registry.RuleSpec`), plants
(name → :class:`~aerobat.plants.spec.PlantSpec`). Each also reads a Python
entry-point group, so a package that declares, for example::

    [project.entry-points."aerobat.maneuvers"]
    slalom = "my_package.slalom:from_spec"

adds a maneuver kind that every command, the store and the studies know, without
any other wiring. aerobat's own built-ins are declared the same way. A maneuver whose
``spec()`` carries ``"module": "my_package.slalom"`` is also found without an entry point:
:func:`from_spec` imports that module (which registers its kind) when the kind is unknown.
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable, Iterator, Mapping
from importlib.metadata import entry_points
from typing import Any, Generic, TypeVar

from aerobat.config import short_repr
from aerobat.core.maneuver import Maneuver
from aerobat.errors import ConfigError

__all__ = [
    "MANEUVERS",
    "ManeuverBuilder",
    "Registry",
    "from_spec",
    "parameters_of",
    "register_maneuver",
    "registered_kinds",
]

T = TypeVar("T")
_NAME = re.compile(r"^[a-z][a-z0-9_]{0,40}$")


class Registry(Generic[T]):
    """Named items of one family, with lazily loaded entry-point plugins.

    Parameters
    ----------
    what : what the items are, for messages (``"maneuver kind"``).
    group : the entry-point group read on first use (``"aerobat.maneuvers"``), or None.
    """

    def __init__(self, what: str, group: str | None = None) -> None:
        self.what = what
        self.group = group
        self._items: dict[str, T] = {}
        self._pending: dict[str, Any] = {}  # entry points not loaded yet
        self._scanned = group is None

    def register(self, name: str, item: T, *, replace: bool = False) -> T:
        """Add ``item`` under ``name`` (a lower-case identifier); returns the item."""
        if not isinstance(name, str) or not _NAME.match(name):
            raise ConfigError(f"{self.what} {name!r}: expected a lower-case identifier")
        if name in self._items and not replace and self._items[name] is not item:
            raise ConfigError(f"{self.what} {name!r} is already registered")
        self._items[name] = item
        self._pending.pop(name, None)
        return item

    def _scan(self) -> None:
        if self._scanned:
            return
        self._scanned = True
        for ep in entry_points(group=self.group or ""):
            if ep.name not in self._items:
                self._pending[ep.name] = ep

    def _load(self, name: str) -> None:
        ep = self._pending.pop(name, None)
        if ep is None:
            return
        try:
            item = ep.load()
        except Exception as exc:  # a broken plugin names itself instead of breaking every command
            raise ConfigError(f"{self.what} {name!r}: the plugin {ep.value} (entry point group {self.group}) "
                              f"failed to load: {type(exc).__name__}: {exc}") from None
        if name not in self._items:
            self._items[name] = item

    def get(self, name: str, *, source: str = "") -> T:
        """The item called ``name``; :class:`ConfigError` naming ``source`` and the known names if none."""
        if not isinstance(name, str):
            where = f"{source}: " if source else ""
            raise ConfigError(f"{where}{self.what} must be a name (a string), got {type(name).__name__} "
                              f"{short_repr(name)}; known: {', '.join(self.names())}")
        if name not in self._items:
            self._scan()
            self._load(name)
        item = self._items.get(name)
        if item is None:
            where = f"{source}: " if source else ""
            raise ConfigError(f"{where}unknown {self.what} {name!r}; known: {', '.join(self.names())}")
        return item

    def names(self) -> tuple[str, ...]:
        """Every registered name (plugins included, not loaded), sorted."""
        self._scan()
        return tuple(sorted({*self._items, *self._pending}))

    def items(self) -> Iterator[tuple[str, T]]:
        """(name, item) for every name, loading plugins as needed."""
        for name in self.names():
            yield name, self.get(name)

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name in self.names()


ManeuverBuilder = Callable[[Mapping[str, Any], str], Maneuver]
"""``builder(spec, source) -> maneuver``; raises :class:`ConfigError` naming ``source`` and the field."""

MANEUVERS: Registry[ManeuverBuilder] = Registry("maneuver kind", "aerobat.maneuvers")


def register_maneuver(kind: str, builder: ManeuverBuilder, *, replace: bool = False) -> None:
    """Make :func:`from_spec` build specifications of ``kind`` with ``builder``.

    Parameters
    ----------
    kind : the value of ``spec["kind"]`` (lower-case identifier).
    builder : ``builder(spec, source)`` returning the maneuver; it raises
        :class:`~aerobat.errors.ConfigError` naming ``source`` and the field on bad input.
    replace : allow replacing an existing registration.
    """
    MANEUVERS.register(kind, builder, replace=replace)


def registered_kinds() -> tuple[str, ...]:
    """The kinds :func:`from_spec` can build, sorted."""
    return MANEUVERS.names()


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
    if not isinstance(source, str):
        raise ConfigError(f"source: expected a string (where the spec came from), got {type(source).__name__} "
                          f"{short_repr(source)}")
    if not isinstance(spec, Mapping):
        raise ConfigError(f"{source}: expected a table, got {type(spec).__name__}")
    kind = spec.get("kind")
    if not isinstance(kind, str):
        raise ConfigError(f"{source}.kind: expected a string naming the maneuver family, got {kind!r}")
    module = spec.get("module")
    if kind not in MANEUVERS and isinstance(module, str) and module.replace(".", "").replace("_", "").isalnum():
        try:  # a plugin's spec names its module; importing it registers the kind
            importlib.import_module(module)
        except ImportError as exc:
            raise ConfigError(f"{source}.module: the plugin module {module!r} of maneuver kind {kind!r} cannot be "
                              f"imported: {exc}") from None
    return MANEUVERS.get(kind, source=f"{source}.kind")(spec, source)


def parameters_of(spec: Mapping[str, Any], expected: int) -> tuple[Any, ...]:
    """The parameter specifications (meaning, unit, scale, bounds) of the maneuver a stored ``spec`` describes;
    none if it cannot be rebuilt here (a plug-in that is not installed) or has not ``expected`` parameters."""
    try:
        parameters = tuple(from_spec(spec, source="stored maneuver").parameters)
    except (ConfigError, ImportError, KeyError, TypeError, ValueError):
        return ()
    return parameters if len(parameters) == expected else ()
