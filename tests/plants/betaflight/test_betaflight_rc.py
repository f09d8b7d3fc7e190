from __future__ import annotations

import pytest

from aerobat.firmware.betaflight.rc import (
    RADIO_LOST_US,
    RC_CHANNEL_COUNT,
    RcCommand,
    stick_to_us,
    throttle_to_us,
    us_to_stick,
    us_to_throttle,
)


def test_stick_mapping_endpoints_and_clamping() -> None:
    assert (stick_to_us(-1.0), stick_to_us(0.0), stick_to_us(1.0)) == (1000, 1500, 2000)
    assert stick_to_us(-3.0) == 1000 and stick_to_us(7.0) == 2000
    assert stick_to_us(0.25) == 1625
    assert us_to_stick(1625) == pytest.approx(0.25)
    assert us_to_stick(0) == -1.0


def test_throttle_mapping() -> None:
    assert (throttle_to_us(0.0), throttle_to_us(0.5), throttle_to_us(1.0)) == (1000, 1500, 2000)
    assert throttle_to_us(-0.2) == 1000
    assert us_to_throttle(1250) == pytest.approx(0.25)


def test_channels_are_aetr1234() -> None:
    channels = RcCommand(roll=1.0, pitch=-1.0, yaw=0.5, throttle=0.25, aux_us=(1900, 1200)).channels_us()
    assert len(channels) == RC_CHANNEL_COUNT
    assert channels[:6] == (2000, 1000, 1250, 1750, 1900, 1200)
    assert channels[6:] == (1000,) * 10


def test_round_trip() -> None:
    command = RcCommand(roll=0.1, pitch=-0.3, yaw=0.7, throttle=0.4, aux_us=(1900,) + (1000,) * 11)
    decoded = RcCommand.from_channels_us(command.channels_us())
    assert decoded.roll == pytest.approx(0.1) and decoded.pitch == pytest.approx(-0.3)
    assert decoded.yaw == pytest.approx(0.7) and decoded.throttle == pytest.approx(0.4)
    assert decoded.aux_us == command.aux_us


def test_radio_lost_is_out_of_range_on_every_channel() -> None:
    assert len(RADIO_LOST_US) == RC_CHANNEL_COUNT
    assert all(value < 885 for value in RADIO_LOST_US)  # below Betaflight's rx_min_usec


def test_too_many_aux_channels() -> None:
    with pytest.raises(ValueError):
        RcCommand(aux_us=(1000,) * 13)
