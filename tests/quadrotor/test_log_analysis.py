"""What a pilot reads from a log (issue 44 item 6): the crash, the step response, the spectrum against throttle.

Each estimate is checked on a signal whose answer is known; the real logs (../shared/data) check that the
ROMA F5's crash no longer sets the plot's limits.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from aerobat.quadrotor.log_analysis import (
    GYRO_SATURATION_DEG_S,
    estimate_step_response,
    find_crash,
    plot_limits,
    throttle_spectrogram,
)

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "flight-logs"
ROMA = DATA / "betaflight" / "diatone-roma-f5.bbl"


def _steps(n: int, dt: float, seed: int = 0) -> np.ndarray:
    """Random set-point steps of ±400 °/s, each held 0.1–0.6 s."""
    rng = np.random.default_rng(seed)
    sp = np.zeros(n)
    i = 0
    while i < n:
        hold = int(rng.uniform(0.1, 0.6) / dt)
        sp[i: i + hold] = rng.uniform(-400.0, 400.0)
        i += hold
    return sp


def _lag(u: np.ndarray, dt: float, tau_s: float, delay: int) -> np.ndarray:
    """A first-order lag of ``tau_s`` behind ``delay`` samples (Euler: y[k] = y[k-1] + a (u[k - delay] - y[k-1]))."""
    a = dt / tau_s
    y = np.zeros(u.size)
    for k in range(1, u.size):
        y[k] = y[k - 1] + a * ((u[k - delay] if k >= delay else 0.0) - y[k - 1])
    return y


def test_the_step_response_of_a_known_loop_is_found():
    dt, tau, delay = 1.0 / 500.0, 0.02, 4
    sp = _steps(30_000, dt)
    gyro = _lag(sp, dt, tau, delay) + np.random.default_rng(1).normal(0.0, 5.0, sp.size)
    r = estimate_step_response(np.arange(sp.size) * dt, sp, gyro)
    assert r is not None and r.segments >= 5
    exact = _lag(np.ones(r.time_s.size), dt, tau, delay)
    assert np.max(np.abs(r.mean - exact)) < 0.06
    assert r.rise_s == pytest.approx(tau * math.log(9.0), rel=0.1)  # 10 → 90 % of a first-order lag
    assert r.delay_s == pytest.approx(delay * dt + tau * math.log(2.0), abs=0.004)
    assert r.overshoot < 0.02


def test_a_set_point_that_does_not_move_gives_no_step_response():
    t = np.arange(20_000) / 500.0
    still = np.full(t.size, 50.0) + np.random.default_rng(0).normal(0.0, 1.0, t.size)  # 1 °/s of noise only
    assert estimate_step_response(t, still, still) is None
    assert estimate_step_response(t[:100], still[:100], still[:100]) is None  # shorter than four responses


def test_the_spectrogram_follows_a_line_that_climbs_with_throttle():
    fs = 1000.0
    t = np.arange(120_000) / fs
    throttle = 0.5 + 0.45 * np.sin(2 * np.pi * t / 40.0)  # sweeps 5–95 % slowly
    freq = 50.0 + 300.0 * throttle  # a motor harmonic: 50 Hz at idle, 350 Hz at full throttle
    signal = np.sin(2 * np.pi * np.cumsum(freq) / fs) + np.random.default_rng(0).normal(0.0, 0.1, t.size)
    m = throttle_spectrogram(t, signal, throttle, segment_samples=256, bins=20)
    assert m is not None and m.counts.sum() > 900
    centres = 0.5 * (m.throttle_edges[:-1] + m.throttle_edges[1:])
    filled = m.counts > 0
    peaks = m.frequency_hz[np.nanargmax(m.power_db[filled], axis=1)]
    assert np.all(np.abs(peaks - (50.0 + 300.0 * centres[filled])) <= 300.0 * 0.05 / 2 + fs / 256)
    assert np.all(np.isnan(m.power_db[~filled]))  # no segment, no number


def test_a_crash_at_the_end_is_found_where_the_flight_was_still_calm():
    t = np.arange(0.0, 30.0, 0.004)
    gyro = np.zeros((t.size, 3))
    gyro[:, 0] = 200.0 * np.sin(t)
    crash = t >= 29.0
    gyro[crash, 1] = 2000.0
    gyro[np.argmax(crash) - 1, 1] = 1500.0  # the sample before saturation is already tumbling
    found = find_crash(t, gyro)
    assert found is not None and found.time_s == pytest.approx(29.0 - 0.008)
    assert "saturated" in found.reason
    limits = plot_limits(gyro[t < found.time_s], saturation=GYRO_SATURATION_DEG_S)
    assert limits is not None and limits[1] < 250.0  # the flight, not the crash


def test_saturation_mid_flight_is_no_crash_and_an_impact_is_one():
    t = np.arange(0.0, 30.0, 0.004)
    gyro = np.zeros((t.size, 3))
    gyro[(t > 10.0) & (t < 10.2), 0] = 1999.0  # a fast roll long before the end
    assert find_crash(t, gyro) is None
    force = np.tile([0.0, 0.0, 9.81], (t.size, 1))
    force[t > 29.5, 2] = 15 * 9.81
    found = find_crash(t, gyro, force, t)
    assert found is not None and found.time_s == pytest.approx(29.5, abs=0.005) and "g" in found.reason


def test_plot_limits_leave_out_saturated_samples_and_hold_the_rest():
    lo, hi = plot_limits(np.array([-100.0, 50.0, 1995.0, np.nan]), saturation=GYRO_SATURATION_DEG_S)
    assert lo < -100.0 and 50.0 < hi < 100.0
    assert plot_limits(np.array([np.nan])) is None
    lo, hi = plot_limits(np.zeros(5))
    assert lo < 0.0 < hi


@pytest.mark.skipif(not ROMA.is_file(), reason=f"the real flight logs are not here ({ROMA} is absent)")
def test_the_roma_f5_crash_no_longer_sets_the_plots_limits(tmp_path):
    """Before: the first flight's crash at 65 s (gyro at 2109 °/s, 17.8 g) set every rate axis to ±2100 °/s."""
    from aerobat.cli import main
    from aerobat.logs import read_logs
    from aerobat.plotting.flightlog import log_crash, plot_log_traces

    log = read_logs(ROMA)[0]
    crash = log_crash(log)
    assert crash is not None and 64.9 < crash.time_s < 65.1
    fig = plot_log_traces(log)
    for ax, most in zip(fig.axes[:3], (300.0, 300.0, 150.0), strict=True):  # flown within ±270 °/s before it
        lo, hi = ax.get_ylim()
        assert -most < lo and hi < most, (ax.get_ylabel(), lo, hi)
    assert main(["log", "plot", f"{ROMA}:1", "--out", str(tmp_path / "p")]) == 0
    for name in ("traces", "pid", "spectra", "spectrogram", "step_response"):
        assert (tmp_path / "p" / f"log1_{name}.png").stat().st_size > 10_000, name


def test_broken_samples_are_no_crash():
    """A crafted log's −inf accelerometer once marked the whole log a crash (the fuzz campaign found it)."""
    t = np.arange(0.0, 30.0, 0.004)
    gyro = np.zeros((t.size, 3))
    gyro[-5:, 0] = np.nan
    force = np.full((t.size, 3), -np.inf)
    assert find_crash(t, gyro, force, t) is None
