"""The flight controller's configuration, as the firmware design model reads it.

Betaflight 4.6's own settings by their CLI names and in its own units (``p_roll = 45``,
``rc_smoothing_auto_factor = 30``, ``tpa_breakpoint = 1350``), the values the firmware actually
runs: 4.6's defaults, then aerobat's settings, then a pilot's tune (the Betaflight plant
resolves them: :func:`aerobat.plants.fpv.design_model.firmware_config`). The design
model is built from this and nothing else about the firmware, so what it models is written down
in one place (:data:`READ`), and a setting it does not model refuses the model when it is not
at the value the model assumes (:data:`ASSUMED`): one line naming the setting, its value and
what the model needs, never a silently different controller.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from aerobat.core.bounds import OneOf, bounded, validate
from aerobat.errors import ConfigError

__all__ = ["ASSUMED", "AXES", "READ", "FirmwareConfig"]

AXES = ("roll", "pitch", "yaw")

READ: tuple[str, ...] = (
    # stick to set point: rates of every rates_type, the throttle curve, RC smoothing
    "rates_type", "quickrates_rc_expo", *(f"{a}_{n}" for a in AXES for n in ("rc_rate", "srate", "expo", "rate_limit")),
    "deadband", "yaw_deadband", "mid_rc", "min_check", "yaw_control_reversed", "thr_mid", "thr_hover", "thr_expo",
    "throttle_limit_type", "throttle_limit_percent", "rc_smoothing", "rc_smoothing_auto_factor",
    "rc_smoothing_auto_factor_throttle", "rc_smoothing_setpoint_cutoff", "rc_smoothing_throttle_cutoff",
    "rc_smoothing_feedforward_cutoff",
    # feedforward
    "feedforward_smooth_factor", "feedforward_jitter_factor", "feedforward_boost",
    "feedforward_max_rate_limit", "feedforward_transition", "feedforward_yaw_hold_gain", "feedforward_yaw_hold_time",
    # the PID, its limits and helpers
    *(f"{t}_{a}" for a in AXES for t in ("p", "i", "d", "f", "d_max")), "d_max_gain", "d_max_advance",
    "pidsum_limit", "pidsum_limit_yaw", "iterm_windup", "iterm_relax", "iterm_relax_type", "iterm_relax_cutoff",
    "anti_gravity_gain", "anti_gravity_cutoff_hz", "anti_gravity_p_gain", "tpa_mode", "tpa_rate", "tpa_breakpoint",
    "tpa_low_rate", "tpa_low_breakpoint", "tpa_low_always", "yaw_lowpass_hz", "acc_limit", "acc_limit_yaw",
    "airmode_start_throttle_percent",
    # the filters that shape the loop
    "gyro_lpf1_type", "gyro_lpf1_static_hz", "gyro_lpf1_dyn_min_hz", "gyro_lpf1_dyn_max_hz", "gyro_lpf1_dyn_expo",
    "gyro_lpf2_type", "gyro_lpf2_static_hz", "gyro_notch1_hz", "gyro_notch1_cutoff", "gyro_notch2_hz",
    "gyro_notch2_cutoff", "dterm_lpf1_type", "dterm_lpf1_static_hz", "dterm_lpf1_dyn_min_hz",
    "dterm_lpf1_dyn_max_hz", "dterm_lpf1_dyn_expo", "dterm_lpf2_type", "dterm_lpf2_static_hz", "dterm_notch_hz",
    "dterm_notch_cutoff",
    # mixer and throttle path
    "mixer_type", "motor_idle", "min_command", "max_throttle", "motor_output_limit", "thrust_linear",
    "throttle_boost", "throttle_boost_cutoff", "yaw_motors_reversed",
    # the loop
    "pid_process_denom",
)
"""Every setting the design model reads (Betaflight 4.6 CLI names)."""

ASSUMED: dict[str, tuple[str, str]] = {
    "abs_control_gain": ("0", "absolute control is not modelled"),
    "use_integrated_yaw": ("OFF", "integrated yaw is not modelled"),
    "iterm_rotation": ("OFF", "I-term rotation is not modelled"),
    "crash_recovery": ("OFF", "crash recovery is not modelled"),
    "transient_throttle_limit": ("0", "the air-mode throttle offset filter is not modelled"),
    "landing_disarm_threshold": ("0", "disarm on impact is not modelled"),
}
# feedforward_averaging is not read: 4.6 copies it in initRcProcessing, which activateConfig runs
# before pidInit sets it, so a booted 4.6 never averages (measured in the SITL: the ROMA F5's
# 2_POINT tune flies with the full, unaveraged feedforward)
"""Settings the model does not model, with the value it assumes and why (another value refuses the model)."""

_LOWPASS = ("PT1", "BIQUAD", "PT2", "PT3")


@dataclass(frozen=True, kw_only=True)
class FirmwareConfig:
    """A Betaflight 4.6 configuration: the values of :data:`READ` (and :data:`ASSUMED`) as the firmware holds them.

    Attributes
    ----------
    values : (name, value) pairs, values as the firmware's CLI prints them (numbers or lookup names).
    airmode : whether ``feature AIRMODE`` is on (Betaflight's default).
    gyro_rate_hz : the gyro's sample rate [Hz] (the SITL's virtual gyro: 8000); the PID loop runs at
        ``gyro_rate_hz / pid_process_denom``.
    source : where the values come from (``"Betaflight 4.6.0 defaults + aerobat settings.toml rev 2"``).
    """

    values: tuple[tuple[str, str], ...]
    airmode: bool = True
    gyro_rate_hz: int = bounded(8000, OneOf((1000, 2000, 4000, 8000), unit="Hz"))
    source: str = ""

    def __post_init__(self) -> None:
        validate(self)
        table = dict(self.values)
        missing = [name for name in READ if name not in table]
        if missing:
            raise ConfigError(f"firmware configuration ({self.source or 'no source'}): no value for "
                              f"{', '.join(missing[:5])}{' …' if len(missing) > 5 else ''}")
        for name, (assumed, why) in ASSUMED.items():
            value = table.get(name, assumed)
            if value.upper() != assumed:
                raise ConfigError(f"firmware configuration ({self.source or 'no source'}): {name} = {value}: {why} "
                                  f"(the design model needs {assumed}); design on the paper's model instead "
                                  f"(--design-model paper)")
        for name in ("gyro_lpf1_type", "gyro_lpf2_type", "dterm_lpf1_type", "dterm_lpf2_type"):
            if table[name].upper() not in _LOWPASS:
                raise ConfigError(f"firmware configuration: {name} = {table[name]}: one of {', '.join(_LOWPASS)}")
        denom = self.number("pid_process_denom")
        if denom != int(denom) or not 1 <= denom <= 16:
            raise ConfigError(f"firmware configuration: pid_process_denom = {denom:g}: allowed 1..16")

    def value(self, name: str) -> str:
        """A setting's value as text (lookup names upper-case)."""
        table = dict(self.values)
        if name not in table:
            raise KeyError(name)
        return table[name].strip().strip('"').upper()

    def number(self, name: str) -> float:
        """A numeric setting's value."""
        text = self.value(name)
        try:
            return float(text)
        except ValueError:
            raise ConfigError(f"firmware configuration: {name} = {text!r} is not a number") from None

    def on(self, name: str) -> bool:
        """An ON/OFF setting."""
        return self.value(name) == "ON"

    @property
    def pid_process_denom(self) -> int:
        """Gyro samples per PID loop."""
        return int(self.number("pid_process_denom"))

    @property
    def gyro_period_s(self) -> float:
        """The gyro's sample period [s]."""
        return 1.0 / self.gyro_rate_hz

    @property
    def pid_period_s(self) -> float:
        """The PID loop's period [s] (``targetPidLooptime``)."""
        return self.pid_process_denom / self.gyro_rate_hz

    @classmethod
    def from_mapping(cls, values: Mapping[str, str], *, airmode: bool = True, gyro_rate_hz: int = 8000,
                     source: str = "") -> FirmwareConfig:
        """From a name → value mapping (only :data:`READ` and :data:`ASSUMED` are kept)."""
        keep = (*READ, *ASSUMED)
        pairs = tuple((name, str(values[name])) for name in keep if name in values)
        return cls(values=pairs, airmode=airmode, gyro_rate_hz=gyro_rate_hz, source=source)

    def to_table(self) -> dict[str, object]:
        """The stored form: ``{"values": {name: value}, "airmode", "gyro_rate_hz", "source"}``."""
        return {"values": dict(self.values), "airmode": self.airmode, "gyro_rate_hz": self.gyro_rate_hz,
                "source": self.source}

    @classmethod
    def from_table(cls, table: Mapping[str, object], *, source: str) -> FirmwareConfig:
        """Inverse of :meth:`to_table`."""
        values = table.get("values")
        if not isinstance(values, Mapping):
            raise ConfigError(f"{source}: expected a table of firmware values")
        gyro = table.get("gyro_rate_hz", 8000)
        if not isinstance(gyro, int) or isinstance(gyro, bool):
            raise ConfigError(f"{source}.gyro_rate_hz: expected an integer, got {gyro!r}")
        return cls.from_mapping({str(k): str(v) for k, v in values.items()}, airmode=bool(table.get("airmode", True)),
                                gyro_rate_hz=gyro, source=str(table.get("source", "")))

