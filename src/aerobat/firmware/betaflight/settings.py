"""The versioned Betaflight CLI settings (``settings.toml``) and what follows from them.

Besides the CLI commands that configure the firmware, the settings fix how
the Python side must drive it: which AUX pulse activates which mode, and how
stick deflection maps to commanded body rate (ACTUAL rates, fc/rc.c
``applyActualRates``).
"""

from __future__ import annotations

import hashlib
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from aerobat.errors import ConfigError

from .rc import AUX_CHANNEL_COUNT, RC_MAX_US, RC_MIN_US

__all__ = ["DEFAULT_SETTINGS_PATH", "PINNED", "BetaflightSettings", "ModeRange", "load_settings"]

DEFAULT_SETTINGS_PATH = Path(__file__).with_name("settings.toml")
# settings.toml's [set] entries that a tune never changes, and why
PINNED: dict[str, str] = {
    "pwr_on_arm_grace": "arming: no grace time after boot, so a simulated run arms at once",
    "small_angle": "arming: the pilot arms level; the SITL refuses arming beyond it",
    "min_check": "radio calibration: aerobat's radio sends exact pulses; throttle low for arming",
    "failsafe_delay": "failsafe: aerobat's lost-radio tests rely on the defaults",
    "failsafe_procedure": "failsafe: aerobat's lost-radio tests rely on DROP",
    "failsafe_throttle_low_delay": "failsafe",
    "runaway_takeoff_prevention": "the offboard take-off at ~21 % throttle never ends the check, which then "
                                  "disarms flips (measured, settings.toml)",
    "yaw_motors_reversed": "the physics' propeller spin directions (the airframe's props_out sets it)",
}
_AXES = ("roll", "pitch", "yaw")


@dataclass(frozen=True)
class ModeRange:
    """One ``aux`` mode range.

    Attributes
    ----------
    name : str
        Betaflight box name (``ARM``, ``ANGLE``, ...).
    permanent_id : int
        The box's permanent id (msp/msp_box.c), as the ``aux`` command takes it.
    aux : int
        AUX channel, counting from 1 (AUX1 is RC channel 5).
    low_us, high_us : int
        Active range in microseconds.
    """

    name: str
    permanent_id: int
    aux: int
    low_us: int
    high_us: int

    @property
    def on_us(self) -> int:
        """A pulse inside the range (its middle, within 1000..2000)."""
        return min(max((self.low_us + self.high_us) // 2, RC_MIN_US), RC_MAX_US)

    @property
    def off_us(self) -> int:
        """A pulse outside the range (1000 or 2000 us)."""
        return RC_MIN_US if self.low_us > RC_MIN_US else RC_MAX_US

    def cli_command(self, slot: int) -> str:
        """The ``aux`` CLI command for mode-activation slot ``slot``."""
        return f"aux {slot} {self.permanent_id} {self.aux - 1} {self.low_us} {self.high_us} 0 0"


@dataclass(frozen=True)
class BetaflightSettings:
    """Parsed ``settings.toml``.

    Attributes
    ----------
    path : Path
        The file.
    sha256 : str
        Hash of its bytes (keys the cached eeprom).
    revision : int
        Human revision number.
    commands : tuple of str
        Raw CLI commands applied first.
    modes : dict of str to ModeRange
        Mode ranges by box name.
    values : tuple of (str, str)
        ``set`` name/value pairs in file order.
    """

    path: Path
    sha256: str
    revision: int
    commands: tuple[str, ...]
    modes: dict[str, ModeRange]
    values: tuple[tuple[str, str], ...]
    tune: Any = field(default=None, compare=False)
    """The :class:`~.translate.TuneReport` applied on top (None: ``settings.toml`` alone)."""

    def with_tune(self, report: Any) -> BetaflightSettings:
        """These settings with a translated tune applied: the firmware starts from 4.6's defaults, takes the
        tune's commands, then aerobat's pinned ones (``PINNED``, the mode ranges, AIR MODE, QUADX)."""
        tuned = dict(report.values())
        pinned = [(name, value) for name, value in self.values if name in PINNED]
        values = tuple((n, v) for n, v in tuned.items() if n not in PINNED) + tuple(pinned)
        features = tuple(c for c in report.commands if c.startswith("feature "))
        digest = hashlib.sha256("\n".join([self.sha256, *report.commands]).encode()).hexdigest()
        return replace(self, sha256=digest, commands=(*features, *self.commands), values=values, tune=report)

    def with_values(self, extra: Mapping[str, str], why: str) -> BetaflightSettings:
        """These settings with ``set`` values added or replaced (the eeprom's cache key changes with them).

        ``why`` is kept in the hash's input and says what needs them (e.g. the serial task's rate for
        RC frames over MSP).
        """
        values = tuple((n, v) for n, v in self.values if n not in extra) + tuple(extra.items())
        lines = [self.sha256, why, *(f"set {n} = {v}" for n, v in extra.items())]
        return replace(self, sha256=hashlib.sha256("\n".join(lines).encode()).hexdigest(), values=values)

    def with_props(self, props_out: bool) -> BetaflightSettings:
        """These settings with the mixer's yaw turned the way the airframe's propellers turn: unchanged for
        props in (``settings.toml``'s pinned ``yaw_motors_reversed = OFF``), ``ON`` for props out
        (:attr:`aerobat.quadrotor.xframe.Airframe.props_out`); the tune never sets it, the airframe does."""
        if not props_out:
            return self
        return self.with_values({"yaw_motors_reversed": "ON"}, "props out: the airframe's propellers turn reversed")

    def cli_commands(self) -> list[str]:
        """All CLI commands, in the order they are applied (without ``save``)."""
        aux = [mode.cli_command(slot) for slot, mode in enumerate(self.modes.values())]
        sets = [f"set {name} = {value}" for name, value in self.values]
        return [*self.commands, *aux, *sets]

    def value(self, name: str) -> str:
        """The configured value of a ``set`` entry (with a tune, a name it does not set is 4.6's default)."""
        for key, value in self.values:
            if key == name:
                return value
        if self.tune is not None:
            from .sitl_table import load_table

            entry = load_table().get(name)
            if entry is not None:
                return entry.default
        raise KeyError(name)

    def resolved(self, name: str) -> str:
        """The value the firmware runs: the configured one, else the build's default (its own table)."""
        try:
            return self.value(name)
        except KeyError:
            from .sitl_table import load_table

            entry = load_table().get(name)
            if entry is None:
                raise
            return entry.default

    def aux_us(self, **active: bool) -> tuple[int, ...]:
        """AUX1..AUX12 pulses that switch the named modes on or off.

        Example: ``settings.aux_us(ARM=True, ANGLE=False)``. Channels of modes
        not named, and unused channels, are 1000 us.
        """
        aux = [RC_MIN_US] * AUX_CHANNEL_COUNT
        for name, on in active.items():
            if name not in self.modes:
                raise KeyError(f"no mode range for {name}; configured: {sorted(self.modes)}")
            mode = self.modes[name]
            aux[mode.aux - 1] = mode.on_us if on else mode.off_us
        return tuple(aux)

    def deadband_us(self, axis: str) -> float:
        """The stick deadband [µs of 500] on ``axis`` (``deadband`` or ``yaw_deadband``; aerobat's settings: 0)."""
        return float(self.value("yaw_deadband" if axis == "yaw" else "deadband")) if self.tune is not None else 0.0

    def rate_deg_s(self, axis: str, stick: float, *, deadband: bool = True) -> float:
        """Commanded body rate [deg/s] for a stick deflection in ACRO (fc/rc.c, every ``rates_type``).

        ACTUAL: ``rate = 10*rc_rate*x + max(0, 10*srate - 10*rc_rate) * (|x|*(x^5*e + x*(1-e)))`` with
        ``e = expo/100``; BETAFLIGHT, RACEFLIGHT, KISS and QUICK as ``applyBetaflightRates`` & co.
        The stick first loses the ``deadband`` (``yaw_deadband``) in us of 500 (``deadband=False``: the
        curve of the deflection past it), and the rate is clamped
        to ``+-rate_limit``. RC smoothing (a filter, not a curve) is not modelled.
        """
        kind = self.value("rates_type").strip('"').upper()
        rc_rate = float(self.value(f"{axis}_rc_rate"))
        srate = float(self.value(f"{axis}_srate"))
        expo = float(self.value(f"{axis}_expo")) / 100.0
        limit = float(self.value(f"{axis}_rate_limit"))
        band = self.deadband_us(axis) if deadband else 0.0
        x = min(max(stick, -1.0), 1.0)
        if band > 0.0:
            x = math.copysign(max(abs(x) * 500.0 - band, 0.0) / (500.0 - band), x)
        a = abs(x)
        if kind == "ACTUAL":
            curve = a * (x**5 * expo + x * (1.0 - expo))
            rate = x * rc_rate * 10.0 + max(0.0, srate * 10.0 - rc_rate * 10.0) * curve
        elif kind == "BETAFLIGHT":
            xc = x * a**3 * expo + x * (1.0 - expo) if expo else x
            rcr = rc_rate / 100.0
            rcr = rcr + 14.54 * (rcr - 2.0) if rcr > 2.0 else rcr
            rate = 200.0 * rcr * xc
            if srate:
                rate /= min(max(1.0 - a * srate / 100.0, 0.01), 1.0)
        elif kind == "RACEFLIGHT":
            xc = (1.0 + 0.01 * expo * 100.0 * (x * x - 1.0)) * x
            rate = 10.0 * rc_rate * xc * (1.0 + a * srate * 0.01)
        elif kind == "KISS":
            use = 1.0 / min(max(1.0 - a * srate / 100.0, 0.01), 1.0)
            rate = min(max(2000.0 * use * (x**3 * expo + x * (1.0 - expo)) * rc_rate / 1000.0, -1998.0), 1998.0)
        elif kind == "QUICK":
            rcr = rc_rate * 2.0
            top = max(srate * 10.0, rcr)
            factor = (top / rcr - 1.0) / (top / rcr)
            if self.tune is not None and self.value("quickrates_rc_expo").upper() == "ON":
                curve = x**3 * expo + x * (1.0 - expo)
                rate = curve * rcr / min(max(1.0 - a * factor, 0.01), 1.0)
            else:
                curve = a**3 * expo + a * (1.0 - expo)
                rate = x * rcr / min(max(1.0 - curve * factor, 0.01), 1.0)
            rate = min(max(rate, -1998.0), 1998.0)
        else:
            raise ValueError(f"rates_type {kind!r}: not a Betaflight 4.6 rates type")
        return min(max(rate, -limit), limit)

    def linear_rates(self) -> bool:
        """Whether every axis's stick → rate curve is aerobat's linear one (ACTUAL, rc_rate = srate, no expo)."""
        if self.value("rates_type").strip('"').upper() != "ACTUAL":
            return False
        if self.tune is not None and (float(self.value("deadband")) or float(self.value("yaw_deadband"))):
            return False
        return all(float(self.value(f"{a}_srate")) == float(self.value(f"{a}_rc_rate"))
                   and float(self.value(f"{a}_expo")) == 0.0 for a in ("roll", "pitch", "yaw"))

    def motor_for_throttle_us(self, throttle_us: float) -> float:
        """Motor command (0..1, all motors, no PID mix) that a throttle pulse gives when armed.

        ``motor = idle + (1 - idle) * curve(clamp((us - min_check) / (2000 - min_check), 0, 1))``
        with ``idle = motor_idle / 10000``; ``curve`` is the identity unless ``thr_mid``, ``thr_hover``,
        ``thr_expo`` (two quadratic Bezier segments, fc/rc.c initRcProcessing) or ``throttle_limit_*``
        (flight/mixer.c applyThrottleLimit) say otherwise. Throttle boost, which acts on throttle changes,
        and thrust linearisation are not modelled.
        """
        min_check = float(self.value("min_check"))
        idle = float(self.value("motor_idle")) / 10000.0
        thr = min(max((throttle_us - min_check) / (RC_MAX_US - min_check), 0.0), 1.0)
        return idle + (1.0 - idle) * self._throttle_curve(thr)

    def _throttle_curve(self, x: float) -> float:
        mid = float(self.value("thr_mid")) / 100.0
        hover = float(self.value("thr_hover")) / 100.0
        expo = float(self.value("thr_expo")) / 100.0
        y = x
        if not (mid == hover and expo == 0.0):
            if x <= mid:
                y = _bezier(x, 0.0, mid * 0.5, mid, 0.0, hover * 0.5 * (1.0 + expo), hover)
            else:
                y = _bezier(x, mid, (1.0 + mid) * 0.5, 1.0, hover, 1.0 + (hover - 1.0) * 0.5 * (1.0 + expo), 1.0)
        if self.tune is not None:
            percent = float(self.value("throttle_limit_percent")) / 100.0
            kind = self.value("throttle_limit_type").upper()
            if percent < 1.0 and kind == "SCALE":
                y *= percent
            elif percent < 1.0 and kind == "CLIP":
                y = min(y, percent)
        return y

    def throttle_us_for_motor(self, motor: float) -> float:
        """Throttle pulse (us) for a motor command (inverse of :meth:`motor_for_throttle_us`, clamped)."""
        if not self.linear_throttle():
            low, high = float(RC_MIN_US), float(RC_MAX_US)
            for _ in range(60):
                middle = 0.5 * (low + high)
                low, high = (middle, high) if self.motor_for_throttle_us(middle) < motor else (low, middle)
            return 0.5 * (low + high)
        min_check = float(self.value("min_check"))
        idle = float(self.value("motor_idle")) / 10000.0
        thr = min(max((motor - idle) / (1.0 - idle), 0.0), 1.0)
        return min_check + thr * (RC_MAX_US - min_check)

    def linear_throttle(self) -> bool:
        """Whether the throttle curve is the identity (``thr_mid = thr_hover``, no expo, no throttle limit)."""
        return all(abs(self._throttle_curve(x) - x) < 1e-12 for x in (0.1, 0.3, 0.5, 0.7, 0.9, 1.0))

    def stick_for_rate(self, axis: str, rate_deg_s: float) -> float:
        """Stick deflection that commands ``rate_deg_s`` (linear curves only: rc_rate = srate, expo 0)."""
        rc_rate = float(self.value(f"{axis}_rc_rate"))
        if float(self.value(f"{axis}_srate")) != rc_rate or float(self.value(f"{axis}_expo")) != 0.0:
            raise ValueError(f"the {axis} rate curve is not linear")
        return min(max(rate_deg_s / (10.0 * rc_rate), -1.0), 1.0)


def _bezier(x: float, x0: float, x1: float, x2: float, y0: float, y1: float, y2: float) -> float:
    """A quadratic Bezier's y at x (fc/rc.c quadraticBezier: solve x(t) = x for t in [0, 1])."""
    a = x0 - 2.0 * x1 + x2
    b = 2.0 * (x1 - x0)
    c = x0 - x
    if abs(a) < 1e-6:
        t = -c / b if b != 0.0 else 0.0
    else:
        t = (-b + math.sqrt(max(b * b - 4.0 * a * c, 0.0))) / (2.0 * a)
    t = min(max(t, 0.0), 1.0)
    return (1.0 - t) ** 2 * y0 + 2.0 * (1.0 - t) * t * y1 + t * t * y2


def _value_text(path: Path, name: str, value: Any) -> str:
    if isinstance(value, bool) or not isinstance(value, int | str):
        raise ConfigError(f"{path}: [set] {name} = {value!r}: expected an integer or a lookup name")
    return str(value)


def load_settings(path: Path | None = None) -> BetaflightSettings:
    """Read and check ``settings.toml`` (default: the one shipped with this package).

    Raises
    ------
    ConfigError
        The file cannot be read or parsed, or a field is missing or out of range (the message
        names the file and the field).
    """
    path = Path(path) if path is not None else DEFAULT_SETTINGS_PATH
    from aerobat.fileio import read_input

    raw = read_input(path, what="Betaflight settings file")  # a regular file only, size-capped (issue 31 H1/H2)
    try:
        data = tomllib.loads(raw.decode())
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as error:
        raise ConfigError(f"{path}: cannot read Betaflight settings: {error}") from None
    if data.get("schema") != 1:
        raise ConfigError(f"{path}: schema = {data.get('schema')!r}: this aerobat reads schema 1")
    modes = {}
    raw_modes = data.get("modes", {})
    if not isinstance(raw_modes, dict):
        raise ConfigError(f"{path}: [modes] must be a table of mode ranges")
    for name, entry in raw_modes.items():
        where = f"{path}: [modes.{name}]"
        try:
            low_us, high_us = (int(v) for v in entry["range_us"])
            aux, permanent_id = int(entry["aux"]), int(entry["permanent_id"])
        except (KeyError, TypeError, ValueError):
            raise ConfigError(f"{where}: needs permanent_id, aux and range_us = [low, high] (integers)") from None
        if not 1 <= aux <= AUX_CHANNEL_COUNT:
            raise ConfigError(f"{where} aux = {aux}: out of range, allowed 1..{AUX_CHANNEL_COUNT}")
        if not 900 <= low_us < high_us <= 2100:
            raise ConfigError(f"{where} range_us = [{low_us}, {high_us}]: allowed 900 <= low < high <= 2100 (us)")
        modes[name] = ModeRange(name, permanent_id, aux, low_us, high_us)
    raw_set = data.get("set", {})
    if not isinstance(raw_set, dict):
        raise ConfigError(f"{path}: [set] must be a table of name = value")
    values = tuple((name, _value_text(path, name, value)) for name, value in raw_set.items())
    return BetaflightSettings(
        path=path,
        sha256=hashlib.sha256(raw).hexdigest(),
        revision=int(data.get("revision", 0)),
        commands=tuple(str(command) for command in data.get("commands", [])),
        modes=modes,
        values=values,
    )
