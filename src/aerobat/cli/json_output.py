"""JSON that is JSON: what a ``--json`` prints, with every value a JSON parser reads.

Python's ``json.dumps`` writes ``NaN`` and ``Infinity`` for non-finite floats, which no JSON parser
but Python's accepts (``jq``, JavaScript's ``JSON.parse`` and strict parsers refuse the whole
document). A quantity that does not exist (a rise time with no step, the spread of a fixed
parameter, a correlation of a constant series) is ``null`` here, and NumPy's scalars and arrays
become numbers and lists.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["json_ready", "json_text"]


def json_ready(value: Any) -> Any:
    """``value`` with every non-finite float None, NumPy scalars and arrays plain numbers and lists, tuples lists,
    paths text and dataclasses dictionaries (recursively)."""
    if isinstance(value, bool | str | int) or value is None:
        return value
    if isinstance(value, float | np.floating):
        number = float(value)
        return number if math.isfinite(number) else None
    if isinstance(value, np.integer | np.bool_):
        return value.item()
    if isinstance(value, np.ndarray):
        return [json_ready(v) for v in value.tolist()]
    if isinstance(value, Mapping):
        return {str(k) if not isinstance(k, str) else k: json_ready(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_ready(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return json_ready(dataclasses.asdict(value))
    raise TypeError(f"{type(value).__name__} is not JSON-ready")


def json_text(value: Any) -> str:
    """``value`` (see :func:`json_ready`) as one line of strict JSON: never ``NaN`` or ``Infinity``."""
    return json.dumps(json_ready(value), allow_nan=False)
