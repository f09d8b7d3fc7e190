"""Bounds declared once, next to the field, and checked in one place.

A parameter dataclass declares what each field allows beside the field itself::

    @dataclass(frozen=True, kw_only=True)
    class Supervisor:
        settle_hold_s: float = bounded(0.1, Interval(0.0, 10.0, unit="s"))

        def __post_init__(self) -> None:
            validate(self)

and :func:`validate` checks every declared field, raising :class:`~aerobat.errors.ConfigError`
with one line that names the field, the value and the allowed range (the messages of
:func:`~aerobat.config.check_range` and :func:`~aerobat.config.check_int`). The file loaders
prefix it with the file and the table. Choices come from the enum or the ``Literal`` they belong
to (:class:`OneOf`), never from a copied list.

The declarations are data a test can read: :func:`constraints` lists a class's, and every
constraint says which values it refuses (:meth:`Interval.outside`), so a test derives
out-of-range inputs for every parameter class from the declarations themselves (as
scikit-learn's parameter constraints do).
"""

from __future__ import annotations

import dataclasses
import enum
import math
import typing
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any, Literal, TypeVar

from aerobat.config import check_int, check_number, check_range, short_repr
from aerobat.errors import ConfigError

__all__ = [
    "BOUNDS",
    "ITERATIONS",
    "MAX_ITERATIONS",
    "Constraint",
    "Integer",
    "Interval",
    "Items",
    "OneOf",
    "SEEDS",
    "Span",
    "bounded",
    "choices_of",
    "constraints",
    "required",
    "validate",
]

T = TypeVar("T")

MAX_ITERATIONS = 10_000
"""The most measured trials one :func:`~aerobat.core.learning.learn` call takes: every record (with its
trial) is kept in memory for the returned session, tens of kilobytes each (a durable session has the
same cap)."""

BOUNDS = "aerobat.bounds"
"""The key of a field's constraint in its ``dataclasses.field`` metadata."""

Limit = float | str | None
"""A limit of a range: a number, the name of another attribute of the same object (a field or a
property, read when checking), or None for no limit."""


class Constraint:
    """What one field allows: :meth:`check` raises :class:`ConfigError` for anything else."""

    def check(self, name: str, value: Any, owner: Any = None) -> Any:
        """``value`` (converted where the constraint says so) if allowed; :class:`ConfigError` otherwise."""
        raise NotImplementedError

    def describe(self, owner: Any = None) -> str:
        """What is allowed, as the error message says it (``[0, 10]``, ``1 … 100``, ``'a', 'b'``)."""
        raise NotImplementedError

    def outside(self, owner: Any = None) -> list[Any]:
        """Values just outside what is allowed (for tests that derive bad inputs from declarations)."""
        raise NotImplementedError


def _resolve(limit: Limit, owner: Any) -> float | None:
    if isinstance(limit, str):
        if owner is None:
            raise TypeError(f"a limit named {limit!r} needs the object it belongs to")
        return float(getattr(owner, limit))
    return limit


@dataclass(frozen=True)
class Interval(Constraint):
    """A finite real number in a range (scikit-learn's ``Interval(Real, low, high, closed=…)``).

    Attributes
    ----------
    low, high : the limits, None for none, or the name of another attribute of the same object.
    closed : which limits are allowed themselves: ``"both"``, ``"left"`` (low), ``"right"`` (high)
        or ``"neither"``.
    unit : said after the range in messages (``"kg"``, ``"m/s², eq 24: …"``).
    as_float : store the value as a Python float (NumPy scalars accepted); otherwise it is kept as given.
    """

    low: Limit = None
    high: Limit = None
    closed: Literal["both", "left", "right", "neither"] = "both"
    unit: str = ""
    as_float: bool = False

    @property
    def low_inclusive(self) -> bool:
        """True if the low limit itself is allowed."""
        return self.closed in ("both", "left")

    @property
    def high_inclusive(self) -> bool:
        """True if the high limit itself is allowed."""
        return self.closed in ("both", "right")

    def check(self, name: str, value: Any, owner: Any = None) -> Any:
        """``value`` if a finite number in the range (a float with ``as_float``); :class:`ConfigError` otherwise."""
        low, high = _resolve(self.low, owner), _resolve(self.high, owner)
        if self.as_float:
            return check_number(name, value, low=low, high=high, low_inclusive=self.low_inclusive,
                                high_inclusive=self.high_inclusive, unit=self.unit)
        check_range(name, value, low=low, high=high, low_inclusive=self.low_inclusive,
                    high_inclusive=self.high_inclusive, unit=self.unit)
        return value

    def describe(self, owner: Any = None) -> str:
        """The range as messages say it: ``[0, 1]``, ``(0, 600]``, ``>= 0``, ``< 0``."""
        low, high = _resolve(self.low, owner), _resolve(self.high, owner)
        lo_inc, hi_inc = self.low_inclusive, self.high_inclusive
        if low is not None and high is not None:
            text = f"{'[' if lo_inc else '('}{low:g}, {high:g}{']' if hi_inc else ')'}"
        elif low is not None:
            text = f"{'>=' if lo_inc else '>'} {low:g}"
        elif high is not None:
            text = f"{'<=' if hi_inc else '<'} {high:g}"
        else:
            text = "any finite value"
        return f"{text} ({self.unit})" if self.unit else text

    def outside(self, owner: Any = None) -> list[Any]:
        """The limits themselves where open, the next floats beyond them where closed."""
        low, high = _resolve(self.low, owner), _resolve(self.high, owner)
        values: list[Any] = []
        if low is not None:
            values.append(math.nextafter(low, -math.inf) if self.low_inclusive else low)
        if high is not None:
            values.append(math.nextafter(high, math.inf) if self.high_inclusive else high)
        return values

    def bounds(self) -> tuple[float, float]:
        """``(low, high)`` for a command-line option (both limits must be numbers)."""
        if not isinstance(self.low, int | float) or not isinstance(self.high, int | float):
            raise TypeError("an Interval without two numeric limits has no (low, high)")
        return float(self.low), float(self.high)


@dataclass(frozen=True)
class Integer(Constraint):
    """An integer (a NumPy integer too, never a bool or a float) in ``low … high``, stored as an int."""

    low: int | None = None
    high: int | None = None

    def check(self, name: str, value: Any, owner: Any = None) -> int:
        """``value`` as an int if in range; :class:`ConfigError` otherwise (:func:`~aerobat.config.check_int`)."""
        return check_int(name, value, low=self.low, high=self.high)

    def describe(self, owner: Any = None) -> str:
        """The range as messages say it: ``1 … 10000``."""
        return f"{self.low if self.low is not None else '…'} … {self.high if self.high is not None else '…'}"

    def outside(self, owner: Any = None) -> list[Any]:
        """One below the low limit, one above the high one."""
        return [v for v in (None if self.low is None else self.low - 1,
                            None if self.high is None else self.high + 1) if v is not None]

    def bounds(self) -> tuple[int, int]:
        """``(low, high)`` for a command-line option (both limits must be set)."""
        if self.low is None or self.high is None:
            raise TypeError("an open-ended Integer has no (low, high)")
        return self.low, self.high


ITERATIONS = Integer(1, MAX_ITERATIONS)
"""The one allowed range of a number of measured iterations: of a ``learn`` call, of a durable
session's target, of ``aerobat learn --trials`` (1 … :data:`MAX_ITERATIONS`). Here, not in
:mod:`aerobat.core.learning`, so that the store checks it without loading the method."""

SEEDS = Integer(0, 2**63 - 1)
"""The one allowed range of a plant's random seed (:class:`~aerobat.plants.PlantChoice`, the arena,
``--seed``): any seed NumPy's generator takes that the store's SQLite INTEGER column holds."""


def choices_of(kind: Any) -> tuple[Any, ...]:
    """The allowed values of an enum (its members' values), a ``Literal[...]`` or a sequence."""
    if isinstance(kind, type) and issubclass(kind, enum.Enum):
        return tuple(member.value for member in kind)
    if typing.get_origin(kind) is Literal:
        return typing.get_args(kind)
    return tuple(kind)


@dataclass(frozen=True)
class OneOf(Constraint):
    """One of the values of an enum or a ``Literal`` (the enum's members pass as themselves).

    With an enum, a value given as text becomes the member (``"none"`` → ``FeedbackScheme.NONE``).
    ``unit`` is said after the choices in messages (``1000, 2000 (Hz)``).
    """

    kind: Any
    unit: str = ""

    @property
    def choices(self) -> tuple[Any, ...]:
        """The allowed values, derived from :attr:`kind`."""
        return choices_of(self.kind)

    def check(self, name: str, value: Any, owner: Any = None) -> Any:
        """``value`` (the enum member, for an enum) if one of the choices; :class:`ConfigError` otherwise."""
        is_enum = isinstance(self.kind, type) and issubclass(self.kind, enum.Enum)
        if is_enum and isinstance(value, self.kind):
            return value
        try:
            allowed = not isinstance(value, bool) and value in self.choices
        except (TypeError, ValueError):  # an unhashable value, or an array (whose == is elementwise), is none
            allowed = False
        if not allowed:
            raise ConfigError(f"{name} = {short_repr(value)}: allowed {self.describe()}")
        return self.kind(value) if is_enum else value

    def describe(self, owner: Any = None) -> str:
        """The choices, quoted, then the unit if any: ``'inverse', 'tsvd', 'damped'``, ``1000, 2000 (Hz)``."""
        text = ", ".join(map(repr, self.choices))
        return f"{text} ({self.unit})" if self.unit else text

    def outside(self, owner: Any = None) -> list[Any]:
        """A string that is none of the choices."""
        return ["not-" + "-".join(map(str, self.choices))]


@dataclass(frozen=True)
class Items(Constraint):
    """A tuple of a fixed length whose items each have a constraint; messages name ``field[label]``.

    Attributes
    ----------
    items : one constraint per item.
    labels : what messages call the items (``"x", "y", "z"``; default 0, 1, …).
    what : what a value of the wrong shape is told was expected (default ``"n values"``).
    """

    items: tuple[Constraint, ...]
    labels: tuple[Any, ...] = ()
    what: str = ""

    @classmethod
    def each(cls, constraint: Constraint, labels: Sequence[Any] | int, what: str = "") -> Items:
        """The same constraint on every item; ``labels`` may be the number of items."""
        names = tuple(range(labels)) if isinstance(labels, int) else tuple(labels)
        return cls((constraint,) * len(names), names, what)

    def _labels(self) -> tuple[Any, ...]:
        return self.labels or tuple(range(len(self.items)))

    def check(self, name: str, value: Any, owner: Any = None) -> Any:
        """``value`` (as a tuple of the checked items) if every item is allowed; :class:`ConfigError` otherwise."""
        if not isinstance(value, tuple | list) or len(value) != len(self.items):
            raise ConfigError(f"{name} = {short_repr(value)}: expected {self.what or f'{len(self.items)} values'}")
        checked = tuple(c.check(f"{name}[{label}]", v, owner)
                        for c, label, v in zip(self.items, self._labels(), value, strict=True))
        same = isinstance(value, tuple) and all(a is b for a, b in zip(checked, value, strict=True))
        return value if same else checked

    def describe(self, owner: Any = None) -> str:
        """Each item's range, by label."""
        return "; ".join(f"[{label}] {c.describe(owner)}" for c, label in zip(self.items, self._labels(), strict=True))

    def outside(self, owner: Any = None) -> list[Any]:
        """Not used for tuples: see :meth:`outside_items`."""
        return []

    def outside_items(self, default: Sequence[Any], owner: Any = None) -> list[tuple[str, tuple[Any, ...], str]]:
        """``(label, tuple, allowed)``: ``default`` with one item replaced by a value outside its range."""
        out = []
        for i, (c, label) in enumerate(zip(self.items, self._labels(), strict=True)):
            for bad in c.outside(owner):
                values = list(default)
                values[i] = bad
                out.append((f"[{label}]", tuple(values), c.describe(owner)))
        return out


@dataclass(frozen=True)
class Span(Constraint):
    """A range ``(low, high)`` of two numbers: ``low`` within :attr:`start`, ``high`` at least ``low``
    (above it, with :attr:`strict`) and at most :attr:`end` if given.

    Messages name ``field[0]`` and ``field[1]``; ``high`` below ``low`` is told ``allowed >= low``
    (``> low``), or ``[low, end]`` (``(low, end]``).
    """

    start: Interval = Interval()
    strict: bool = False
    end: float | None = None

    def _items(self, low: Any) -> Items:
        closed: Literal["both", "right", "left", "neither"]
        if self.end is None:
            closed = "neither" if self.strict else "both"
        else:
            closed = "right" if self.strict else "both"
        high = Interval(low=low, high=self.end, closed=closed, unit=self.start.unit)
        return Items((self.start, high), what="two numbers (low, high)")

    def check(self, name: str, value: Any, owner: Any = None) -> Any:
        """``value`` (as a tuple) if a range starting within :attr:`start`; :class:`ConfigError` otherwise."""
        if not isinstance(value, tuple | list) or len(value) != 2:
            raise ConfigError(f"{name} = {short_repr(value)}: expected two numbers (low, high)")
        low = self.start.check(f"{name}[0]", value[0], owner)
        return self._items(low).check(name, value, owner)

    def describe(self, owner: Any = None) -> str:
        """The range of the low end; the high end is at least the low one."""
        upto = "" if self.end is None else f", <= {self.end:g}"
        return f"[0] {self.start.describe(owner)}; [1] {'>' if self.strict else '>='} [0]{upto}"

    def outside(self, owner: Any = None) -> list[Any]:
        """Not used for ranges: see :meth:`outside_items`."""
        return []

    def outside_items(self, default: Sequence[Any], owner: Any = None) -> list[tuple[str, tuple[Any, ...], str]]:
        """``(label, tuple, allowed)``: ``default`` with its low end outside :attr:`start`, or its high end below it."""
        return self._items(default[0]).outside_items(default, owner)


def bounded(default: T, constraint: Constraint, **field_options: Any) -> T:
    """A dataclass field with a default and its declared constraint (``dataclasses.field`` options too)."""
    metadata = {**field_options.pop("metadata", {}), BOUNDS: constraint}
    return dataclasses.field(default=default, metadata=metadata, **field_options)  # type: ignore[no-any-return]


def required(constraint: Constraint, **field_options: Any) -> Any:
    """A dataclass field without a default, with its declared constraint (``dataclasses.field`` options too)."""
    metadata = {**field_options.pop("metadata", {}), BOUNDS: constraint}
    return dataclasses.field(metadata=metadata, **field_options)


@cache
def _declared(cls: type) -> tuple[tuple[str, Constraint], ...]:
    return tuple((f.name, f.metadata[BOUNDS]) for f in dataclasses.fields(cls) if BOUNDS in f.metadata)


def constraints(cls: type) -> dict[str, Constraint]:
    """The declared constraint of each bounded field of dataclass ``cls``, in field order."""
    return dict(_declared(cls))


def validate(obj: Any, *, only: Iterable[str] | None = None, skip: Iterable[str] = ()) -> None:
    """Check every declared field of ``obj`` (or those in ``only``, less those in ``skip``), in field order.

    A constraint that converts (an enum from its text, a float from a NumPy scalar) stores the
    converted value on ``obj`` (frozen dataclasses included). The first field out of range raises
    :class:`ConfigError`.
    """
    wanted = None if only is None else set(only)
    skipped = set(skip)
    for name, constraint in _declared(type(obj)):  # type: ignore[arg-type]
        if (wanted is not None and name not in wanted) or name in skipped:
            continue
        value = getattr(obj, name)
        checked = constraint.check(name, value, obj)
        if checked is not value:
            object.__setattr__(obj, name, checked)
