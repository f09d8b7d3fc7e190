"""RC channel encoding, as a receiver hands channels to Betaflight.

Channel order is AETR1234 (Betaflight's default ``map``): channel 0 roll
(aileron), 1 pitch (elevator), 2 throttle, 3 yaw (rudder), 4.. AUX1..AUX12.
Values are pulse widths in microseconds, 1000..2000 with 1500 the centre.

Stick positions are in [-1, 1] for roll, pitch and yaw (+1 = 2000 us: roll
right, pitch forward/nose down, yaw right/nose right) and the throttle is a
fraction in [0, 1] (0 = 1000 us). A lost radio is encoded the way a receiver
reports it: every channel out of the valid pulse range (0 us), which
Betaflight treats as invalid channels and, after its hold time, as a receiver
failsafe.

This module does not depend on the simulator; the same encoding drives a real
flight controller (e.g. through MSP_SET_RAW_RC or a receiver emulator).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

__all__ = [
    "AUX_CHANNEL_COUNT",
    "RC_CHANNEL_COUNT",
    "RC_MAX_US",
    "RC_MID_US",
    "RC_MIN_US",
    "RADIO_LOST_US",
    "RcCommand",
    "stick_to_us",
    "throttle_to_us",
    "us_to_stick",
    "us_to_throttle",
]

RC_CHANNEL_COUNT = 16
"""Channels in one RC frame (the SITL RC packet carries 16)."""
AUX_CHANNEL_COUNT = RC_CHANNEL_COUNT - 4
RC_MIN_US = 1000
RC_MID_US = 1500
RC_MAX_US = 2000
_HALF_RANGE_US = (RC_MAX_US - RC_MIN_US) / 2

RADIO_LOST_US: tuple[int, ...] = (0,) * RC_CHANNEL_COUNT
"""A frame as a receiver reports a lost link: every channel out of range.

Betaflight holds the last valid values for 300 ms, then enters failsafe
stage 1 (sticks centred, throttle low) and, after ``failsafe_delay``,
stage 2 (``failsafe_procedure``; DROP disarms).
"""


def _clamp(value: float, low: float, high: float) -> float:
    return low if value < low else high if value > high else value


def stick_to_us(position: float) -> int:
    """Map a stick position in [-1, 1] to a pulse width in microseconds.

    Parameters
    ----------
    position : float
        Stick deflection; values outside [-1, 1] are clamped.

    Returns
    -------
    int
        Pulse width in 1000..2000 us, rounded to the nearest microsecond.
    """
    return int(round(RC_MID_US + _HALF_RANGE_US * _clamp(position, -1.0, 1.0)))


def us_to_stick(pulse_us: float) -> float:
    """Map a pulse width in microseconds to a stick position in [-1, 1] (inverse of :func:`stick_to_us`)."""
    return _clamp((pulse_us - RC_MID_US) / _HALF_RANGE_US, -1.0, 1.0)


def throttle_to_us(fraction: float) -> int:
    """Map a throttle fraction in [0, 1] to a pulse width in microseconds (clamped, rounded)."""
    return int(round(RC_MIN_US + (RC_MAX_US - RC_MIN_US) * _clamp(fraction, 0.0, 1.0)))


def us_to_throttle(pulse_us: float) -> float:
    """Map a pulse width in microseconds to a throttle fraction in [0, 1]."""
    return _clamp((pulse_us - RC_MIN_US) / (RC_MAX_US - RC_MIN_US), 0.0, 1.0)


@dataclass(frozen=True)
class RcCommand:
    """One RC frame in physical terms.

    Attributes
    ----------
    roll, pitch, yaw : float
        Stick positions in [-1, 1] (+: roll right, pitch forward, yaw right).
    throttle : float
        Throttle fraction in [0, 1].
    aux_us : tuple of int
        AUX1.. pulse widths in microseconds (missing channels are 1000 us).
    """

    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0
    throttle: float = 0.0
    aux_us: tuple[int, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        if len(self.aux_us) > AUX_CHANNEL_COUNT:
            raise ValueError(f"at most {AUX_CHANNEL_COUNT} AUX channels, got {len(self.aux_us)}")

    def channels_us(self) -> tuple[int, ...]:
        """Encode as 16 channels in AETR1234 order, in microseconds."""
        aux = tuple(int(v) for v in self.aux_us) + (RC_MIN_US,) * (AUX_CHANNEL_COUNT - len(self.aux_us))
        return (
            stick_to_us(self.roll),
            stick_to_us(self.pitch),
            throttle_to_us(self.throttle),
            stick_to_us(self.yaw),
            *aux,
        )

    @classmethod
    def from_channels_us(cls, channels_us: Sequence[int]) -> RcCommand:
        """Decode AETR1234 channels in microseconds (inverse of :meth:`channels_us`, up to rounding)."""
        if len(channels_us) < 4:
            raise ValueError(f"need at least 4 channels, got {len(channels_us)}")
        return cls(
            roll=us_to_stick(channels_us[0]),
            pitch=us_to_stick(channels_us[1]),
            throttle=us_to_throttle(channels_us[2]),
            yaw=us_to_stick(channels_us[3]),
            aux_us=tuple(int(v) for v in channels_us[4:RC_CHANNEL_COUNT]),
        )
