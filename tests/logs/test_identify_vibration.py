"""The rotors' speed from the frame's vibration, folded by a log's slow sampling (issue 42)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from aerobat.experiments.log_identify import identify_from_logs
from aerobat.logs import read_log
from aerobat.quadrotor.flightlog import Channel
from aerobat.quadrotor.identification.logfit import Geometry, thrust_curve
from aerobat.quadrotor.identification.vibration import fit_vibration, folded_hz
from aerobat.quadrotor.vehicle import fpv5
from aerobat.quadrotor.xframe import Airframe

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "flight-logs"
ROMA = DATA / "betaflight" / "diatone-roma-f5.bbl"
GECKO = DATA / "betaflight" / "aikonf7-gecko.bbl"
needs_data = pytest.mark.skipif(not ROMA.is_file(), reason=f"the real flight logs are not here ({DATA} is absent)")
RATE_HZ = 250.0


def _thrust(u: np.ndarray) -> np.ndarray:
    return 9.0 * np.asarray(u, dtype=float) ** 1.6  # a rotor's thrust [N] at its command


def _flight(k: float, amplitude_rad_s: tuple[float, float, float], seed: int) -> tuple[np.ndarray, ...]:
    """90 s at 250 Hz: steady throttle levels of 4 s, a slow flight motion, and the rotors' balance line, which turns
    at √(T/k)/2π (130–250 Hz here) and is sampled where it falls, folded."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 90.0, 1.0 / RATE_HZ)
    levels = rng.uniform(0.2, 0.42, size=int(t[-1] // 4.0) + 1)
    u = np.repeat(levels[(t // 4.0).astype(int)][:, None], 4, axis=1)
    rotor_hz = np.sqrt(_thrust(u[:, 0]) / k) / (2.0 * math.pi)
    phase = 2.0 * math.pi * np.cumsum(rotor_hz) / RATE_HZ  # the line's phase at each sample
    motion = np.cumsum(rng.standard_normal((t.size, 3)), axis=0) * 0.01
    motion -= np.convolve(motion[:, 0], np.ones(50) / 50, mode="same")[:, None]  # slow, not drifting
    gyro = motion + np.sin(phase)[:, None] * np.array(amplitude_rad_s) + 0.01 * rng.standard_normal((t.size, 3))
    return t, gyro, u


def test_a_line_above_the_nyquist_frequency_appears_folded() -> None:
    assert folded_hz(190.0, 250.0) == pytest.approx(60.0)
    assert folded_hz(260.0, 250.0) == pytest.approx(10.0)
    assert folded_hz(100.0, 250.0) == pytest.approx(100.0)
    assert folded_hz(np.array([125.0, 375.0]), 250.0).tolist() == pytest.approx([125.0, 125.0])


def test_the_rotors_speed_is_found_through_the_fold_and_the_lines_amplitude_per_axis() -> None:
    k_true = 1.1e-6
    fit = fit_vibration([_flight(k_true, (0.12, 0.06, 0.0), seed=3)], _thrust, 1.56e-6)
    assert fit is not None
    assert fit.log_rate_hz == pytest.approx(RATE_HZ)
    assert fit.thrust_coefficient_n_s2 == pytest.approx(k_true, rel=0.015)
    assert fit.matched_share > 0.75 and fit.matched_share_prior < 0.5  # a line folded under 30 Hz is not the peak
    assert fit.contrast > 5.0 and fit.runner_up < 0.8
    # a sinusoid of amplitude A has rms A/√2; the yaw axis has no line
    assert fit.line_rms_rad_s[0] == pytest.approx(0.12 / math.sqrt(2.0), rel=0.15)
    assert fit.line_rms_rad_s[1] == pytest.approx(0.06 / math.sqrt(2.0), rel=0.15)
    assert fit.line_rms_rad_s[2] < 0.01
    assert 130.0 < fit.rotor_hz < 260.0


def test_a_log_without_a_line_finds_no_speed_it_can_trust() -> None:
    t, gyro, u = _flight(1.1e-6, (0.0, 0.0, 0.0), seed=4)
    fit = fit_vibration([(t, gyro, u)], _thrust, 1.56e-6)
    assert fit is not None
    assert fit.contrast < 2.0  # no k stands out: the report says so, not a number to fly on


def test_no_steady_window_gives_none() -> None:
    t = np.arange(0.0, 10.0, 1.0 / RATE_HZ)
    u = np.clip(0.3 + 0.2 * np.sin(2.0 * math.pi * 0.5 * t), 0, 1)[:, None].repeat(4, axis=1)  # never steady
    assert fit_vibration([(t, np.zeros((t.size, 3)), u)], _thrust, 1.56e-6) is None


@needs_data
def test_the_roma_f5s_flights_agree_on_its_rotors_speed_and_beat_the_prior() -> None:
    """Each flight alone, with flight 1's thrust curve: the same thrust coefficient within 15 %, and the log's
    strongest line falls on the folded rotor lines far more often than at the prior's k."""
    identified = identify_from_logs([f"{ROMA}:1"], Geometry(mass_kg=0.55, motor_x_m=0.08, motor_y_m=0.08),
                                    prior=fpv5())
    whole = identified.vibration
    assert whole is not None
    f_max, ratio, shape = identified.fit.values["thrust_max_n"][0], identified.fit.model.r, identified.fit.model.k
    def curve(u: np.ndarray) -> np.ndarray:
        return f_max * thrust_curve(u, ratio, shape)

    found = []
    for index in (1, 2, 3):
        log = read_log(ROMA, index)
        assert log.has(Channel.GYRO_UNFILTERED)  # debug_mode GYRO_SCALED
        motors = log.signals[Channel.MOTOR_COMMAND]
        fit = fit_vibration([(motors.time_s, log.signals[Channel.GYRO_UNFILTERED].at(motors.time_s), motors.values)],
                            curve, Airframe().thrust_coefficient_n_s2, flying_command=0.1)
        assert fit is not None and fit.windows >= 30
        assert fit.matched_share >= 3.0 * fit.matched_share_prior and fit.contrast > 5.0
        found.append(fit.thrust_coefficient_n_s2)
    assert max(found) / min(found) < 1.15
    assert whole.thrust_coefficient_n_s2 == pytest.approx(found[0], rel=0.02)


@needs_data
def test_a_log_without_the_unfiltered_gyro_has_no_vibration_fit() -> None:
    log = read_log(GECKO, 1)
    assert not log.has(Channel.GYRO_UNFILTERED)  # debug_mode 0


@needs_data
def test_identify_prints_the_vibration_and_writes_it_as_lines_to_move_into_the_airframe(tmp_path, capsys) -> None:
    import tomllib

    from aerobat.cli import main
    from aerobat.plants.fpv.params import load_betaflight

    airframe = tmp_path / "roma_bf.toml"
    assert main(["identify", "--log", f"{ROMA}:1", "--vehicle", "fpv5", "--mass-kg", "0.55", "--motor-x-m", "0.08",
                 "--motor-y-m", "0.08", "--output", str(tmp_path / "roma.toml"), "--airframe", str(airframe)]) == 0
    said = capsys.readouterr().out
    assert "vibration: rotors at " in said and "thrust coefficient " in said
    text = airframe.read_text()
    as_written = load_betaflight(airframe).airframe
    assert not as_written.vibration_flown  # not flown unless the user moves the lines in
    assert as_written.thrust_coefficient_n_s2 == Airframe().thrust_coefficient_n_s2
    moved = [line[4:] for line in text.splitlines() if line.startswith("#   ")]
    fields = tomllib.loads("\n".join(moved))
    assert set(fields) == {"thrust_coefficient_n_s2", "vibration_rms_rad_s", "vibration_thrust_n"}
    flown = tmp_path / "roma_vibrating.toml"
    flown.write_text(text.replace("[airframe]\n", "[airframe]\n" + "\n".join(moved) + "\n", 1))
    vibrating = load_betaflight(flown).airframe
    assert vibrating.vibration_flown
    assert 0.5 < vibrating.thrust_coefficient_n_s2 / Airframe().thrust_coefficient_n_s2 < 0.8
    assert all(0.05 < v < 0.5 for v in vibrating.vibration_rms_rad_s)  # 3-20 °/s
