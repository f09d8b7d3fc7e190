"""SitlProcess against a fake firmware speaking the SITL protocol (fast, no build needed)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from aerobat.firmware.betaflight.configure import AT_REST_LEVEL
from aerobat.firmware.betaflight.errors import FirmwareExited, FirmwareNotResponding
from aerobat.firmware.betaflight.rc import RcCommand
from aerobat.firmware.betaflight.sitl import SitlProcess

FAKE = Path(__file__).with_name("fake_sitl.py")


def at(time_s: float):  # noqa: ANN201
    return AT_REST_LEVEL._replace(time_s=time_s)


def test_rc_is_sent_at_its_rate_before_the_state(monkeypatch: pytest.MonkeyPatch) -> None:
    with SitlProcess(FAKE, None, rc_rate_hz=250.0) as sitl:
        motors = sitl.step(at(125e-6))
        assert motors[0] == 0.0  # no RC until set_rc
        sitl.set_rc(RcCommand(throttle=0.5).channels_us())
        counts = [sitl.step(at(k * 125e-6))[0] for k in range(2, 2 + 64)]
        assert counts[0] == 1.0  # the first RC packet arrives with this very state packet
        assert counts[-1] == 2.0  # 64 steps of 125 us = 8 ms: one more frame at 250 Hz
        assert sitl.step(at(66 * 125e-6))[1] == pytest.approx(1.5)


def test_time_checks() -> None:
    with SitlProcess(FAKE, None) as sitl:
        sitl.step(at(250e-6))
        with pytest.raises(ValueError, match="increase"):
            sitl.step(at(125e-6))
        with pytest.raises(ValueError, match="multiple"):
            sitl.step(at(300e-6))


def test_start_failure_is_reported_and_cleaned_up(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    # a private temporary folder: the shared /tmp sees other runs' firmware folders come and go
    monkeypatch.setenv("FAKE_SITL_MODE", "exit")
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    made: list[str] = []
    mkdtemp = tempfile.mkdtemp
    monkeypatch.setattr(tempfile, "mkdtemp", lambda **kw: made.append(mkdtemp(**kw)) or made[-1])
    with pytest.raises(FirmwareNotResponding, match="exiting early"):
        SitlProcess(FAKE, None)
    assert len(made) == 1 and Path(made[0]).parent == tmp_path  # the firmware's folder was made here
    assert list(tmp_path.iterdir()) == []  # and removed


def test_mute_firmware_trips_the_watchdog(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FAKE_SITL_MODE", "mute")
    with SitlProcess(FAKE, None, step_timeout_s=0.2) as sitl:
        with pytest.raises(FirmwareNotResponding) as caught:
            sitl.step(at(125e-6))
        assert not isinstance(caught.value, FirmwareExited)
