"""The versioned Betaflight CLI settings (``settings.toml``) and what follows from them.

Besides the CLI commands that configure the firmware, the settings fix how
the Python side must drive it: which AUX pulse activates which mode, and how
stick deflection maps to commanded body rate (ACTUAL rates, fc/rc.c
``applyActualRates``).
"""

from __future__ import annotations

import hashlib
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aerobat.errors import ConfigError

from .rc import AUX_CHANNEL_COUNT, RC_MAX_US, RC_MIN_US

__all__ = ["DEFAULT_SETTINGS_PATH", "BetaflightSettings", "ModeRange", "load_settings"]

DEFAULT_SETTINGS_PATH = Path(__file__).with_name("settings.toml")
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

    def cli_commands(self) -> list[str]:
        """All CLI commands, in the order they are applied (without ``save``)."""
        aux = [mode.cli_command(slot) for slot, mode in enumerate(self.modes.values())]
        sets = [f"set {name} = {value}" for name, value in self.values]
        return [*self.commands, *aux, *sets]

    def value(self, name: str) -> str:
        """The configured value of a ``set`` entry."""
        for key, value in self.values:
            if key == name:
                return value
        raise KeyError(name)

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

    def rate_deg_s(self, axis: str, stick: float) -> float:
        """Commanded body rate for a stick deflection in ACRO (fc/rc.c ``applyActualRates``).

        ``rate = 10*rc_rate*x + max(0, 10*srate - 10*rc_rate) * (|x|*(x^5*e + x*(1-e)))``
        with ``e = expo/100``, clamped to ``+-rate_limit``. RC smoothing and
        deadband (0) are not modelled.
        """
        if self.value("rates_type").strip('"') != "ACTUAL":
            raise ValueError("only ACTUAL rates are modelled")
        rc_rate = float(self.value(f"{axis}_rc_rate"))
        srate = float(self.value(f"{axis}_srate"))
        expo = float(self.value(f"{axis}_expo")) / 100.0
        limit = float(self.value(f"{axis}_rate_limit"))
        x = min(max(stick, -1.0), 1.0)
        curve = abs(x) * (x**5 * expo + x * (1.0 - expo))
        rate = x * rc_rate * 10.0 + max(0.0, srate * 10.0 - rc_rate * 10.0) * curve
        return min(max(rate, -limit), limit)

    def motor_for_throttle_us(self, throttle_us: float) -> float:
        """Motor command (0..1, all motors, no PID mix) that a throttle pulse gives when armed.

        ``motor = idle + (1 - idle) * clamp((us - min_check) / (2000 - min_check), 0, 1)``
        with ``idle = motor_idle / 10000`` (linear throttle curve; throttle boost,
        which acts on throttle changes, not modelled).
        """
        min_check = float(self.value("min_check"))
        idle = float(self.value("motor_idle")) / 10000.0
        thr = min(max((throttle_us - min_check) / (RC_MAX_US - min_check), 0.0), 1.0)
        return idle + (1.0 - idle) * thr

    def throttle_us_for_motor(self, motor: float) -> float:
        """Throttle pulse (us) for a motor command (inverse of :meth:`motor_for_throttle_us`, clamped)."""
        min_check = float(self.value("min_check"))
        idle = float(self.value("motor_idle")) / 10000.0
        thr = min(max((motor - idle) / (1.0 - idle), 0.0), 1.0)
        return min_check + thr * (RC_MAX_US - min_check)

    def stick_for_rate(self, axis: str, rate_deg_s: float) -> float:
        """Stick deflection that commands ``rate_deg_s`` (linear curves only: rc_rate = srate, expo 0)."""
        rc_rate = float(self.value(f"{axis}_rc_rate"))
        if float(self.value(f"{axis}_srate")) != rc_rate or float(self.value(f"{axis}_expo")) != 0.0:
            raise ValueError(f"the {axis} rate curve is not linear")
        return min(max(rate_deg_s / (10.0 * rc_rate), -1.0), 1.0)


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
    try:
        raw = path.read_bytes()
        data = tomllib.loads(raw.decode())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as error:
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
