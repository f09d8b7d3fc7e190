"""A real flight replayed through the firmware (issue 24): sticks in, gyro, motors and PID terms against the log.

The log is the ROMA F5's first flight in ../shared/data (skipped with the reason when absent); the
firmware tests need the SITL (skipped when it cannot be built).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from aerobat.cli import main
from aerobat.experiments.log_replay import find_steps, replay_log
from aerobat.firmware.betaflight.settings import load_settings
from aerobat.firmware.betaflight.translate import translate
from aerobat.firmware.betaflight.tune import load_tune
from aerobat.logs import Channel, read_log
from aerobat.plants.betaflight.replay import StickTrack, channels_from_commands

DATA = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "flight-logs"  # ../shared/data
ROMA = DATA / "betaflight" / "diatone-roma-f5.bbl"
CRAZYFLIE = DATA / "crazyflie" / "log10"
needs_data = pytest.mark.skipif(not ROMA.is_file(), reason=f"the real flight logs are not here ({DATA} is absent)")


def _roma_settings():
    return load_settings().with_tune(translate(load_tune(ROMA, log_index=1)))


@needs_data
def test_sticks_become_pulses_with_the_deadband_and_yaw_reversed() -> None:
    settings = _roma_settings()  # deadband 2, yaw_deadband 2
    rpy = np.array([[100.0, -250.0, 100.0], [0.0, 0.0, 0.0], [498.0, -498.0, -498.0]])
    pulses = channels_from_commands(settings, rpy, np.array([0.0, 0.5, 1.0]))
    assert pulses[0, [0, 1, 3]].tolist() == [1602.0, 1248.0, 1398.0]  # yaw: rcCommand is the negated stick
    assert pulses[1, [0, 1, 3]].tolist() == [1500.0, 1500.0, 1500.0]
    assert pulses[2, [0, 1, 3]].tolist() == [2000.0, 1000.0, 2000.0]
    assert pulses[0, 2] <= 1050.0 and pulses[2, 2] == 2000.0 and 1400.0 < pulses[1, 2] < 1600.0


@needs_data
def test_the_tunes_rate_curve_on_the_logged_sticks_gives_the_logged_set_point() -> None:
    log = read_log(ROMA, 1).window(5.0, 60.0)
    settings = _roma_settings()
    sticks = log.signal(Channel.STICKS)
    pulses = channels_from_commands(settings, sticks.values * 500.0, log.signal(Channel.THROTTLE_STICK).values[:, 0])
    curve = np.array([[settings.rate_deg_s("roll", (p[0] - 1500) / 500),
                       settings.rate_deg_s("pitch", (p[1] - 1500) / 500),
                       -settings.rate_deg_s("yaw", (p[3] - 1500) / 500)] for p in pulses])
    logged = np.degrees(log.signal(Channel.RATE_SETPOINT).values)
    rms = np.sqrt(np.mean((curve - logged) ** 2, axis=0))
    assert np.all(rms < 1.0), rms  # deg/s, on set points of 25-47 deg/s rms
    assert np.abs(logged).max() > 200.0


def test_steps_are_found_where_the_set_point_jumps_and_held() -> None:
    t = np.arange(0.0, 2.0, 0.004)
    sp = np.where(t >= 0.5, 300.0, 0.0) + np.where(t >= 1.2, -250.0, 0.0) + 40.0 * np.sin(2 * np.pi * 0.5 * t)
    steps = find_steps(t, sp, min_deg_s=100.0)
    assert [round(t[a], 3) for a, _, _ in steps] == [0.496, 1.196]
    assert find_steps(t, 40.0 * np.sin(2 * np.pi * 0.5 * t), min_deg_s=100.0) == []


def test_a_stick_track_holds_each_sample_until_the_next() -> None:
    track = StickTrack(np.array([0.0, 0.004, 0.008]), np.array([[1500, 1500, 1000, 1500], [1600, 1500, 1100, 1500],
                                                               [1700, 1500, 1200, 1500]]))
    assert track.at(0.005)[0] == 1600 and track.at(-1.0)[0] == 1500 and track.at(9.0)[0] == 1700
    with pytest.raises(ValueError, match="increase"):
        StickTrack(np.array([0.0, 0.0]), np.zeros((2, 4)))


@needs_data
def test_a_real_flight_through_the_firmware_matches_the_log(firmware: tuple[Path, Path]) -> None:
    result = replay_log(ROMA, index=1, window_s=(20.0, 24.0))
    gyro_r = [m.correlation for m in result.gyro]
    assert gyro_r[0] > 0.99 and gyro_r[2] > 0.99 and gyro_r[1] > 0.8, gyro_r
    assert all(m.rms < 2.0 for m in result.setpoint), result.setpoint  # the firmware's own set point, deg/s
    assert all(m.correlation > 0.95 for m in result.motors), result.motors
    p_roll = result.pid[0][0]
    assert p_roll is not None and p_roll.correlation > 0.3, p_roll
    assert result.pid[2][2] is None  # Betaflight logs no yaw D term
    assert result.excluded_s == 0.0 and result.window_s == (20.0, 24.0)
    assert result.time_s[0] >= 20.0 and result.time_s[-1] <= 24.0


@needs_data
def test_log_replay_cli_prints_json_and_writes_the_figure(firmware: tuple[Path, Path], tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["log", "replay", f"{ROMA}:1", "--window-s", "22", "23", "--out", str(tmp_path), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    assert Path(out["figure"]).is_file() and out["window_s"] == [22.0, 23.0]
    assert out["gyro"]["roll"]["correlation"] > 0.95
    assert set(out["pid"]) == {"P", "I", "D", "F"}


@needs_data
@pytest.mark.parametrize(("args", "message"), [
    (["--window-s", "70", "80"], "--window-s 70 80: the window must lie in the log's 0..65.906 s"),
    (["--window-s", "21", "20"], "--window-s 21 20: the window"),
    (["--window-s", "20", "20.05"], "at least 0.1 s"),
])
def test_a_window_outside_the_log_is_refused_in_one_line(args: list[str], message: str, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["log", "replay", f"{ROMA}:1", *args, "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2 and message in err and "Traceback" not in err
    assert not list(tmp_path.iterdir())


@needs_data
def test_a_log_that_is_not_betaflight_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["log", "replay", str(CRAZYFLIE), "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2 and "replay needs a Betaflight blackbox log" in err


@needs_data
def test_a_log_number_the_file_does_not_hold_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["log", "replay", f"{ROMA}:4", "--out", str(tmp_path)])
    assert code == 2 and "log 4 does not exist; the file holds 3 log(s)" in capsys.readouterr().err


def test_a_synthetic_stick_track_flies_in_the_air_and_the_firmware_reports_its_set_point(
        firmware: tuple[Path, Path]) -> None:
    """No log needed: half right roll stick at hover throttle, in ACRO, with the floor taken away."""
    from aerobat.plants.betaflight.plant import BetaflightPlant
    from aerobat.plants.betaflight.replay import replay_sticks
    from aerobat.quadrotor.vehicle import fpv5

    plant = BetaflightPlant(fpv5(), binary=firmware[0], eeprom=firmware[1])
    t = np.arange(0.0, 1.0, 0.004)
    throttle = round(plant.settings.throttle_us_for_motor(0.35))
    roll = np.where((t >= 0.3) & (t < 0.5), 1750, 1500)
    track = StickTrack(t, np.column_stack([roll, np.full_like(t, 1500), np.full_like(t, throttle),
                                           np.full_like(t, 1500)]))
    trace = replay_sticks(plant, track)
    held = (trace.time_s > 0.4) & (trace.time_s < 0.5)
    expected = plant.settings.rate_deg_s("roll", 0.5)
    assert np.all(np.abs(trace.setpoint_deg_s[held, 0] - expected) < 1.0), (expected, trace.setpoint_deg_s[held, 0])
    assert np.degrees(trace.rates_rad_s[held, 0]).mean() == pytest.approx(expected, rel=0.1)  # rolling right, +p
    assert np.all(np.abs(trace.setpoint_deg_s[trace.time_s < 0.25]) < 0.5)
    assert np.all(np.isfinite(trace.pid)) and np.abs(trace.pid[held, 0, 0]).max() > 0.0  # P roll is reported
    assert trace.motors.min() > 0.0  # armed and flying all the way: no floor, no disarm
