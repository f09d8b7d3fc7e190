"""One codec for the core's frozen dataclasses: their fields as plain values and back, by the fields' types.

The core's records (:class:`~aerobat.core.outcomes.Iteration`, :class:`~aerobat.core.design.Design`,
:class:`~aerobat.core.notes.IterationNote`) and the store's records are frozen dataclasses
of numbers, strings, enums, numpy arrays and tuples of such dataclasses. :func:`encode`
turns chosen fields into plain values, :func:`decode` builds the dataclass back from them,
reading each field's type hint; two :class:`Form` s differ only in how arrays, booleans and
nested records are kept:

* :attr:`Form.JSON` (``session.json``, study specifications and results, exports): an
  array as nested lists of floats, its non-finite entries as ``null`` (``NaN`` when read);
  a boolean as a boolean; a tuple as a list (a record in it as a table).
* :attr:`Form.COLUMNS` (the store's tables): an array as little-endian float64 bytes
  (exact, every bit); a boolean as 0/1; a tuple as the JSON text of that list.

In both, an enum is its value and a numpy scalar a Python number. Decoding takes only the
fields present (the others keep their defaults) and refuses a value its type refuses
(:class:`ValueError`: an unknown enum value, bytes that are no float64 array).
"""

from __future__ import annotations

import dataclasses
import json
import math
import types
import typing
from collections.abc import Callable, Iterable, Mapping
from enum import Enum
from typing import Any

import numpy as np

__all__ = ["Form", "decode", "decode_value", "encode", "encode_value", "pack_f8", "unpack_f8"]


class Form(Enum):
    """Where the values go: JSON documents, or the store's columns."""

    JSON = "json"
    COLUMNS = "columns"


def pack_f8(values: Any) -> bytes:
    """An array as little-endian float64 bytes (every bit kept)."""
    return np.ascontiguousarray(np.asarray(values, dtype=np.float64), dtype="<f8").tobytes()


def unpack_f8(blob: bytes | None, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """The float64 array :func:`pack_f8` wrote (reshaped to ``shape`` if given)."""
    array = np.frombuffer(blob or b"", dtype="<f8").astype(np.float64)
    return array.reshape(shape) if shape is not None else array


def _finite_or_none(values: Any) -> Any:
    if isinstance(values, list):
        return [_finite_or_none(v) for v in values]
    return values if math.isfinite(values) else None


def _nan_for_none(values: Any) -> Any:
    if isinstance(values, list | tuple):
        return [_nan_for_none(v) for v in values]
    return math.nan if values is None else values


def encode_value(value: Any, form: Form) -> Any:
    """One value as ``form`` keeps it (see the module's description)."""
    if isinstance(value, np.ndarray):
        return pack_f8(value) if form is Form.COLUMNS else _finite_or_none(np.asarray(value, dtype=float).tolist())
    if isinstance(value, Enum):
        return value.value
    if isinstance(value, bool | np.bool_):
        return int(value) if form is Form.COLUMNS else bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, tuple):
        items = [encode(v, form=Form.JSON) if dataclasses.is_dataclass(v) else encode_value(v, Form.JSON)
                 for v in value]
        return json.dumps(items, separators=(",", ":")) if form is Form.COLUMNS else items
    return value


def encode(obj: Any, names: Iterable[str] | None = None, *, form: Form,
           keys: Mapping[str, str] | None = None) -> dict[str, Any]:
    """The fields ``names`` of a dataclass (default: all) as ``form`` keeps them, under ``keys[name]`` if renamed.

    A name may also be a property of ``obj`` (a value derived from its fields).
    """
    chosen = [f.name for f in dataclasses.fields(obj)] if names is None else list(names)
    keys = keys or {}
    return {keys.get(name, name): encode_value(getattr(obj, name), form) for name in chosen}


Decoder = Callable[[Any, "tuple[int, ...] | None"], Any]


def _decoder(hint: Any, form: Form) -> Decoder | None:
    """How to turn a stored value back into a field of type ``hint`` (None: as it is)."""
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    optional = isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union
    inner = args[0] if optional and len(args) == 1 else hint

    def nullable(convert: Callable[[Any], Any]) -> Decoder:
        return lambda v, shape: None if v is None and optional else convert(v)

    if inner is np.ndarray:
        if form is Form.COLUMNS:
            return lambda v, shape: None if v is None and optional else unpack_f8(v, shape)
        return nullable(lambda v: np.asarray(_nan_for_none(v), dtype=np.float64))
    if isinstance(inner, type) and issubclass(inner, Enum):
        return nullable(inner)
    if inner is bool:
        return lambda v, shape: bool(v)
    if inner is float:
        return lambda v, shape: None if v is None and optional else (math.nan if v is None else float(v))
    if inner is int:
        return nullable(int)
    if inner is str and form is Form.JSON:
        return nullable(str)
    item = typing.get_args(inner)
    if typing.get_origin(inner) is tuple and len(item) == 2 and item[1] is Ellipsis:
        element = item[0]
        record = isinstance(element, type) and dataclasses.is_dataclass(element)

        def items(v: Any) -> tuple[Any, ...]:
            listed = json.loads(v) if isinstance(v, str | bytes) else v
            if not isinstance(listed, list | tuple) or (record and not all(isinstance(t, Mapping) for t in listed)):
                raise ValueError(f"expected a list of {getattr(element, '__name__', element)}, got "
                                 f"{type(listed).__name__}")
            if record:
                return tuple(decode(element, t, form=Form.JSON) for t in listed)
            return tuple(decode_value(element, e, Form.JSON) for e in listed)

        return lambda v, shape: () if v is None else items(v)
    return None


_DECODERS: dict[tuple[type[Any], Form], tuple[tuple[str, Decoder | None], ...]] = {}


def _decoders(cls: type[Any], form: Form) -> tuple[tuple[str, Decoder | None], ...]:
    """Each field of the dataclass ``cls`` with how its value is decoded (read once per class and form)."""
    if (cls, form) not in _DECODERS:
        hints = typing.get_type_hints(cls)
        _DECODERS[cls, form] = tuple((f.name, _decoder(hints[f.name], form)) for f in dataclasses.fields(cls))
    return _DECODERS[cls, form]


def decode_value(hint: Any, value: Any, form: Form, shape: tuple[int, ...] | None = None) -> Any:
    """One value of type ``hint`` from what ``form`` keeps (the inverse of :func:`encode_value`)."""
    convert = _decoder(hint, form)
    return value if convert is None else convert(value, shape)


def decode(cls: type[Any], table: Mapping[str, Any], *, form: Form, keys: Mapping[str, str] | None = None,
           shapes: Mapping[str, tuple[int, ...]] | None = None, **given: Any) -> Any:
    """A dataclass ``cls`` from ``table``: every field not ``given`` decoded from ``table[keys.get(name, name)]``.

    Fields missing from ``table`` keep their defaults (a field without a default: :class:`TypeError`).
    Raises :class:`ValueError` for a value its type refuses.
    """
    values = dict(given)
    keys = keys or {}
    for name, convert in _decoders(cls, form):
        key = keys.get(name, name)
        if name in values or key not in table:
            continue
        raw = table[key]
        values[name] = raw if convert is None else convert(raw, (shapes or {}).get(name))
    return cls(**values)
