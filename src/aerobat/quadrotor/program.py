"""Command programs: the onboard "command generator" of Sect. 10.2.

A program is a list of switches — time, channel, value — exactly as the paper's
vehicles store maneuvers onboard. Channels:

==================  =====  ==========================================================
``collective``      m/s²   mass-normalized collective thrust command f̂/m
``rate_p/q/r``      rad/s  body-rate command offsets p̂, q̂, r̂
``accel_p/q/r``     rad/s² body angular accelerations, integrated from 0 into rates
==================  =====  ==========================================================

Each channel holds the value of its latest switch (zero-order). Before a
channel's first switch it holds its hover value (collective g, everything else
0). The body-rate command on an axis is ``rate_x(t) + ∫_0^t accel_x dτ`` (Sect. 8
defines flips by accelerations, Sect. 9 translations by rates).

Ramp-downs (Sect. 7.2) are envelopes over the last ``collective_s`` /
``rates_s`` seconds of the program that pull the command linearly to its hover
value, reaching it exactly at ``duration_s``:
``cmd(t) = hover + w(t)·(raw(t) − hover)``, ``w(t) = min(1, (T − t)/T_ramp)``.

For integration a program is compiled to *segments*: breakpoints
``t_0 = 0 < … < t_K = T`` and, per segment and channel (collective, p̂, q̂, r̂),
quadratic coefficients in local time ``τ = t − t_k``. Every command value the
simulator uses comes from those coefficients, so continuous-time and sampled
playback read the same program.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from aerobat.config import check_type, read_toml, short_repr, write_file
from aerobat.core.bounds import Interval, bounded, required, validate
from aerobat.errors import ConfigError

__all__ = [
    "CHANNELS",
    "MANEUVER_RAMP_S",
    "CompiledProgram",
    "Program",
    "RampDown",
    "Switch",
    "load_program",
    "save_program",
]

CHANNELS = ("collective", "rate_p", "rate_q", "rate_r", "accel_p", "accel_q", "accel_r")
CHANNEL_UNITS = {
    "collective": "m/s²",
    "rate_p": "rad/s",
    "rate_q": "rad/s",
    "rate_r": "rad/s",
    "accel_p": "rad/s²",
    "accel_q": "rad/s²",
    "accel_r": "rad/s²",
}
# Generous sanity bounds: a value outside them is a unit mistake, not a maneuver.
CHANNEL_LIMITS = {"collective": (0.0, 200.0), "rate": (-100.0, 100.0), "accel": (-1e4, 1e4)}
MAX_DURATION_S = 600.0
_RAMP = Interval(0.0, None, unit="s")
MANEUVER_RAMP_S = Interval(0.0, 1.0, unit="s", as_float=True)
"""The ramp-down a maneuver family may ask for [s] (``MultiFlip.ramp_collective_s``, ``Translation.ramp_s``,
``--ramp-s``); a program's own :class:`RampDown` may be longer."""


def _channel_limits(channel: str) -> tuple[float, float]:
    return CHANNEL_LIMITS[channel.split("_")[0]]


def _finite(value: float) -> bool:
    """math.isfinite, False for an integer beyond any float (instead of OverflowError)."""
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


@dataclass(frozen=True, kw_only=True)
class Switch:
    """At ``time_s`` [s], set ``channel`` to ``value`` (units per channel, see module doc)."""

    time_s: float
    channel: str
    value: float


def make_switch(time_s: float, channel: str, value: float) -> Switch:
    """``Switch(time_s=…, channel=…, value=…)``, the same object, built at a third of the cost of the frozen
    dataclass's ``__init__`` (maneuvers build thousands per design; :class:`Program` checks every switch)."""
    switch = _new(Switch)
    fields = switch.__dict__
    fields["time_s"] = time_s
    fields["channel"] = channel
    fields["value"] = value
    return switch


_new = object.__new__


@dataclass(frozen=True, kw_only=True)
class RampDown:
    """Ramp-down envelopes to hover over the program's last seconds (Sect. 7.2).

    Attributes
    ----------
    collective_s : ramp duration for the collective command [s]; 0 disables it.
    rates_s : ramp duration for the body-rate commands [s]; 0 disables it.
    """

    collective_s: float = bounded(0.0, _RAMP)
    rates_s: float = bounded(0.0, _RAMP)

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True, kw_only=True)
class Program:
    """A maneuver program: switches on command channels over ``[0, duration_s]``.

    Attributes
    ----------
    switches : the switch list; order does not matter, it is sorted on compile.
    duration_s : end of the maneuver [s]; after it the vehicle's supervisor takes over.
    ramp_down : ramp-down envelopes (Sect. 7.2).
    hover_collective_m_s2 : the collective hover value that ramps approach [m/s²].
    name : free text.
    provenance : where the program came from (the command, session or design that made it).
    """

    switches: tuple[Switch, ...]
    duration_s: float = required(Interval(0.0, MAX_DURATION_S, closed="right", unit="s"))
    ramp_down: RampDown = field(default_factory=RampDown)
    hover_collective_m_s2: float = bounded(9.81, Interval(0.0, None, closed="neither", unit="m/s²"))
    name: str = ""
    provenance: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        if isinstance(self.switches, str) or not isinstance(self.switches, tuple | list):
            raise ConfigError(f"switches: expected a tuple of Switch, got {type(self.switches).__name__} "
                              f"{short_repr(self.switches)}")
        check_type("ramp_down", self.ramp_down, RampDown, "a RampDown")
        check_type("name", self.name, str, "a string")
        validate(self)
        end = self.duration_s
        for index, sw in enumerate(self.switches):
            # the common case in a few comparisons (programs are built inside every design iteration);
            # anything unusual goes through the checks below, which say what is wrong
            limits = _LIMITS.get(getattr(sw, "channel", None))  # type: ignore[arg-type]
            if (limits is None or not isinstance(sw, Switch) or type(sw.time_s) not in _PLAIN
                    or type(sw.value) not in _PLAIN or not 0.0 <= sw.time_s < end
                    or not limits[0] <= sw.value <= limits[1]):
                _check_switch(index, sw, end)
        if len({(sw.channel, float(sw.time_s)) for sw in self.switches}) != len(self.switches):
            _check_overlaps(self.switches)

    def compile(self) -> CompiledProgram:
        """Segment breakpoints and per-segment polynomial command coefficients."""
        return _compile(self)

    def commands_at(self, times_s: np.ndarray) -> np.ndarray:
        """Exact commands (collective, p̂, q̂, r̂) at ``times_s`` [s]; shape (N, 4). Hover after the end."""
        return self.compile().evaluate(np.asarray(times_s, dtype=float))


_LIMITS = {channel: _channel_limits(channel) for channel in CHANNELS}
_PLAIN = (float, int)


def _check_overlaps(switches: Sequence[Switch]) -> None:
    """Raise the ConfigError that names the first switch overlapping an earlier one on its channel."""
    seen: dict[tuple[str, float], int] = {}
    for index, sw in enumerate(switches):
        key = (sw.channel, float(sw.time_s))
        if key in seen:
            raise ConfigError(
                f"switch {index} ({sw.channel}): overlaps switch {seen[key]} — two switches on one channel at "
                f"time_s = {sw.time_s:g}"
            )
        seen[key] = index


def _check_switch(index: int, sw: Any, end: float) -> None:
    """Raise the ConfigError that says what is wrong with switch ``index`` (nothing if it is fine)."""
    where = f"switch {index}"
    if not isinstance(sw, Switch):
        raise ConfigError(f"{where}: expected a Switch, got {type(sw).__name__}")
    if sw.channel not in CHANNELS:
        raise ConfigError(f"{where}: unknown channel {sw.channel!r}; allowed: {', '.join(CHANNELS)}")
    for attr in ("time_s", "value"):
        v = getattr(sw, attr)
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise ConfigError(f"{where}: {attr} must be a number, got {v!r}")
        if not _finite(v):
            raise ConfigError(f"{where} ({sw.channel}): {attr} = {v} is not finite")
    if sw.time_s < 0:
        raise ConfigError(f"{where} ({sw.channel}): time_s = {sw.time_s:g} is negative; "
                          f"allowed [0, duration_s)")
    if sw.time_s >= end:
        raise ConfigError(
            f"{where} ({sw.channel}): time_s = {sw.time_s:g} is at or after the program end "
            f"duration_s = {end:g}; allowed [0, duration_s)"
        )
    low, high = _LIMITS[sw.channel]
    if not low <= sw.value <= high:
        raise ConfigError(
            f"{where} ({sw.channel}): value = {sw.value:g} is out of range: allowed "
            f"[{low:g}, {high:g}] ({CHANNEL_UNITS[sw.channel]})"
        )


@dataclass(frozen=True)
class CompiledProgram:
    """Piecewise-polynomial form of a program, ready for the compiled kernels.

    Attributes
    ----------
    breakpoints_s : (K+1,) segment boundaries, 0 … duration [s].
    coefficients : (K, 4, 3) per segment, channel (collective, p̂, q̂, r̂) and power of τ.
    hover : (4,) commands the supervisor holds after the program ends.
    """

    breakpoints_s: np.ndarray
    coefficients: np.ndarray
    hover: np.ndarray

    @property
    def duration_s(self) -> float:
        return float(self.breakpoints_s[-1])

    def evaluate(self, times_s: np.ndarray) -> np.ndarray:
        times_s = np.atleast_1d(times_s)
        out = np.empty((times_s.size, 4))
        bp = self.breakpoints_s
        k = np.clip(np.searchsorted(bp, times_s, side="right") - 1, 0, len(bp) - 2)
        tau = times_s - bp[k]
        c = self.coefficients[k]
        out[:] = c[:, :, 0] + tau[:, None] * (c[:, :, 1] + tau[:, None] * c[:, :, 2])
        after = times_s >= bp[-1]
        out[after] = self.hover
        return out


_CHANNEL_INDEX = {channel: i for i, channel in enumerate(CHANNELS)}


def _compile(program: Program) -> CompiledProgram:
    # plain floats and locals: this runs for every program of every design iteration
    T = float(program.duration_s)
    ramp_c = float(program.ramp_down.collective_s)
    ramp_r = float(program.ramp_down.rates_s)
    switches = program.switches
    index = _CHANNEL_INDEX
    # (time, channel, value), in time and then channel order (no two switches share both)
    ordered = sorted([(float(sw.time_s), index[sw.channel], sw.value) for sw in switches])
    times = {0.0, T}
    times.update([o[0] for o in ordered])
    for ramp in (ramp_c, ramp_r):
        if 0.0 < ramp < T:
            times.add(T - ramp)
    breaks = sorted(times)
    K = len(breaks) - 1
    g = program.hover_collective_m_s2
    value = [g, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # latest value per channel, in CHANNELS order
    ip = iq = ir = 0.0  # ∫ accel up to the current segment start
    rows: list[float] = []
    add = rows.extend
    count = len(ordered)
    j = 0
    start_c = T - ramp_c - 1e-15
    start_r = T - ramp_r - 1e-15
    inv_c = -1.0 / ramp_c if ramp_c > 0.0 else 0.0
    inv_r = -1.0 / ramp_r if ramp_r > 0.0 else 0.0
    for k in range(K):
        t0 = breaks[k]
        t1 = breaks[k + 1]
        while j < count and ordered[j][0] <= t0:
            value[ordered[j][1]] = float(ordered[j][2])
            j += 1
        c_val, p_val, q_val, r_val, ap, aq, ar = value
        # the ramp envelopes w(t0 + τ) = w0 + w1 τ on this segment (breakpoints include T − ramp)
        if ramp_c > 0.0 and not t0 < start_c:
            wc0, wc1 = (T - t0) / ramp_c, inv_c
        else:
            wc0, wc1 = 1.0, 0.0
        if ramp_r > 0.0 and not t0 < start_r:
            wr0, wr1 = (T - t0) / ramp_r, inv_r
        else:
            wr0, wr1 = 1.0, 0.0
        dc = c_val - g
        rp = p_val + ip
        rq = q_val + iq
        rr = r_val + ir
        add((g + wc0 * dc, wc1 * dc, 0.0,
             wr0 * rp, wr0 * ap + wr1 * rp, wr1 * ap,
             wr0 * rq, wr0 * aq + wr1 * rq, wr1 * aq,
             wr0 * rr, wr0 * ar + wr1 * rr, wr1 * ar))
        dt = t1 - t0
        ip += ap * dt
        iq += aq * dt
        ir += ar * dt
    coeffs = np.array(rows, dtype=float).reshape(K, 4, 3)
    return CompiledProgram(np.array(breaks), coeffs, np.array([g, 0.0, 0.0, 0.0]))


# ---------------------------------------------------------------------------- TOML


def program_to_table(program: Program) -> dict[str, Any]:
    header: dict[str, Any] = {"provenance": program.provenance} if program.provenance else {}
    return {
        "program": {
            **header,
            "name": program.name,
            "duration_s": program.duration_s,
            "hover_collective_m_s2": program.hover_collective_m_s2,
            "ramp_down": {"collective_s": program.ramp_down.collective_s, "rates_s": program.ramp_down.rates_s},
        },
        "switch": [{"time_s": s.time_s, "channel": s.channel, "value": s.value} for s in program.switches],
    }


def save_program(program: Program, path: str | Path) -> None:
    """Write ``program`` as TOML (``[program]`` header and ``[[switch]]`` entries), exact to the last bit."""
    check_type("program", program, Program, "a Program")
    write_file(path, tomli_w.dumps(program_to_table(program)))


def program_from_table(data: dict[str, Any], *, source: str) -> Program:
    unknown = sorted(set(data) - {"program", "switch"})
    if unknown:
        raise ConfigError(f"{source}: unknown table(s) {', '.join(unknown)}; allowed: [program], [[switch]]")
    header = data.get("program")
    if not isinstance(header, dict):
        raise ConfigError(f"{source}: missing required table [program] (with duration_s)")
    allowed = {"name", "duration_s", "hover_collective_m_s2", "ramp_down", "provenance"}
    bad = sorted(set(header) - allowed)
    if bad:
        raise ConfigError(
            f"{source}: [program] unknown field(s) {', '.join(bad)}; allowed: {', '.join(sorted(allowed))}"
        )
    if "duration_s" not in header:
        raise ConfigError(f"{source}: [program] missing required field duration_s")
    ramp_table = header.get("ramp_down", {})
    if not isinstance(ramp_table, dict):
        raise ConfigError(f"{source}: [program.ramp_down] must be a table")
    bad = sorted(set(ramp_table) - {"collective_s", "rates_s"})
    if bad:
        raise ConfigError(
            f"{source}: [program.ramp_down] unknown field(s) {', '.join(bad)}; allowed: collective_s, rates_s"
        )
    switches_raw = data.get("switch", [])
    if not isinstance(switches_raw, list):
        raise ConfigError(f"{source}: 'switch' must be an array of tables ([[switch]])")
    switches = []
    for index, entry in enumerate(switches_raw):
        where = f"{source}: switch {index}"
        if not isinstance(entry, dict):
            raise ConfigError(f"{where}: expected a table")
        missing = [k for k in ("time_s", "channel", "value") if k not in entry]
        if missing:
            raise ConfigError(f"{where}: missing required field(s) {', '.join(missing)}")
        extra = sorted(set(entry) - {"time_s", "channel", "value"})
        if extra:
            raise ConfigError(f"{where}: unknown field(s) {', '.join(extra)}; allowed: time_s, channel, value")
        for key in ("time_s", "value"):
            if isinstance(entry[key], bool) or not isinstance(entry[key], int | float):
                raise ConfigError(f"{where}: {key} must be a number, got {entry[key]!r}")
        if not isinstance(entry["channel"], str):
            raise ConfigError(f"{where}: channel must be a string, got {entry['channel']!r}")
        switches.append(Switch(time_s=float(entry["time_s"]), channel=entry["channel"], value=float(entry["value"])))
    try:
        for key in ("duration_s", "hover_collective_m_s2"):
            if key in header and (isinstance(header[key], bool) or not isinstance(header[key], int | float)):
                raise ConfigError(f"[program] {key} must be a number, got {header[key]!r}")
        name = header.get("name", "")
        if not isinstance(name, str):
            raise ConfigError(f"[program] name must be a string, got {name!r}")
        provenance = header.get("provenance", "")
        if not isinstance(provenance, str):
            raise ConfigError(f"[program] provenance must be a string, got {provenance!r}")
        try:
            ramp_down = RampDown(**{k: float(v) if not isinstance(v, bool) and isinstance(v, int | float) else v
                                    for k, v in ramp_table.items()})
        except ConfigError as exc:
            raise ConfigError(f"ramp_down.{exc}") from None
        return Program(
            switches=tuple(switches),
            duration_s=float(header["duration_s"]),
            ramp_down=ramp_down,
            hover_collective_m_s2=float(header.get("hover_collective_m_s2", 9.81)),
            name=name,
            provenance=provenance,
        )
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"{source}: {exc}") from None


def load_program(path: str | Path) -> Program:
    """Read a program TOML file; errors name the file, switch and field."""
    return program_from_table(read_toml(path), source=str(path))
