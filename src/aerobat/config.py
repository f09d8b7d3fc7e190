"""Validated construction of parameter dataclasses from TOML tables.

Every parameter set in aerobat is a frozen dataclass that validates itself in
``__post_init__``. This module adds what a *file* needs on top of that: unknown
keys, wrong types and missing fields are reported with the file name and the
table they were found in, so a user can fix the file without reading code.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import os
import tomllib
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from aerobat.errors import ConfigError

__all__ = [
    "replace_sections",
    "ConfigError",
    "as_float_array",
    "as_path",
    "check_finite",
    "check_int",
    "check_number",
    "check_range",
    "check_real",
    "check_type",
    "dataclass_from_table",
    "dataclass_to_table",
    "read_toml",
    "short_repr",
    "write_file",
    "table_field",
]

T = TypeVar("T")


def check_finite(name: str, value: float, unit: str = "") -> None:
    """Raise :class:`ConfigError` unless ``value`` is a finite real number."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{name} must be a number, got {type(value).__name__} {short_repr(value)}")
    try:
        finite = math.isfinite(value)
    except OverflowError:  # an integer beyond any float
        raise ConfigError(f"{name} = {short_repr(value)} is too large{_unit(unit)}") from None
    if not finite:
        raise ConfigError(f"{name} = {value} must be finite{_unit(unit)}")


def check_real(name: str, value: Any) -> None:
    """Raise :class:`ConfigError` unless ``value`` is a real number a float can hold (nan and inf pass)."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
        raise ConfigError(f"{name} must be a number, got {type(value).__name__} {short_repr(value)}")
    if isinstance(value, numbers.Integral) and abs(int(value)) > 2**1023:
        raise ConfigError(f"{name} = {short_repr(value)} is too large")


def check_number(name: str, value: Any, *, low: float | None = None, high: float | None = None,
                 low_inclusive: bool = True, high_inclusive: bool = True, unit: str = "") -> float:
    """``value`` as a float: a finite real number (NumPy scalars too, never a bool) within the range."""
    if isinstance(value, np.integer | np.floating) and not isinstance(value, np.bool_):
        value = value.item()
    check_range(name, value, low=low, high=high, low_inclusive=low_inclusive, high_inclusive=high_inclusive,
                unit=unit)
    return float(value)


def check_int(name: str, value: Any, *, low: int | None = None, high: int | None = None) -> int:
    """``value`` as an int: an integer (a NumPy integer too, never a bool or a float) within [low, high]."""
    if isinstance(value, np.integer):
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ConfigError(f"{name} must be an integer, got {type(value).__name__} {short_repr(value)}")
    if (low is not None and value < low) or (high is not None and value > high):
        allowed = f"{low if low is not None else '…'} … {high if high is not None else '…'}"
        raise ConfigError(f"{name} = {short_repr(value)} is out of range: allowed {allowed}")
    return value


def as_float_array(name: str, value: Any, shape: tuple[int, ...] | None = None, *, finite: bool = True) -> Any:
    """``value`` as a float array of ``shape``, finite; :class:`ConfigError` naming ``name`` otherwise."""
    if isinstance(value, str | bytes | Mapping) or value is None:
        raise ConfigError(f"{name}: expected an array of numbers, got {type(value).__name__} {short_repr(value)}")
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError, OverflowError) as exc:
        raise ConfigError(f"{name}: expected an array of numbers, got {short_repr(value)} ({exc})") from None
    if shape is not None and array.shape != shape:
        raise ConfigError(f"{name} must have shape {shape}, got {array.shape}")
    if finite and not np.all(np.isfinite(array)):
        raise ConfigError(f"{name} contains non-finite values")
    return array


def check_range(
    name: str,
    value: float,
    *,
    low: float | None = None,
    high: float | None = None,
    low_inclusive: bool = True,
    high_inclusive: bool = True,
    unit: str = "",
) -> None:
    """Raise :class:`ConfigError` naming ``name``, ``value`` and the allowed range if out of it."""
    check_finite(name, value, unit)
    ok = True
    if low is not None:
        ok &= value >= low if low_inclusive else value > low
    if high is not None:
        ok &= value <= high if high_inclusive else value < high
    if not ok:
        allowed = _describe(low, high, low_inclusive, high_inclusive)
        raise ConfigError(f"{name} = {value:g} is out of range: allowed {allowed}{_unit(unit)}")


def _describe(low: float | None, high: float | None, lo_inc: bool, hi_inc: bool) -> str:
    if low is not None and high is not None:
        return f"{'[' if lo_inc else '('}{low:g}, {high:g}{']' if hi_inc else ')'}"
    if low is not None:
        return f"{'>=' if lo_inc else '>'} {low:g}"
    if high is not None:
        return f"{'<=' if hi_inc else '<'} {high:g}"
    return "any finite value"


def _unit(unit: str) -> str:
    return f" ({unit})" if unit else ""


def short_repr(value: Any, limit: int = 60) -> str:
    """``repr(value)``, cut to ``limit`` characters (for messages about values of the wrong type)."""
    try:
        text = repr(value)
    except Exception:  # noqa: BLE001 - a value whose repr fails is still described
        text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[: limit - 1] + "…"


def as_path(value: Any, name: str = "path") -> Path:
    """``value`` as a :class:`~pathlib.Path` (from a str or an ``os.PathLike``); :class:`ConfigError` otherwise."""
    if not isinstance(value, str | os.PathLike):
        raise ConfigError(f"{name}: expected a file path (str or pathlib.Path), got {type(value).__name__} "
                          f"{short_repr(value)}")
    try:
        path = Path(value)
    except TypeError as exc:  # an os.PathLike whose __fspath__ returns bytes or nonsense
        raise ConfigError(f"{name}: expected a file path, got {short_repr(value)} ({exc})") from None
    if "\x00" in str(path):
        raise ConfigError(f"{name} {str(path)!r}: a file path cannot contain a NUL character")
    return path


def read_toml(path: str | Path, option: str | None = None) -> dict[str, Any]:
    """Read a TOML file (a regular file, at most 16 MiB), turning I/O and syntax problems into :class:`ConfigError`."""
    from aerobat.fileio import read_input_text

    if isinstance(path, str) and not path.strip():  # Path("") is the working folder
        raise ConfigError(f"{option or 'TOML file'}: empty file name")
    path = as_path(path, option or "path")
    text = read_input_text(path, option, what="TOML file")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML: {exc}") from None
    except RecursionError:
        raise ConfigError(f"{path}: invalid TOML: nested too deeply") from None


def write_file(path: Any, text: str, name: str = "path") -> Path:
    """Write ``text`` to ``path`` atomically, never over a store: :class:`ConfigError` for a path that is not one
    or must not be written, :class:`~aerobat.errors.OutputError` if writing fails."""
    from aerobat.fileio import write_output

    path = as_path(path, name)
    return write_output(path, text)


def check_type(name: str, value: Any, expected: type | tuple[type, ...], what: str) -> Any:
    """``value`` if it is an instance of ``expected``; :class:`ConfigError` naming ``name`` and what came otherwise."""
    if not isinstance(value, expected):
        raise ConfigError(f"{name}: expected {what}, got {type(value).__name__} {short_repr(value)}")
    return value


def _coerce(value: Any, annotation: Any, where: str) -> Any:
    """Check ``value`` against a field annotation and convert lists to tuples."""
    origin = typing.get_origin(annotation)
    if annotation is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{where}: expected a number, got {type(value).__name__} {value!r}")
        return float(value)
    if annotation is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {type(value).__name__} {value!r}")
        return value
    if annotation is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if annotation is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {type(value).__name__} {value!r}")
        return value
    if origin is tuple:
        args = typing.get_args(annotation)
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{where}: expected an array, got {type(value).__name__} {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(f"{where}: expected an array of {len(args)} values, got {len(value)}")
        return tuple(_coerce(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args, strict=True)))
    if origin is typing.Literal:
        choices = typing.get_args(annotation)
        if value not in choices:
            raise ConfigError(f"{where}: expected one of {', '.join(map(repr, choices))}, got {value!r}")
        return value
    if origin in (typing.Union, types.UnionType):
        members = [a for a in typing.get_args(annotation) if a is not type(None)]
        return _coerce(value, members[0], where)
    if dataclasses.is_dataclass(annotation):
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where}: expected a table, got {type(value).__name__}")
        return dataclass_from_table(annotation, value, source=where)  # type: ignore[arg-type]
    return value


def dataclass_from_table(cls: type[T], table: Mapping[str, Any], *, source: str) -> T:
    """Build ``cls`` from a TOML table, with errors that name ``source`` and the field.

    Missing fields take the dataclass defaults; unknown keys are an error (they are
    almost always typos).
    """
    if not isinstance(table, Mapping):
        raise ConfigError(f"{source}: expected a table, got {type(table).__name__}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(table) - set(fields))
    if unknown:
        raise ConfigError(f"{source}: unknown field(s) {', '.join(unknown)}; allowed: {', '.join(fields)}")
    kwargs = {}
    for name, value in table.items():
        kwargs[name] = _coerce(value, hints[name], f"{source}.{name}")
    missing = [
        n for n, f in fields.items()
        if n not in kwargs and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    ]
    if missing:
        raise ConfigError(f"{source}: missing required field(s) {', '.join(missing)}")
    try:
        return cls(**kwargs)
    except ValueError as exc:  # the dataclass's own validation (ConfigError included)
        text = str(exc)
        raise ConfigError(text if text.startswith(source) else f"{source}: {text}") from None


def dataclass_to_table(obj: Any) -> dict[str, Any]:
    """Turn a (nested) parameter dataclass into TOML-ready plain values."""
    out: dict[str, Any] = {}
    for field in dataclasses.fields(obj):
        value = getattr(obj, field.name)
        if dataclasses.is_dataclass(value):
            out[field.name] = dataclass_to_table(value)
        elif isinstance(value, tuple):
            out[field.name] = list(value)
        else:
            out[field.name] = value
    return out


def table_field(table: Mapping[str, Any], name: str, source: str, expected: type | tuple[type, ...],
                what: str) -> Any:
    """``table[name]``, checked against ``expected`` (bool is never a number), finite if a float.

    Raises :class:`ConfigError` naming ``source.name``, what was expected and what was found.
    """
    if name not in table:
        raise ConfigError(f"{source}: missing required field {name}")
    value = table[name]
    if isinstance(value, bool) and bool not in (expected if isinstance(expected, tuple) else (expected,)):
        raise ConfigError(f"{source}.{name}: expected {what}, got {type(value).__name__} {value!r}")
    if not isinstance(value, expected):
        raise ConfigError(f"{source}.{name}: expected {what}, got {type(value).__name__} {value!r}")
    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(f"{source}.{name} = {value}: must be finite")
    return value


def replace_sections(obj: Any, sections: Mapping[str, Any]) -> Any:
    """Copy of a dataclass of sections with whole sections or ``section__field=value`` changes."""
    changes: dict[str, Any] = {}
    for key, value in sections.items():
        if "__" in key:
            sec, fld = key.split("__", 1)
            current = changes.get(sec, getattr(obj, sec))
            changes[sec] = dataclasses.replace(current, **{fld: value})
        else:
            changes[key] = value
    return dataclasses.replace(obj, **changes)
