"""The state a lab plant carries from one trial to the next, and its JSON form.

Every plant that can be paused and resumed (``get_state``/``set_state``, the core's
``StatefulPlant``) keeps the same kinds of things between trials: its random generator,
counters (trials flown, the radio tick), fractions such as the battery's thrust capacity in
(0, 1], and flat arrays of floats (the vehicle's true state, integrators, the start position).
:class:`StateLayout` names what one plant keeps; :meth:`StateLayout.encode` writes it as plain
JSON-ready values and :meth:`StateLayout.decode` reads it back into a checked
:class:`PlantState`, or raises one ``ValueError`` naming the field (``arena state.tick = -1:
expected an integer >= 0``). The JSON form is format 1: what the store holds from every earlier
version reads unchanged.

An array name with a dot lives in a nested table: ``vehicle.x`` is ``state["vehicle"]["x"]``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["FORMAT", "PlantState", "StateLayout"]

FORMAT = 1
"""The only state format this aerobat writes and reads."""


@dataclass(frozen=True)
class PlantState:
    """One plant's state between trials, decoded and checked.

    Attributes
    ----------
    rng : dict
        The generator's ``bit_generator.state`` (assign it to restore the generator).
    counters : Mapping[str, int]
        Non-negative integers by name (``trials_flown``, ``tick``).
    fractions : Mapping[str, float]
        Numbers in (0, 1] by name (``capacity``).
    arrays : Mapping[str, numpy.ndarray]
        Flat float64 arrays of finite numbers by name, each of the length asked for.
    """

    rng: dict[str, Any]
    counters: Mapping[str, int]
    fractions: Mapping[str, float]
    arrays: Mapping[str, np.ndarray]


def _plain_rng(rng: np.random.Generator) -> dict[str, Any]:
    state = rng.bit_generator.state
    return {key: (dict(value) if isinstance(value, Mapping) else value) for key, value in state.items()}


@dataclass(frozen=True)
class StateLayout:
    """What one plant keeps between trials, by kind.

    Parameters
    ----------
    plant : str
        The plant's name, first word of every error (``"arena"``).
    counters : tuple of str
        Names of the non-negative integer counters.
    fractions : tuple of str
        Names of the numbers in (0, 1].
    finite : bool
        Refuse arrays holding NaN or infinity (default). A plant whose true state may
        legitimately hold them after a diverged trial (it starts the next one afresh) says False.
    """

    plant: str
    counters: tuple[str, ...]
    fractions: tuple[str, ...] = ()
    finite: bool = True

    def encode(
        self,
        rng: np.random.Generator,
        counters: Mapping[str, int],
        fractions: Mapping[str, float],
        arrays: Mapping[str, np.ndarray],
    ) -> dict[str, Any]:
        """The state as JSON-ready plain values: ``format``, ``rng``, the counters, fractions and arrays."""
        state: dict[str, Any] = {"format": FORMAT, "rng": _plain_rng(rng)}
        state.update({name: int(counters[name]) for name in self.counters})
        state.update({name: float(fractions[name]) for name in self.fractions})
        for name, values in arrays.items():
            table, _, key = name.rpartition(".")
            target = state.setdefault(table, {}) if table else state
            target[key] = [float(v) for v in np.asarray(values).ravel()]
        return state

    def decode(
        self,
        state: object,
        rng: np.random.Generator,
        sizes: Mapping[str, int],
        *,
        padding: Mapping[str, float] | None = None,
    ) -> PlantState:
        """Check ``state`` (from :meth:`encode`) against this layout and read it.

        Parameters
        ----------
        state : object
            What :meth:`encode` wrote, typically read back from the store.
        rng : numpy.random.Generator
            The plant's generator: the stored one must be of its kind. Not changed here.
        sizes : Mapping[str, int]
            The arrays to read and the length each must have (they depend on the plant's
            configuration, e.g. whether it has onboard feedback).
        padding : Mapping[str, float], optional
            Arrays stored one value shorter by an earlier version, and the value to append
            (e.g. a model entry added later whose neutral value is 0).

        Raises
        ------
        ValueError
            A field is missing, of the wrong type, length or range, or the generator kind differs.
        """
        where = f"{self.plant} state"
        if not isinstance(state, Mapping):
            raise ValueError(f"{where}: expected a table, got {type(state).__name__}")
        tops = dict.fromkeys(name.partition(".")[0] for name in sizes)
        missing = [k for k in ("format", "rng", *self.counters, *self.fractions, *tops) if k not in state]
        if missing:
            raise ValueError(f"{where}: missing field(s) {', '.join(missing)}")
        if state["format"] != FORMAT:
            raise ValueError(f"{where}.format = {state['format']!r}: this aerobat reads format {FORMAT}")
        kind = rng.bit_generator.state["bit_generator"]
        stored = state["rng"]
        if not isinstance(stored, Mapping) or stored.get("bit_generator") != kind:
            raise ValueError(f"{where}.rng: expected a {kind} generator state")
        plain_rng = {k: (dict(v) if isinstance(v, Mapping) else v) for k, v in stored.items()}
        try:  # a copy's generator takes the state: the plant's own is only changed by the caller
            type(rng.bit_generator)().state = plain_rng
        except (TypeError, ValueError, KeyError) as exc:
            raise ValueError(f"{where}.rng: {exc}") from None
        counters = {}
        for name in self.counters:
            count = state[name]
            if isinstance(count, bool) or not isinstance(count, int) or count < 0:
                raise ValueError(f"{where}.{name} = {count!r}: expected an integer >= 0")
            counters[name] = count
        fractions = {}
        for name in self.fractions:
            value = state[name]
            if isinstance(value, bool) or not isinstance(value, int | float) or not 0.0 < value <= 1.0:
                raise ValueError(f"{where}.{name} = {value!r}: expected a number in (0, 1]")
            fractions[name] = float(value)
        pads = padding or {}
        arrays = {name: _floats(state, name, size, pads.get(name), where, self.finite) for name, size in sizes.items()}
        return PlantState(rng=plain_rng, counters=counters, fractions=fractions, arrays=arrays)


def _floats(
    state: Mapping[str, Any], name: str, size: int, pad: float | None, where: str, finite: bool
) -> np.ndarray:
    value: Any = state
    for part in name.split("."):
        if not isinstance(value, Mapping):
            raise ValueError(f"{where}.{name.rpartition('.')[0]}: expected a table")
        value = value.get(part)
    try:
        values = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{where}.{name}: expected a list of numbers") from None
    if pad is not None and values.shape == (size - 1,):
        values = np.append(values, pad)
    if values.shape != (size,):
        raise ValueError(f"{where}.{name}: expected {size} numbers, got {values.size}")
    if finite and not np.all(np.isfinite(values)):
        raise ValueError(f"{where}.{name}: expected finite numbers")
    return values
