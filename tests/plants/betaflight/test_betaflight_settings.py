from __future__ import annotations

import pytest

from aerobat.firmware.betaflight.settings import load_settings


def test_packaged_settings_render_cli_commands() -> None:
    settings = load_settings()
    commands = settings.cli_commands()
    assert "aux 0 0 0 1700 2100 0 0" in commands  # ARM on AUX1
    assert "aux 1 1 1 1700 2100 0 0" in commands  # ANGLE on AUX2
    assert "set pwr_on_arm_grace = 0" in commands
    assert "set rates_type = ACTUAL" in commands
    assert len(settings.sha256) == 64


def test_aux_switches() -> None:
    settings = load_settings()
    aux = settings.aux_us(ARM=True, ANGLE=False)
    assert aux[0] == 1900 and aux[1] == 1000 and len(aux) == 12
    with pytest.raises(KeyError):
        settings.aux_us(HORIZON=True)


def test_linear_max_rate() -> None:
    settings = load_settings()
    assert settings.rate_deg_s("roll", 0.5) == pytest.approx(1000.0)
    assert settings.rate_deg_s("pitch", -0.25) == pytest.approx(-500.0)
    assert settings.rate_deg_s("yaw", 1.0) == pytest.approx(1998.0)  # 2000 clamped by rate_limit
    assert settings.stick_for_rate("roll", 1500.0) == pytest.approx(0.75)


def test_throttle_map() -> None:
    settings = load_settings()
    assert settings.motor_for_throttle_us(1000) == pytest.approx(0.055)
    assert settings.motor_for_throttle_us(1050) == pytest.approx(0.055)
    assert settings.motor_for_throttle_us(2000) == pytest.approx(1.0)
    assert settings.throttle_us_for_motor(settings.motor_for_throttle_us(1400)) == pytest.approx(1400)
